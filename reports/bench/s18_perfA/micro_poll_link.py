"""RobotLoop._poll_link alone with a link whose state report does not change (as in most frames: the tick
before took the new one), warm and after a pass over EVICT_MB of memory. Run in each tree:
    cd TREE && OMP_NUM_THREADS=1 nice -n 10 env PYTHONPATH=. python reports/bench/s18_perfA/micro_poll_link.py [EVICT_MB]"""
from __future__ import annotations

import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path.cwd() / "tests"))
from support.robot import FakeLink  # noqa: E402

from edge_runtime.robot.loop import RobotLoop  # noqa: E402

q = np.array((0.0, -0.6, 0.0, 1.2, 0.0, 0.5, 0.0))
link = FakeLink(start=(0.4, 0.2, 0.6))
link._state = replace(link._state, joint_positions_rad=q)
loop = RobotLoop(link, clock=lambda: 0.0)
loop.tick()
junk = np.ones(int(float(sys.argv[1] if len(sys.argv) > 1 else 0) * (1 << 20) / 8))
best = []
for _ in range(5):
    t = []
    for _ in range(3000):
        if junk.size:
            junk.sum()
        c0 = time.thread_time()
        loop._poll_link()
        t.append(time.thread_time() - c0)
    best.append(np.median(t))
print(f"_poll_link, unchanged state, {junk.nbytes >> 20} MB evicted: median {min(best) * 1e6:.2f} us (best of 5 x 3000)")
