"""plan_escape_turn on captured calls (capture_plans.py): this tree's against another tree's (--base: its hazard.py, whose
plan_escape_turn runs on this tree's helpers): the same answers (asserted, and against the captured one) and the CPU of each (thread
time, best of --repeat rounds, the two taking turns).

    cd TREE && OMP_NUM_THREADS=1 PYTHONPATH=. /work/main/.venv/bin/python reports/bench/s17_perf6/micro_plan.py \
        --base /work/main/edge_runtime/robot/hazard.py /work/notes/perf6/plans_bench.pkl [--repeat 30]
"""
from __future__ import annotations

import argparse
import ast
import functools
import pickle
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from edge_runtime.robot import hazard as hz


def cpu_ms(fns: dict, repeat: int) -> dict:
    """Each of ``fns``' best thread time (ms) over ``repeat`` rounds, the functions taking turns in each round (a
    shared machine's load then weighs on both alike)."""
    best = dict.fromkeys(fns, float("inf"))
    for _ in range(repeat):
        for k, fn in fns.items():
            c0 = time.thread_time()
            fn()
            best[k] = min(best[k], time.thread_time() - c0)
    return {k: v * 1e3 for k, v in best.items()}


def function_of(path: Path, name: str):
    """``name`` as defined in the module file ``path``, run in this tree's hazard module's namespace (its helpers
    are this tree's: the base's own module cannot be imported next to it, its config sections are taken)."""
    tree = ast.parse(path.read_text())
    node = next(n for n in tree.body if isinstance(n, ast.FunctionDef) and n.name == name)
    space = dict(vars(hz))
    exec(compile(ast.Module([node], []), str(path), "exec"), space)
    return space[name]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("calls", nargs="+")
    ap.add_argument("--base", required=True)
    ap.add_argument("--repeat", type=int, default=30)
    ap.add_argument("--per-call", action="store_true")
    args = ap.parse_args()
    base = SimpleNamespace(plan_escape_turn=function_of(Path(args.base), "plan_escape_turn"))
    calls = [c for f in args.calls for c in pickle.loads(Path(f).read_bytes())]
    for c in calls:  # read-only, as arm_capsules gives them (their _capsule_terms remembered)
        for v in c["capsules"]:
            v.flags.writeable = False
    times = {"base": [], "this tree": []}
    for c in calls:
        plans = {k: functools.partial(m.plan_escape_turn, c["capsules"], c["people"], *c["args"], **c["kwargs"])
                 for k, m in (("base", base), ("this tree", hz))}
        answers = {k: f() for k, f in plans.items()}
        assert answers["base"] == answers["this tree"] == c["turn"], (answers, c["turn"])
        for k, v in cpu_ms(plans, args.repeat).items():
            times[k].append(v)
    if args.per_call:
        for k, (b, t) in enumerate(zip(times["base"], times["this tree"])):
            print(f"call {k}: base {b:.3f} ms, this tree {t:.3f} ms")
    print(f"{len(calls)} calls, answers identical ({sum(c['turn'] is not None for c in calls)} turns, the rest None)")
    for k, v in times.items():
        v = np.array(v)
        print(f"{k:9s} p50 {np.median(v):.3f}  mean {v.mean():.3f}  max {v.max():.3f} ms")
    r = np.array(times["this tree"]) / np.array(times["base"])
    print(f"this tree / base per call: p50 {np.median(r):.2f}  min {r.min():.2f}  max {r.max():.2f}")


if __name__ == "__main__":
    main()
