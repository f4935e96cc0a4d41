"""Quantisation recipes for the FOLDED int8 lifter, scored on the export's val split (fp32 rule).

    PYTHONPATH=. python reports/lifter/s19_fold2/candidates.py --work /tmp/fold/work --out DIR [--only a,b]

Each candidate is the shipped recipe (static QDQ, per-tensor 8-bit weights, uint8 activations, MinMax, 1,000
evenly spread training windows: export.lifter_int8) changed in one or two ways, built from the fp32 graph with
its centering folded (export.lifter_fold), scored with models.lifter_train.evaluate on 20,000 and 5,000 val
frames (the export's figure and its choice basis). Writes DIR/<name>.onnx and DIR/scores.json.
"""
from __future__ import annotations

import argparse
import json
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np
import onnx
from onnxruntime.quantization import CalibrationMethod, QuantFormat, QuantType, quantize_static

from export.lifter_assets import DEFAULT_ASSETS, MAX_INT8_LOSS_MM, MAX_INT8_LOSS_REL, int8_source, onnx_runner
from export.lifter_fold import EXPAND_CONVS
from export.quantize import WindowReader, _preprocess_model, _quiet_root_logger, int8_report
from models.lifter_train import eval_frames, evaluate
from models.pose_data import PoseSet

SHRINK_CONVS = ("/pose/shrink/Conv", "/trajectory/shrink/Conv")


def weights_of(model: onnx.ModelProto, nodes) -> list[str]:
    return [n.input[1] for n in model.graph.node if n.name in nodes]


def build(src: Path, out: Path, calib: np.ndarray, *, per_channel=False, pc_nodes=(), fp32_nodes=(),
          reduce_range=False, extra=None, method=CalibrationMethod.MinMax) -> None:
    model = onnx.load(str(src))
    overrides = {}
    for w in weights_of(model, pc_nodes):  # per-channel only for these convolutions' weights
        n_out = next(i for i in model.graph.initializer if i.name == w).dims[0]
        overrides[w] = [{"axis": 0}] * n_out
    opts = {"CalibTensorRangeSymmetric": False, **(extra or {})}
    if overrides:
        opts["TensorQuantOverrides"] = overrides
    with warnings.catch_warnings(), _quiet_root_logger():
        warnings.simplefilter("ignore")
        quantize_static(str(src), str(out), WindowReader(calib, input_name="keypoints_2d"),
                        quant_format=QuantFormat.QDQ, op_types_to_quantize=None, per_channel=per_channel,
                        activation_type=QuantType.QUInt8, weight_type=QuantType.QInt8, reduce_range=reduce_range,
                        calibrate_method=method, nodes_to_exclude=list(fp32_nodes) or None, extra_options=opts)


def main() -> None:
    p = argparse.ArgumentParser()
    p.add_argument("--work", required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--only", default=None)
    a = p.parse_args()
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    train, val = PoseSet.load(Path(a.work) / "train.npz"), PoseSet.load(Path(a.work) / "val.npz")
    even = lambda n: train.windows(eval_frames(train, n)).astype(np.float32)  # noqa: E731

    def rand(n, seed):
        idx = np.flatnonzero(train.valid)
        return train.windows(np.sort(np.random.default_rng(seed).choice(idx, n, replace=False))).astype(np.float32)

    c1000 = even(1000)
    cands = {
        "folded": dict(calib=c1000),
        "n2000": dict(calib=even(2000)),
        "n4000": dict(calib=even(4000)),
        "n8000": dict(calib=even(8000)),
        "rand1000_s1": dict(calib=rand(1000, 1)),
        "rand1000_s2": dict(calib=rand(1000, 2)),
        "sym_act": dict(calib=c1000, extra={"ActivationSymmetric": True}),
        "per_channel": dict(calib=c1000, per_channel=True),
        "pc_expand": dict(calib=c1000, pc_nodes=EXPAND_CONVS),
        "per_channel_rr7": dict(calib=c1000, per_channel=True, reduce_range=True),
        "rr7": dict(calib=c1000, reduce_range=True),
        "expand_fp32": dict(calib=c1000, fp32_nodes=EXPAND_CONVS),
        "shrink_fp32": dict(calib=c1000, fp32_nodes=SHRINK_CONVS),
        "movavg": dict(calib=c1000, extra={"CalibMovingAverage": True}),
        "pose_shrink_fp32": dict(calib=c1000, fp32_nodes=SHRINK_CONVS[:1]),
        "movavg_shrink_fp32": dict(calib=c1000, fp32_nodes=SHRINK_CONVS, extra={"CalibMovingAverage": True}),
    }
    # the same recipes on other calibration draws: is a pass the recipe's or the draw's?
    draws = {"n2000": even(2000), "n4000": even(4000), "n8000": even(8000),
             **{f"rand1000_s{s}": rand(1000, s) for s in (1, 2, 3, 4)}}
    for recipe in ("folded", "movavg", "shrink_fp32", "pose_shrink_fp32", "movavg_shrink_fp32", "per_channel_rr7"):
        for d, c in draws.items():
            cands[f"{recipe}@{d}"] = {**cands[recipe], "calib": c}
    only = [n for n in cands if any(n == o or (o.endswith("*") and n.startswith(o[:-1]))
                                    for o in a.only.split(","))] if a.only else list(cands)
    fp32 = DEFAULT_ASSETS / "lifter.fp32.onnx"
    scores_path = out / "scores.json"
    scores = json.loads(scores_path.read_text()) if scores_path.is_file() else {}
    ref = {n: evaluate(None, val, n, runner=onnx_runner(fp32))["mpjpe_mm"] for n in (20000, 5000)}
    allowed = {n: m + max(MAX_INT8_LOSS_MM, MAX_INT8_LOSS_REL * m) for n, m in ref.items()}
    print(f"fp32 MPJPE {ref}; allowed {allowed}")
    with tempfile.TemporaryDirectory() as td:
        src = _preprocess_model(int8_source(fp32, True, Path(td)), Path(td) / "pre.onnx")
        for name in only:
            t0 = time.time()
            path = out / f"{name}.onnx"
            build(src, path, **cands[name])
            m20 = evaluate(None, val, 20000, runner=onnx_runner(path))
            m5 = evaluate(None, val, 5000, runner=onnx_runner(path))["mpjpe_mm"]
            rt = int8_report(path)["runtime_op_types"]
            s = {"mpjpe_mm": m20["mpjpe_mm"], "p_mpjpe_mm": m20["p_mpjpe_mm"], "root_error_mm": m20["root_error_mm"],
                 "mpjpe_5000_mm": m5, "margin_20000_mm": allowed[20000] - m20["mpjpe_mm"],
                 "margin_5000_mm": allowed[5000] - m5, "runtime_nodes": sum(rt.values()), "runtime_op_types": rt,
                 "n_calib": len(cands[name]["calib"]), "built_utc": time.strftime("%H:%M:%S", time.gmtime(t0))}
            scores[name] = s
            print(f"{name:12s} MPJPE {s['mpjpe_mm']:.3f} (margin {s['margin_20000_mm']:+.3f}) P {s['p_mpjpe_mm']:.2f} "
                  f"root {s['root_error_mm']:.1f} | 5000: {m5:.3f} (margin {s['margin_5000_mm']:+.3f}) | "
                  f"{s['runtime_nodes']} nodes | {time.time() - t0:.0f} s", flush=True)
            scores_path.write_text(json.dumps({"fp32": ref, "allowed": allowed, **scores}, indent=1, default=float))


if __name__ == "__main__":
    main()
