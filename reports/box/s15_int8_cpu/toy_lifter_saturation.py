import sys; sys.path.insert(0, "/work/main"); sys.path[:0] = ["/work/main/tests/models", "/work/main/tests"]
import numpy as np, torch, onnxruntime as ort, tempfile
from pathlib import Path
import export.lifter_assets as la
from export.quantize import build_variant
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
def run(path, level):
    so = ort.SessionOptions(); so.graph_optimization_level = level; so.intra_op_num_threads = 1
    s = ort.InferenceSession(str(path), so, providers=["CPUExecutionProvider"])
    return s.run(None, {s.get_inputs()[0].name: x})[0]
for cand in la.CANDIDATES:
    q = build_variant(fp32, td / f"l.{cand.name}.onnx", cand, x[:200], describe=False)
    e_opt = np.linalg.norm(run(q, ort.GraphOptimizationLevel.ORT_ENABLE_ALL) - pose32, axis=-1).mean()
    e_ref = np.linalg.norm(run(q, ort.GraphOptimizationLevel.ORT_DISABLE_ALL) - pose32, axis=-1).mean()
    print(cand.name, "int kernels err/spread", e_opt/spread, "float-simulated QDQ err/spread", e_ref/spread, flush=True)
