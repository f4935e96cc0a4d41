"""A/B of plan_escape_turn, session 17's (main 4e7d563) against this tree's, on the calls a bench run made
(capture_escape.py), interleaved, CPU by time.thread_time. Run from the tree: python ab_plan.py"""
import pickle
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, ".")
sys.path.insert(0, str(Path(__file__).parent))
from _base_module import load_base  # noqa: E402

import edge_runtime.robot.hazard as new  # noqa: E402

old = load_base()
calls = pickle.load(open("/tmp/perfC/escape_calls.pkl", "rb"))
for a, k, r in calls:
    assert new.plan_escape_turn(*a, **k) == r == old.plan_escape_turn(*a, **k)
res = {"old": [], "new": []}
for _ in range(40):
    for name, m in (("old", old), ("new", new)):
        t0 = time.thread_time()
        for a, k, _r in calls:
            m.plan_escape_turn(*a, **k)
        res[name].append((time.thread_time() - t0) / len(calls) * 1e6)
for name, v in res.items():
    print(name, "min %.0f  median %.0f us per plan" % (min(v), np.median(v)))
