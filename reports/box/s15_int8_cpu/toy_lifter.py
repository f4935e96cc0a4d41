"""The tests' toy lifter quantised with 8-bit and 7-bit weights: int8 error / spread with onnxruntime's
integer kernels and with the same QDQ graph computed in float (optimisations off), and the drift between
them (export.quantize.integer_kernel_drift). Run from the repository root:
PYTHONPATH=.:tests:tests/models python reports/box/s15_int8_cpu/toy_lifter.py"""
import tempfile
from pathlib import Path

import numpy as np
import onnxruntime as ort
import torch
from test_lifter_model import _warmed

import export.lifter_assets as la
from export.quantize import build_variant, integer_kernel_drift
from models.lifter import LifterConfig, LifterNet
from models.pose_data import DataConfig, build_splits

tiny = build_splits(DataConfig(train_subjects=2, test_subjects=1, seconds_per_subject=12, train_cameras=2,
                               test_cameras=1, views=1, seed=3))
torch.manual_seed(2)
train = tiny["train"]
x = train.windows(np.flatnonzero(train.valid)[::7]).astype(np.float32)
net = _warmed(LifterNet(LifterConfig(channels=32, trajectory_channels=16)), torch.from_numpy(x))
td = Path(tempfile.mkdtemp())
fp32 = la.export_onnx(net, td / "l.onnx")
pose32, _ = la.onnx_runner(fp32)(x)
spread = np.linalg.norm(pose32 - pose32.mean(0), axis=-1).mean()


def error(path, level) -> float:
    so = ort.SessionOptions()
    so.graph_optimization_level, so.intra_op_num_threads = level, 1
    s = ort.InferenceSession(str(path), so, providers=["CPUExecutionProvider"])
    pose = s.run(None, {s.get_inputs()[0].name: x})[0]
    return float(np.linalg.norm(pose - pose32, axis=-1).mean() / spread)


print("weights  candidate     err/spread integer kernels  float QDQ  drift")
for rr in (False, True):
    for cand in la.CANDIDATES:
        q = build_variant(fp32, td / f"l.{cand.name}.onnx", cand, x[:200], describe=False, reduce_range=rr)
        print(f"{'7-bit' if rr else '8-bit'}    {cand.name:13s} {error(q, ort.GraphOptimizationLevel.ORT_ENABLE_ALL):10.3f}"
              f"       {error(q, ort.GraphOptimizationLevel.ORT_DISABLE_ALL):10.3f}"
              f"  {integer_kernel_drift(q, {'keypoints_2d': x[:64]}):.5f}", flush=True)
