"""Capture every plan_escape_turn call (its arguments and its answer) of a run, for the exactness tests and the
micro-benchmark: wraps edge_runtime.robot.loop.plan_escape_turn, then runs a command given after ``--``.

    cd TREE && PYTHONPATH=. /work/main/.venv/bin/python reports/bench/s17_perf6/capture_plans.py OUT.pkl -- \
        reports/bench/s15_perf/prof_cycle.py --seconds 60 --out /tmp/x.json
    ... capture_plans.py OUT.pkl -- -m firmware_sim hrc --scenario hard:10 --seed 15 ...
"""
from __future__ import annotations

import atexit
import pickle
import runpy
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path.cwd()))

import edge_runtime.robot.loop as loopmod  # noqa: E402


def main() -> None:
    out, rest = sys.argv[1], sys.argv[sys.argv.index("--") + 1:]
    calls = []
    plan = loopmod.plan_escape_turn

    def captured(capsules, people, *args, **kwargs):
        turn = plan(capsules, people, *args, **kwargs)
        calls.append({"capsules": tuple(np.array(v) for v in capsules),
                      "people": [(np.array(c), np.array(r)) for c, r in people],
                      "args": args, "kwargs": kwargs, "turn": turn})
        return turn

    loopmod.plan_escape_turn = captured
    atexit.register(lambda: Path(out).write_bytes(pickle.dumps(calls)) and print(f"{len(calls)} calls -> {out}"))
    sys.argv = rest
    if rest[0] == "-m":
        sys.argv = rest[1:]
        runpy.run_module(rest[1], run_name="__main__", alter_sys=True)
    else:
        runpy.run_path(rest[0], run_name="__main__")


if __name__ == "__main__":
    main()
