"""The shipped int8 lifter on this CPU with onnxruntime's default u8 x s8 kernels (which saturate int16 pair sums
on x86 without VNNI, the shipped lifter having 8-bit weights) against session.x64quantprecision=1 (u8 x u8
kernels, exact), scored like lifter_candidates.py on a development seed's varied val split.

    PYTHONPATH=. python reports/bench/s18_ortperf/lifter_exact_int8.py --seed 13 --out /tmp/ortperf/exact.json
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import onnxruntime as ort

from edge_runtime.core.manifest import ASSETS_DIR
from edge_runtime.core.onnx import session_options
from export.lifter_assets import session_runner


def main(argv=None) -> int:
    from models.lifter_train import evaluate
    from models.pose_data import VariedConfig, build_varied_splits

    p = argparse.ArgumentParser()
    p.add_argument("--seed", type=int, default=13)
    p.add_argument("--eval-frames", type=int, default=12000)
    p.add_argument("--out", required=True)
    a = p.parse_args(argv)
    cfg = VariedConfig(train_scenes=24, val_scenes=6, test_scenes=1, seconds_per_scene=30.0, seed=a.seed)
    val = build_varied_splits(cfg)["val"]
    res = {"utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime()), "data": cfg.to_dict(), "rows": {}}
    for name, file, entries in (("fp32", "lifter.fp32.onnx", {}), ("int8", "lifter.int8.onnx", {}),
                                ("int8_u8u8", "lifter.int8.onnx", {"session.x64quantprecision": "1"})):
        so = session_options(1)
        for k, v in entries.items():
            so.add_session_config_entry(k, v)
        sess = ort.InferenceSession(str(ASSETS_DIR / file), so, providers=["CPUExecutionProvider"])
        m = evaluate(None, val, a.eval_frames, runner=session_runner(sess))
        res["rows"][name] = {k: round(m[k], 2) for k in ("n_frames", "mpjpe_mm", "p_mpjpe_mm", "root_error_mm",
                                                           "abs_mpjpe_mm")}
        print(name, res["rows"][name], file=sys.stderr)
    Path(a.out).write_text(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
