"""Where the int8 lifters clip their input: the folded model quantises the raw keypoints (every joint) on one
uint8 range calibrated over the training windows, the shipped one the root's x/y and the joints' offsets from it
on their own ranges. A keypoint outside its range is clipped to it before the first convolution.

For the export's validation split (the windows ``python -m export lifter-int8`` scores), it reports each model's
input ranges (from its QuantizeLinear nodes), the share of windows with some value outside them, and the
metrics of both models on the windows only the folded model clips.

    PYTHONPATH=. python reports/lifter/s19_fold/input_range.py --split /tmp/fold/work/val.npz \
        --shipped edge_runtime/assets/lifter.int8.onnx --folded /tmp/fold/folded/lifter.int8.onnx \
        --out reports/lifter/s19_fold/results/input_range.json
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import onnx
from onnx import numpy_helper

from export.lifter_assets import onnx_runner
from models.lifter_train import eval_frames, predict, score
from models.pose_data import PoseSet


def quant_range(model: onnx.ModelProto, tensor: str) -> tuple[float, float]:
    """The real range a QuantizeLinear of ``tensor`` can represent (uint8: 0..255)."""
    inits = {i.name: numpy_helper.to_array(i) for i in model.graph.initializer}
    q = next(n for n in model.graph.node if n.op_type == "QuantizeLinear" and n.input[0] == tensor)
    s, z = float(inits[q.input[1]]), int(inits[q.input[2]])
    return (0 - z) * s, (255 - z) * s


def first_quantised(model: onnx.ModelProto) -> str:
    """The tensor the folded graph quantises first: the raw input after the pose branch's reshape/transpose."""
    return next(n.input[0] for n in model.graph.node if n.op_type == "QuantizeLinear")


def main(argv=None) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--split", required=True)
    p.add_argument("--shipped", required=True)
    p.add_argument("--folded", required=True)
    p.add_argument("--frames", type=int, default=20000)
    p.add_argument("--out", required=True)
    a = p.parse_args(argv)
    ship, fold = onnx.load(a.shipped), onnx.load(a.folded)
    root_lo, root_hi = quant_range(ship, "/Slice_output_0")      # the root joint's x/y
    off_lo, off_hi = quant_range(ship, "/Sub_output_0")          # joint - root, before the x4 scale
    raw_lo, raw_hi = quant_range(fold, first_quantised(fold))    # every joint's x/y
    ps = PoseSet.load(a.split)
    idx = eval_frames(ps, a.frames)
    x = ps.windows(idx).astype(np.float32)                       # (N, 27, 17, 2)
    off = x[:, :, 1:] - x[:, :, :1]
    out_fold = ((x < raw_lo) | (x > raw_hi)).any(axis=(1, 2, 3))
    out_ship = ((x[:, :, 0] < root_lo) | (x[:, :, 0] > root_hi)).any(axis=(1, 2)) | \
        ((off < off_lo) | (off > off_hi)).any(axis=(1, 2, 3))
    res = {"frames": int(len(idx)), "split": a.split,
           "ranges": {"folded_raw_keypoints": [raw_lo, raw_hi], "shipped_root": [root_lo, root_hi],
                      "shipped_offsets": [off_lo, off_hi]},
           "input_range_of_windows": [float(x.min()), float(x.max())],
           "share_clipped": {"folded": float(out_fold.mean()), "shipped": float(out_ship.mean()),
                             "folded_only": float((out_fold & ~out_ship).mean())}}
    for name, path in (("shipped", a.shipped), ("folded", a.folded)):
        for subset, mask in (("clipped_by_folded", out_fold), ("not_clipped_by_folded", ~out_fold)):
            if mask.any():
                pose, root = predict(None, ps, idx[mask], runner=onnx_runner(path))
                m = score(ps, idx[mask], pose, root)
                res.setdefault(subset, {})[name] = {k: round(m[k], 2) for k in
                                                    ("mpjpe_mm", "p_mpjpe_mm", "root_error_mm", "n_frames")}
    print(json.dumps(res, indent=1))
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(res, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
