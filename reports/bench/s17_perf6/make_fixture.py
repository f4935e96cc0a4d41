"""The fixture of branch perf6 (its tests/support folder, escape_plans_s17.npz) from captured plan_escape_turn calls (capture_plans.py): every --every-th
call of each capture, its inputs and the answer the code of the capture gave (session 16's plan).

    /work/main/.venv/bin/python reports/bench/s17_perf6/make_fixture.py OUT.npz CAPTURE.pkl ... [--every 2]
"""
from __future__ import annotations

import argparse
import pickle
from pathlib import Path

import numpy as np


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("captures", nargs="+")
    ap.add_argument("--every", type=int, default=2)
    args = ap.parse_args()
    capsules, spheres, per_call, per_person, plan_args, turns = [], [], [], [], [], []
    for path in args.captures:
        for call in pickle.loads(Path(path).read_bytes())[::args.every]:
            if call["kwargs"]:
                raise SystemExit(f"{path}: keyword arguments not kept: {sorted(call['kwargs'])}")
            a, b, r = call["capsules"]
            capsules.append(np.column_stack([a, b, r]))
            spheres += [np.column_stack([c, r]) for c, r in call["people"]]
            per_call.append((len(r), len(call["people"])))
            per_person += [len(r) for _, r in call["people"]]
            plan_args.append([np.nan if v is None else v for v in call["args"]])
            turns.append(np.nan if call["turn"] is None else call["turn"])
    # flat rows and counts: capsules (a, b, r) and spheres (centre, radius); per call its capsules and people
    arrays = {"capsules": np.concatenate(capsules), "spheres": np.concatenate(spheres),
              "per_call": np.array(per_call), "per_person": np.array(per_person), "args": np.array(plan_args, float),
              "turn": np.array(turns, float)}
    k = len(turns)
    np.savez_compressed(args.out, **arrays)
    print(f"{k} calls -> {args.out} ({Path(args.out).stat().st_size} bytes)")


if __name__ == "__main__":
    main()
