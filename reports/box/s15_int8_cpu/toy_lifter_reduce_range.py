import sys; sys.path[:0] = ["/work/main", "/work/main/tests/models", "/work/main/tests"]
import numpy as np, torch, tempfile
from pathlib import Path
import export.lifter_assets as la
from export.quantize import build_variant, integer_kernel_drift
from models.pose_data import build_splits, DataConfig
from models.lifter import LifterNet, LifterConfig
from test_lifter_model import _warmed
tiny = build_splits(DataConfig(train_subjects=2, test_subjects=1, seconds_per_subject=12, train_cameras=2, test_cameras=1, views=1, seed=3))
torch.manual_seed(2)
train = tiny["train"]; idx = np.flatnonzero(train.valid); x = train.windows(idx[::7]).astype(np.float32)
net = _warmed(LifterNet(LifterConfig(channels=32, trajectory_channels=16)), torch.from_numpy(x))
td = Path(tempfile.mkdtemp())
fp32 = la.export_onnx(net, td / "l.onnx")
pose32, _ = la.onnx_runner(fp32)(x)
spread = np.linalg.norm(pose32 - pose32.mean(0), axis=-1).mean()
for rr in (False, True):
  for cand in la.CANDIDATES:
    q = build_variant(fp32, td / f"l.{cand.name}.onnx", cand, x[:200], describe=False, reduce_range=rr)
    p8, _ = la.onnx_runner(q)(x)
    print(rr, cand.name, "err/spread %.3f" % (np.linalg.norm(p8 - pose32, axis=-1).mean()/spread), "drift %.5f" % integer_kernel_drift(q, {"keypoints_2d": x[:64]}), "spread", spread, flush=True)
