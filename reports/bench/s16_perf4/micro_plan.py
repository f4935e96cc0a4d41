"""plan_escape_turn of the tree it runs in, timed on the bench scenario's captured calls (session 15's capture,
reports/bench/s15_perf/capture.py; not kept: /work/notes/perf/capture_before.pkl). Every call must give its captured
turn. Run it from each tree in turn (before, after, before, after): two trees cannot share one process (the box
configuration's sections register once).

    cd TREE && OMP_NUM_THREADS=1 /work/main/.venv/bin/python /work/wt/perf4/reports/bench/s16_perf4/micro_plan.py
"""
import pickle
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path.cwd()))
import edge_runtime.robot.hazard as hz  # noqa: E402 - the tree's own, from the working directory

CAPTURE = Path("/work/notes/perf/capture_before.pkl")
calls = pickle.loads(CAPTURE.read_bytes())["plan_escape_turn"]
assert all(hz.plan_escape_turn(*a, **k) == r for a, k, r in calls)
rounds = []
for _ in range(9):
    t0 = time.thread_time()
    for a, k, _ in calls:
        hz.plan_escape_turn(*a, **k)
    rounds.append((time.thread_time() - t0) / len(calls))
print(f"{len(calls)} calls, {sum(r is not None for *_, r in calls)} turning; "
      f"plan_escape_turn {np.median(rounds) * 1e6:7.1f} us per call (median of 9 rounds)")
