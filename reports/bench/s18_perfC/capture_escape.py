"""Every plan_escape_turn call (arguments and result) of a prof_cycle run, to /tmp/perfC/escape_calls.pkl.
Run from the tree as prof_cycle.py: python capture_escape.py --seconds 60 --out X.json"""
import pickle
import sys
from pathlib import Path

sys.path.insert(0, str(Path.cwd()))
sys.path.insert(0, str(Path.cwd() / "reports/bench/s15_perf"))
import prof_cycle as pc  # noqa: E402

import edge_runtime.robot.loop as loopmod  # noqa: E402

CALLS = []
plan = loopmod.plan_escape_turn


def recorded(*a, **k):
    result = plan(*a, **k)
    CALLS.append((a, k, result))
    return result


loopmod.plan_escape_turn = recorded
pc.summarize = lambda out: None
pc.main()
Path("/tmp/perfC").mkdir(exist_ok=True)
pickle.dump(CALLS, open("/tmp/perfC/escape_calls.pkl", "wb"))
print(len(CALLS), "calls")
