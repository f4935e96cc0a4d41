"""Real (not profiled) cost of one command on the CAN link, split: the link's own work (null bus) vs
python-can's virtual bus (the bench's StampedBus: deepcopy + queue per frame)."""
import sys
import time
import timeit

sys.path.insert(0, '.')
import numpy as np

from bench.arm_echo import StampedBus
from edge_runtime.robot.link.base import LinkConfig
from edge_runtime.robot.link.can import CanRobotLink


class NullBus:
    def send(self, msg, timeout=None): pass
    def recv(self, timeout=None): return None
    def shutdown(self): pass

rng = np.random.default_rng(1)
targets = [np.array([0.5, 0.3, 0.6]) + rng.uniform(-0.1, 0.1, 3) for _ in range(4000)]
buses = []
for label, bus in (("null bus", NullBus()), ("virtual bus", StampedBus(f"micro-{time.time()}"))):
    buses.append(bus)
    link = CanRobotLink(bus=bus, config=LinkConfig(heartbeat_period_s=None))
    it = iter(targets * 10)
    for _ in range(2):
        r = timeit.timeit(lambda link=link, it=it: link.retract(next(it), 0.1, 0.2), number=3000) / 3000 * 1e6
        s = timeit.timeit(lambda link=link: link.set_speed(float(rng.uniform(0, 1.5))), number=3000) / 3000 * 1e6
        a = timeit.timeit(lambda link=link: link.set_alarm("red", 2000.0, 80.0), number=3000) / 3000 * 1e6
        print(f"{label:12s} retract {r:6.1f} us  set_speed {s:6.1f} us  set_alarm {a:6.1f} us")
for b in buses:
    b.shutdown()
