"""int8 lifter candidates built from the shipped lifter.fp32.onnx into --out (never edge_runtime/assets), scored
against fp32 with the export's own scoring (models.lifter_train.evaluate: MPJPE, P-MPJPE, root error) on a
development seed's varied data (calibration on its train split, scoring on its val split).

    PYTHONPATH=. python reports/bench/s18_ortperf/lifter_candidates.py --seed 13 --out /tmp/ortperf/lifter

Candidates: today's recipe rebuilt on this calibration (qdq_pt, 8-bit weights, as shipped), and changes of one
knob each: reduce_range (7-bit weights), per-channel, the input's centering kept fp32, QOperator format,
U8U8 (uint8 weights). The shipped int8 file is scored too. Writes --out/scores.json.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from onnxruntime.quantization import CalibrationMethod, QuantFormat, QuantType, quantize_static

from edge_runtime.core.manifest import ASSETS_DIR
from edge_runtime.core.onnx import open_session
from export.lifter_assets import N_CALIB, session_runner
from export.quantize import WindowReader, _preprocess_model, _quiet_root_logger, int8_report

INPUT_CENTERING = ["/Slice", "/Slice_1", "/Sub", "/Mul", "/Concat"]
"""The fp32 graph's first nodes: the root joint's 2D position and the other joints relative to it (x2)."""

CANDIDATES = {  # name -> quantize_static keyword changes from today's recipe
    "today_qdq_pt": {},
    "qdq_pt_rr": {"reduce_range": True},
    "qdq_pc": {"per_channel": True},
    "qdq_pc_rr": {"per_channel": True, "reduce_range": True},
    "qdq_pt_fp32in": {"nodes_to_exclude": INPUT_CENTERING},
    "qdq_pt_rr_fp32in": {"reduce_range": True, "nodes_to_exclude": INPUT_CENTERING},
    "qop_pt": {"quant_format": QuantFormat.QOperator},
    "qdq_pt_u8u8": {"weight_type": QuantType.QUInt8},
    "qdq_pt_fp32expand": {"nodes_to_exclude": ["/pose/expand_conv/Conv", "/trajectory/expand_conv/Conv"]},
}
TODAY = dict(quant_format=QuantFormat.QDQ, op_types_to_quantize=None, per_channel=False,
             activation_type=QuantType.QUInt8, weight_type=QuantType.QInt8, reduce_range=False,
             calibrate_method=CalibrationMethod.MinMax, extra_options={"CalibTensorRangeSymmetric": False})
"""export.quantize.build_variant's call for the shipped Variant qdq_pt, with the 8-bit weights it was built with."""


def main(argv=None) -> int:
    from models.lifter_train import eval_frames, evaluate
    from models.pose_data import VariedConfig, build_varied_splits

    p = argparse.ArgumentParser()
    p.add_argument("--seed", type=int, default=13)
    p.add_argument("--scenes", type=int, default=24)
    p.add_argument("--seconds", type=float, default=30.0)
    p.add_argument("--eval-frames", type=int, default=5000)
    p.add_argument("--only", default="")
    p.add_argument("--fp32", default="", help="the fp32 graph to quantise (default: the shipped one), e.g. "
                                              "fold_centering.py's")
    p.add_argument("--out", required=True)
    a = p.parse_args(argv)
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.time()
    cfg = VariedConfig(train_scenes=a.scenes, val_scenes=6, test_scenes=1, seconds_per_scene=a.seconds, seed=a.seed)
    splits = build_varied_splits(cfg)
    train, val = splits["train"], splits["val"]
    calib = train.windows(eval_frames(train, N_CALIB)).astype(np.float32)
    print(f"data {time.time() - t0:.0f} s: calib {calib.shape}, val frames {int(val.valid.sum())}", file=sys.stderr)
    fp32 = Path(a.fp32) if a.fp32 else ASSETS_DIR / "lifter.fp32.onnx"
    scores = {"utc": time.strftime("%Y-%m-%d %H:%M", time.gmtime()), "data": cfg.to_dict(), "fp32_graph": str(fp32),
              "eval_frames": a.eval_frames, "candidates": {}}

    def score(path: Path) -> dict:
        m = evaluate(None, val, a.eval_frames, runner=session_runner(open_session(path)))
        return {k: round(m[k], 2) for k in ("mpjpe_mm", "p_mpjpe_mm", "root_error_mm", "abs_mpjpe_mm")}

    scores["fp32"] = score(fp32)
    scores["shipped_int8"] = score(ASSETS_DIR / "lifter.int8.onnx")
    print(f"fp32 {scores['fp32']}\nshipped int8 {scores['shipped_int8']}", file=sys.stderr)
    names = [n for n in CANDIDATES if not a.only or n in a.only.split(",")]
    with tempfile.TemporaryDirectory() as td:
        pre = _preprocess_model(fp32, Path(td) / "pre.onnx")
        for name in names:
            path = out / f"lifter.int8.{name}.onnx"
            kw = {**TODAY, **CANDIDATES[name]}
            with _quiet_root_logger():
                quantize_static(str(pre), str(path), WindowReader(calib, input_name="keypoints_2d"), **kw)
            s = score(path)
            rep = int8_report(path)
            scores["candidates"][name] = {
                **s, "d_mpjpe_mm": round(s["mpjpe_mm"] - scores["fp32"]["mpjpe_mm"], 2),
                "d_p_mpjpe_mm": round(s["p_mpjpe_mm"] - scores["fp32"]["p_mpjpe_mm"], 2),
                "bytes": path.stat().st_size, "runtime_op_types": rep["runtime_op_types"],
                "kwargs": {k: str(v) for k, v in CANDIDATES[name].items()}}
            print(f"{name}: {s}", file=sys.stderr)
            (out / "scores.json").write_text(json.dumps(scores, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
