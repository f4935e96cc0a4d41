"""A/B of HazardMonitor.observe, session 17's (main 4e7d563) against this tree's: two people walking, the arm's
joints new at every frame (300 frames), the same decisions asserted; interleaved, CPU by time.thread_time.
Run from the tree: python ab_observe.py [ROUNDS]"""
import math
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, ".")
sys.path.insert(0, "tests")
sys.path.insert(0, str(Path(__file__).parent))
from _base_module import load_base  # noqa: E402
from support.robot import anchored_worker  # noqa: E402

import edge_runtime.robot.hazard as new  # noqa: E402

old = load_base()
N = 300
frames = []
for k in range(N):
    a = anchored_worker((0.9 + 0.4 * math.sin(k / 40), 1.2 - 0.3 * math.cos(k / 50)), heading=math.pi)
    b = anchored_worker((-1.5 + 0.02 * k, 1.8), heading=1.2)
    q = np.array([0.3 * math.sin(k / 20), -0.5, 0.2, 1.2, 0.1 * k / N, 0.4, 0.0])
    frames.append((k / 30, {1: a, 2: b}, np.array([0.4, 0.14, 0.6]), q))


def run(m):
    mon = m.HazardMonitor()
    t0 = time.thread_time()
    out = [mon.observe(t, people, eff, q) for t, people, eff, q in frames]
    return time.thread_time() - t0, out


for a, b in zip(run(old)[1], run(new)[1]):
    assert (a.state, a.reason, a.distance_m, a.speed_scale, a.coming, a.worker) == \
        (b.state, b.reason, b.distance_m, b.speed_scale, b.coming, b.worker)
res = {"old": [], "new": []}
for _ in range(int(sys.argv[1]) if len(sys.argv) > 1 else 15):
    for name, m in (("old", old), ("new", new)):
        res[name].append(run(m)[0] / N * 1e6)
for name, v in res.items():
    print(name, "observe: min %.0f  median %.0f us" % (min(v), np.median(v)))
