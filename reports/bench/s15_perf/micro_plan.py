"""Old (textbook, session 14) vs new plan_escape_turn / point_clearance on the bench scenario's captured calls, interleaved."""
import pickle
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path.cwd())); sys.path.insert(0, str(Path.cwd() / "tests"))
import numpy as np
from robot.test_hazard_vectorised import textbook_clearance, textbook_plan

import edge_runtime.robot.hazard as hz

CAP = pickle.load(open("/work/notes/perf/capture_before.pkl", "rb"))
def per_call(fn, calls, reps=7):
    best = []
    for _ in range(reps):
        t = time.thread_time()
        for a, k, _ in calls:
            fn(*a, **k)
        best.append((time.thread_time() - t) / len(calls))
    return np.median(best) * 1e6
plans = CAP["plan_escape_turn"]
assert all(hz.plan_escape_turn(*a, **k) == r for a, k, r in plans)
pcs = CAP["point_clearance_m"][:1000]
assert all(np.array_equal(hz.point_clearance_m(*a, **k), r) for a, k, r in pcs)
for _ in range(2):
    print(f"plan_escape_turn old {per_call(textbook_plan, plans):7.1f} us  new {per_call(hz.plan_escape_turn, plans):7.1f} us"
          f"   point_clearance_m old {per_call(textbook_clearance, pcs):6.1f} us  new {per_call(hz.point_clearance_m, pcs):6.1f} us")
