"""Stage 1 (issue 12, session 14): one small 1D CNN that classifies any prefix of a detector capture (the capture's
first n raw frames, n = 100 + 100 c for a decision c s after the trigger), trained on the TRAINING cohort only
(cohort seed 0: the train.npz (ground-truth windows) and test.npz (detector captures) that
``python -m export assets --seed 0 --work DIR`` writes to DIR/data and trains the shipped ConvLSTM on).

Session 12's quick CNN (``../early_diagnosis_s12/prefix_models.py``) trained one model per cut; this one is a
single model for every cut: each batch is cut to a random prefix length, and the features are a max over the
prefix's valid positions plus the mean of its last 0.16 s (where the hand is now), so one network decides at any
point. 25 Hz (the mean of 4 raw frames), channels normalised by the training set's mean and sd.

    PYTHONPATH=. OMP_NUM_THREADS=1 python reports/wearable/early_diagnosis_s14/prefix_net.py DIR/data OUT.pt \
        [EPOCHS [WIDTH [LABEL_SMOOTHING [SEED]]]]

Round 1: 30 epochs, width 32, label smoothing 0.05, seed 0. Round 2 (after round 1's false alerts): width 48, no
label smoothing (it caps the top probability near 0.96, so thresholds above that cannot be asked), 40 epochs, seeds
0, 1, 2 (their mean: ``hybrid.py`` takes several checkpoints, comma-separated).

Writes OUT.pt (state dict, normalisation, training provenance) and OUT.onnx (fp32, dynamic length), and prints
the parameter count and the one-thread onnxruntime cost of one decision at the longest prefix it is used at.
"""
import sys
import time

import numpy as np
import torch
import torch.nn as nn

from models.dataset import load_npz

DOWN = 4
"""Raw frames (100 Hz) per input step: 25 Hz."""
MIN_FRAMES, MAX_FRAMES = 120, 420
"""Prefix lengths trained on: 0.2 s to 3.2 s after the trigger (the capture starts 1 s before it)."""
LAST_STEPS = 4
"""The 'now' features: the mean of the last 4 positions (0.16 s) of the last conv layer."""


class PrefixNet(nn.Module):
    def __init__(self, classes: int = 6, width: int = 32):
        super().__init__()
        self.register_buffer("mu", torch.zeros(1, 3, 1))
        self.register_buffer("sd", torch.ones(1, 3, 1))
        self.conv = nn.Sequential(
            nn.Conv1d(3, width, 5, padding=2), nn.ReLU(), nn.Conv1d(width, width, 5, padding=2), nn.ReLU(),
            nn.MaxPool1d(2), nn.Conv1d(width, 2 * width, 5, padding=2), nn.ReLU())
        self.drop = nn.Dropout(0.3)
        self.head = nn.Linear(4 * width, classes)

    def forward(self, x25: torch.Tensor) -> torch.Tensor:
        """(N, 3, T) m/s^2 at 25 Hz -> (N, classes) logits."""
        f = self.conv((x25 - self.mu) / self.sd)
        z = torch.cat([f.amax(dim=2), f[:, :, -LAST_STEPS:].mean(dim=2)], dim=1)
        return self.head(self.drop(z))


def to25(X: np.ndarray, n: int | None = None) -> torch.Tensor:
    """(N, frames, 3) at 100 Hz -> (N, 3, frames // 4) at 25 Hz, the first ``n`` frames (a multiple of 4 used)."""
    X = X if n is None else X[:, :n]
    m = X.shape[1] // DOWN * DOWN
    return torch.tensor(X[:, :m].reshape(len(X), m // DOWN, DOWN, 3).mean(2).transpose(0, 2, 1), dtype=torch.float32)


def shift(x: torch.Tensor, k: int) -> torch.Tensor:
    """The capture k steps later (k > 0: its first value repeated in front) or earlier (k < 0)."""
    if k > 0:
        return torch.cat([x[:, :, :1].expand(-1, -1, k), x[:, :, :-k]], dim=2)
    if k < 0:
        return torch.cat([x[:, :, -k:], x[:, :, -1:].expand(-1, -1, -k)], dim=2)
    return x


def rotation(g: torch.Generator, max_deg: float) -> torch.Tensor:
    """A random rotation (3, 3) about a random axis by up to ``max_deg`` (another wrist orientation)."""
    axis = torch.randn(3, generator=g)
    axis = axis / axis.norm()
    a = float(torch.rand(1, generator=g)) * np.radians(max_deg)
    K = torch.tensor([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return torch.eye(3) + np.sin(a) * K + (1 - np.cos(a)) * K @ K


def fit(X: np.ndarray, y: np.ndarray, epochs: int = 16, seed: int = 0, width: int = 32, smoothing: float = 0.05,
        log=print) -> PrefixNet:
    torch.manual_seed(seed)
    g = torch.Generator().manual_seed(seed)
    a = to25(X)
    net = PrefixNet(width=width)
    net.mu.copy_(a.mean((0, 2), keepdim=True))
    net.sd.copy_(a.std((0, 2), keepdim=True))
    opt = torch.optim.Adam(net.parameters(), 2e-3, weight_decay=1e-4)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, epochs)
    yt = torch.tensor(y)
    cw = torch.tensor(len(y) / (6 * np.bincount(y, minlength=6)), dtype=torch.float32)
    lossf = nn.CrossEntropyLoss(weight=cw, label_smoothing=smoothing)
    t0 = time.time()
    for ep in range(epochs):
        net.train()
        perm = torch.randperm(len(a), generator=g)
        tot = 0.0
        for i in range(0, len(a), 64):
            idx = perm[i:i + 64]
            n = int(torch.randint(MIN_FRAMES // DOWN, MAX_FRAMES // DOWN + 1, (1,), generator=g))  # steps
            xb = shift(a[idx], int(torch.randint(-5, 6, (1,), generator=g)))[:, :, :n]
            xb = torch.einsum("ij,njt->nit", rotation(g, 15.0), xb)
            opt.zero_grad()
            loss = lossf(net(xb), yt[idx])
            loss.backward()
            opt.step()
            tot += float(loss) * len(idx)
        sched.step()
        log(f"epoch {ep + 1}/{epochs}: loss {tot / len(a):.4f} ({time.time() - t0:.0f} s)")
    net.eval()
    return net


@torch.no_grad()
def prefix_probs(net: PrefixNet, X: np.ndarray, frames: list[int], batch: int = 2048) -> np.ndarray:
    """(N, len(frames), K) softmax of every capture's prefix of each length."""
    out = np.zeros((len(X), len(frames), net.head.out_features), np.float32)
    for i in range(0, len(X), batch):
        for j, n in enumerate(frames):
            out[i:i + batch, j] = net(to25(X[i:i + batch], n)).softmax(1).numpy()
    return out


def load(path: str) -> PrefixNet:
    ck = torch.load(path)
    net = PrefixNet(width=ck.get("width", 32))
    net.load_state_dict(ck["state"])
    return net.eval()


def export_and_time(net: PrefixNet, onnx_path: str, frames: int, reps: int = 2000) -> dict:
    """fp32 ONNX with a dynamic length; median one-thread onnxruntime time of one decision on a prefix of
    ``frames`` raw frames (the model runs on the whole prefix at each decision: no state kept)."""
    import onnxruntime as ort
    x = torch.zeros(1, 3, frames // DOWN)
    torch.onnx.export(net, (x,), onnx_path, input_names=["x25"], output_names=["logits"],
                      dynamic_axes={"x25": {0: "n", 2: "t"}}, opset_version=17, dynamo=False)
    so = ort.SessionOptions()
    so.intra_op_num_threads = 1
    so.inter_op_num_threads = 1
    s = ort.InferenceSession(onnx_path, so, providers=["CPUExecutionProvider"])
    feed = {"x25": np.random.default_rng(0).normal(size=(1, 3, frames // DOWN)).astype(np.float32)}
    ref = net(torch.from_numpy(feed["x25"])).detach().numpy()
    got = s.run(None, feed)[0]
    for _ in range(200):
        s.run(None, feed)
    ts = []
    for _ in range(reps):
        t = time.perf_counter()
        s.run(None, feed)
        ts.append(time.perf_counter() - t)
    return {"frames": frames, "median_us": round(float(np.median(ts)) * 1e6, 1),
            "p90_us": round(float(np.percentile(ts, 90)) * 1e6, 1), "max_abs_diff_vs_torch": float(np.abs(ref - got).max())}


def main(data_dir: str, out: str, epochs: int = 16, width: int = 32, smoothing: float = 0.05, seed: int = 0) -> None:
    torch.set_num_threads(1)
    gt, cap = load_npz(f"{data_dir}/train.npz"), load_npz(f"{data_dir}/test.npz")
    assert list(gt.classes) == list(cap.classes)
    X = np.concatenate([gt.X, cap.X]).astype(np.float32)
    y = np.concatenate([gt.y, cap.y])
    print(f"training cohort: {len(gt.y)} ground-truth windows + {len(cap.y)} detector captures, counts "
          f"{np.bincount(y, minlength=6).tolist()}", flush=True)
    net = fit(X, y, epochs, seed, width, smoothing, log=lambda s: print(s, flush=True))
    params = sum(p.numel() for p in net.parameters())
    torch.save({"state": net.state_dict(), "classes": list(gt.classes), "params": params, "epochs": epochs,
                "width": width, "label_smoothing": smoothing, "seed": seed, "data": data_dir}, out)
    cost = export_and_time(net, out.rsplit(".", 1)[0] + ".onnx", MAX_FRAMES)
    print(f"parameters {params}; onnxruntime fp32, 1 thread, one decision on {MAX_FRAMES} frames: {cost}")


if __name__ == "__main__":
    a = sys.argv[1:]
    main(a[0], a[1], int(a[2]) if len(a) > 2 else 16, int(a[3]) if len(a) > 3 else 32,
         float(a[4]) if len(a) > 4 else 0.05, int(a[5]) if len(a) > 5 else 0)
