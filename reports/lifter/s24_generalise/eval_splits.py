"""Score lifters' ONNX files on the varied recipe's validation and test splits, per motion type.

    python reports/lifter/s24_generalise/eval_splits.py --json OUT.json NAME=ASSETS_DIR [NAME=ASSETS_DIR ...]

Re-simulates ``models.pose_data.build_varied_splits(VariedConfig(seed=0))`` (the recipe of the shipped
lifter and of session 24's candidates: validation and test do not depend on ``random_limbs_share``),
then scores every lifter's fp32 and int8 file on ``val`` (all types), ``val_trained`` (val without the
held-out types ``carry`` and ``reach``: where session 24 compares and chooses) and ``test`` (scored to
report, never to choose), 20,000 evenly spread valid frames each, as ``python -m export lifter`` does.
Run from the repository root (the worktree) with PYTHONPATH=. so its packages are the ones imported.
"""
from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from export.lifter_assets import onnx_runner
from models.lifter_train import evaluate
from models.pose_data import VariedConfig, build_varied_splits, trained_types_only

KEYS = ("mpjpe_mm", "p_mpjpe_mm", "root_error_mm", "per_activity_p_mpjpe_mm", "per_activity_mpjpe_mm", "n_frames")


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("lifters", nargs="+", metavar="NAME=DIR")
    p.add_argument("--json", required=True)
    p.add_argument("--eval-frames", type=int, default=20000)
    a = p.parse_args()
    t0 = time.time()
    sp = build_varied_splits(VariedConfig(seed=0))
    sets = {"val": sp["val"], "val_trained": trained_types_only(sp["val"]), "test": sp["test"]}
    out = {"simulated_s": round(time.time() - t0, 1), "valid_frames": {k: int(v.valid.sum()) for k, v in sets.items()},
           "lifters": {}}
    for spec in a.lifters:
        name, d = spec.split("=", 1)
        out["lifters"][name] = {"assets": d}
        for prec in ("fp32", "int8"):
            run = onnx_runner(Path(d) / f"lifter.{prec}.onnx")
            res = {}
            for s, ps in sets.items():
                m = evaluate(None, ps, a.eval_frames, runner=run)
                res[s] = {k: m[k] for k in KEYS}
                print(f"{name} {prec} {s}: P-MPJPE {m['p_mpjpe_mm']:.1f} mm, MPJPE {m['mpjpe_mm']:.1f} mm; " +
                      ", ".join(f"{k} {v:.1f}" for k, v in m["per_activity_p_mpjpe_mm"].items()), flush=True)
            out["lifters"][name][prec] = res
    Path(a.json).write_text(json.dumps(out, indent=1, sort_keys=True))


if __name__ == "__main__":
    main()
