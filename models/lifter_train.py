"""Train and evaluate the pose lifter (models/lifter.py) on simulated data (models/pose_data.py).

Training (:func:`fit`), as VideoPose3D trains its 27-frame model, scaled to a CPU:

* the strided variant (one pose per 27-frame window), mini-batches of random valid frames;
* loss = MPJPE of the root-relative pose + the trajectory's 1/z-weighted root error
  (:func:`models.lifter.weighted_mpjpe`, w = 1 / true depth), in metres;
* Adam (amsgrad), learning rate ``lr`` decayed by ``lr_decay`` after every epoch, BatchNorm
  momentum decayed from 0.1 toward 0.001 over the run (VideoPose3D's schedule);
* mirror-image augmentation (:func:`models.pose_data.flip`) on half of every batch;
* seeded: the same seed, data and thread count give the same weights.

Evaluation (:func:`evaluate`) on valid frames, in millimetres: MPJPE (protocol 1),
P-MPJPE (protocol 2: after a per-frame similarity Procrustes alignment), root position
error (3D and depth only), absolute MPJPE (pose + root), per joint and per activity.
"""
from __future__ import annotations

import dataclasses
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from edge_runtime.core.skeleton import JOINTS

from .lifter import LifterConfig, LifterNet, mpjpe, weighted_mpjpe
from .pose_data import ACTIVITY_NAMES, PoseSet, flip


@dataclass(frozen=True)
class TrainConfig:
    """Optimisation settings."""

    epochs: int = 6                   #: passes over ``frames_per_epoch`` frames
    frames_per_epoch: int | None = None   #: frames drawn per epoch (None: every valid training frame)
    batch_size: int = 256             #: windows per step
    lr: float = 1e-3                  #: initial Adam learning rate
    lr_decay: float = 0.8             #: learning-rate factor after every epoch (VideoPose3D: 0.95 over 80 epochs)
    bn_momentum: tuple[float, float] = (0.1, 0.001)   #: BatchNorm momentum at the start and the end
    flip: bool = True                 #: mirror augmentation on half of each batch
    trajectory_weight: float = 1.0    #: weight of the root loss
    seed: int = 0                     #: seeds torch and the batch order
    threads: int = 1                  #: torch CPU threads (1 is fastest on a shared 2-core box)

    def to_dict(self) -> dict:
        d = dataclasses.asdict(self)
        d["bn_momentum"] = list(self.bn_momentum)
        return d


def seed_everything(seed: int, threads: int) -> None:
    np.random.seed(seed % 2**32)
    torch.manual_seed(seed)
    torch.use_deterministic_algorithms(True, warn_only=True)
    torch.set_num_threads(threads)


def _batch(ps: PoseSet, idx: np.ndarray, rf: int, flip_mask: np.ndarray | None = None):
    x, p, r = ps.windows(idx, rf), ps.pose3d[idx], ps.root3d[idx]
    if flip_mask is not None and flip_mask.any():
        fx, fp, fr = flip(x[flip_mask], p[flip_mask], r[flip_mask])
        x, p, r = x.copy(), p.copy(), r.copy()
        x[flip_mask], p[flip_mask], r[flip_mask] = fx, fp, fr
    return torch.from_numpy(np.ascontiguousarray(x)), torch.from_numpy(p), torch.from_numpy(r)


def _set_bn_momentum(model: torch.nn.Module, momentum: float) -> None:
    for m in model.modules():
        if isinstance(m, torch.nn.BatchNorm1d):
            m.momentum = momentum


def fit(train: PoseSet, model_cfg: LifterConfig = LifterConfig(), cfg: TrainConfig = TrainConfig(),
        progress: bool = True, log=print) -> tuple[LifterNet, list[dict]]:
    """Train a strided :class:`LifterNet` on the valid frames of ``train``; returns (model, per-epoch history)."""
    from tqdm import tqdm

    seed_everything(cfg.seed, cfg.threads)
    rng = np.random.default_rng(cfg.seed)
    model = LifterNet(model_cfg, strided=True)
    opt = torch.optim.Adam(model.parameters(), lr=cfg.lr, amsgrad=True)
    frames = np.flatnonzero(train.valid)
    if frames.size == 0:
        raise ValueError("training set: no valid frames")
    per_epoch = min(cfg.frames_per_epoch or frames.size, frames.size)
    steps = max(1, per_epoch // cfg.batch_size)
    rf = model_cfg.receptive_field
    history = []
    total_steps, step = cfg.epochs * steps, 0
    m0, m1 = cfg.bn_momentum
    for epoch in range(cfg.epochs):
        model.train()
        order = rng.permutation(frames)[: steps * cfg.batch_size].reshape(steps, cfg.batch_size)
        t0, sums = time.perf_counter(), np.zeros(2)
        bar = tqdm(order, desc=f"lifter c{model_cfg.channels} epoch {epoch + 1}/{cfg.epochs}", unit="batch",
                   disable=not progress, leave=False)
        for idx in bar:
            _set_bn_momentum(model, m0 * (m1 / m0) ** (step / max(total_steps - 1, 1)))
            flip_mask = rng.random(len(idx)) < 0.5 if cfg.flip else None
            x, p, r = _batch(train, idx, rf, flip_mask)
            pose, root = model(x)
            loss_pose = mpjpe(pose[:, 0], p)
            loss_root = weighted_mpjpe(root[:, 0], r, 1.0 / r[:, 2].clamp(min=0.5))
            loss = loss_pose + cfg.trajectory_weight * loss_root
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            sums += (loss_pose.item(), loss_root.item())
            step += 1
            bar.set_postfix(mpjpe_mm=f"{1000 * loss_pose.item():.1f}")
        for g in opt.param_groups:
            g["lr"] *= cfg.lr_decay
        h = {"epoch": epoch + 1, "train_mpjpe_mm": 1000 * sums[0] / steps, "train_root_loss": sums[1] / steps,
             "seconds": time.perf_counter() - t0, "steps": steps}
        history.append(h)
        log(f"epoch {epoch + 1}/{cfg.epochs}: train MPJPE {h['train_mpjpe_mm']:.1f} mm, "
            f"root loss {h['train_root_loss']:.4f}, {h['seconds']:.0f} s")
    return model.eval(), history


# --------------------------------------------------------------------------- evaluation
def p_mpjpe(pred: np.ndarray, target: np.ndarray) -> np.ndarray:
    """Per-frame MPJPE after the similarity (rotation, translation, scale) that best aligns ``pred`` (N, J, 3)
    to ``target`` -- VideoPose3D's protocol 2. Returns (N,) in the input units."""
    mu_x, mu_y = target.mean(1, keepdims=True), pred.mean(1, keepdims=True)
    x0, y0 = target - mu_x, pred - mu_y
    nx = np.linalg.norm(x0, axis=(1, 2), keepdims=True)
    ny = np.linalg.norm(y0, axis=(1, 2), keepdims=True)
    x0, y0 = x0 / np.maximum(nx, 1e-12), y0 / np.maximum(ny, 1e-12)
    H = np.matmul(x0.transpose(0, 2, 1), y0)
    U, s, Vt = np.linalg.svd(H)
    V = Vt.transpose(0, 2, 1)
    R = np.matmul(V, U.transpose(0, 2, 1))
    # no reflections
    sign = np.sign(np.linalg.det(R))[:, None]
    V[:, :, -1] *= sign
    s[:, -1] *= sign.ravel()
    R = np.matmul(V, U.transpose(0, 2, 1))
    a = s.sum(1, keepdims=True)[:, :, None] * nx / np.maximum(ny, 1e-12)
    aligned = a * np.matmul(pred - mu_y, R) + mu_x
    return np.linalg.norm(aligned - target, axis=-1).mean(1)


def predict(model: torch.nn.Module, ps: PoseSet, idx: np.ndarray, batch: int = 2048, rf: int = 27,
            runner=None) -> tuple[np.ndarray, np.ndarray]:
    """(pose (N, 17, 3), root (N, 3)) for frames ``idx``: with the torch model, or ``runner(windows) ->
    (pose, root)`` (e.g. an onnxruntime session) when given."""
    poses, roots = [], []
    for k in range(0, len(idx), batch):
        x = ps.windows(idx[k:k + batch], rf).astype(np.float32)
        if runner is None:
            with torch.no_grad():
                p, r = model(torch.from_numpy(x))
            p, r = p.numpy(), r.numpy()
        else:
            p, r = runner(x)
        poses.append(p[:, 0])
        roots.append(r[:, 0])
    return np.concatenate(poses), np.concatenate(roots)


def eval_frames(ps: PoseSet, max_frames: int | None = None, seed: int = 0) -> np.ndarray:
    """Valid frame indices, an evenly spread subset of at most ``max_frames``."""
    idx = np.flatnonzero(ps.valid)
    if max_frames and idx.size > max_frames:
        idx = idx[np.linspace(0, idx.size - 1, max_frames).astype(int)]
    return idx


ANKLE_HEIGHT_M = 0.07     # ankle joint above the floor when the foot is down (0.039 H for H = 1.72 m, + shoe)


def ground_plane_root(ps: PoseSet, idx: np.ndarray, pose: np.ndarray) -> np.ndarray | None:
    """The alternative to the trajectory network, for comparison: (N, 3) pelvis positions from the floor.

    With the camera's extrinsics known (``ps.meta["extrinsics"]``: robot -> camera ``R``, ``t``), the ray
    through the lower ankle's 2D keypoint meets the plane ``ANKLE_HEIGHT_M`` above the floor; the pelvis is
    that point minus the ankle's predicted root-relative offset. None without extrinsics."""
    from edge_runtime.core.skeleton import BASE_HEIGHT_M, L_ANKLE, R_ANKLE
    from firmware_sim.devices.camera import F_PX, HEIGHT_PX, WIDTH_PX

    ext = ps.meta.get("extrinsics")
    if not ext:
        return None
    out = np.empty((len(idx), 3))
    for cam_id in np.unique(ps.camera[idx]):
        e = ext.get(int(cam_id), ext.get(str(int(cam_id))))
        R, t = np.asarray(e["R"]), np.asarray(e["t"])
        sel = ps.camera[idx] == cam_id
        down = R @ np.array([0.0, -1.0, 0.0])                     # robot "down" in the camera frame
        p = pose[sel]
        ankle = np.where((p[:, L_ANKLE] @ down > p[:, R_ANKLE] @ down), L_ANKLE, R_ANKLE)
        k = ps.kp2d[idx[sel], ankle]                              # normalised canonical coordinates
        u = (k[:, 0] + 1) * WIDTH_PX / 2
        v = (k[:, 1] + HEIGHT_PX / WIDTH_PX) * WIDTH_PX / 2
        ray = np.stack([(u - WIDTH_PX / 2) / F_PX, (v - HEIGHT_PX / 2) / F_PX, np.ones(len(u))], 1)
        n = R @ np.array([0.0, 1.0, 0.0])
        x0 = R @ np.array([0.0, ANKLE_HEIGHT_M - BASE_HEIGHT_M, 0.0]) + t
        s = (n @ x0) / np.where(np.abs(ray @ n) > 1e-6, ray @ n, np.nan)
        out[sel] = ray * s[:, None] - p[np.arange(len(p)), ankle]
    return out


def score(ps: PoseSet, idx: np.ndarray, pose: np.ndarray, root: np.ndarray) -> dict:
    """The metrics of predictions for frames ``idx`` (millimetres)."""
    gt_p, gt_r = ps.pose3d[idx].astype(np.float64), ps.root3d[idx].astype(np.float64)
    pose, root = pose.astype(np.float64), root.astype(np.float64)
    per = np.linalg.norm(pose - gt_p, axis=-1)                         # (N, 17)
    frame_err = per.mean(1)
    acts = ps.activity[idx]
    names = ps.meta.get("activity_names", ACTIVITY_NAMES)
    pa = p_mpjpe(pose, gt_p)
    root_err = np.linalg.norm(root - gt_r, axis=-1)
    ground = ground_plane_root(ps, idx, pose)
    extra = {}
    if ground is not None:
        g_err = np.linalg.norm(ground - gt_r, axis=-1)
        g_err = g_err[np.isfinite(g_err)]
        extra = {"ground_plane_root_error_mm": 1000 * float(g_err.mean()),
                 "ground_plane_root_error_median_mm": 1000 * float(np.median(g_err))}
    return {**extra,
        "n_frames": int(len(idx)),
        "mpjpe_mm": 1000 * float(frame_err.mean()),
        "p_mpjpe_mm": 1000 * float(pa.mean()),
        "root_error_mm": 1000 * float(root_err.mean()),
        "root_error_median_mm": 1000 * float(np.median(root_err)),
        "root_depth_error_mm": 1000 * float(np.abs(root[:, 2] - gt_r[:, 2]).mean()),
        "root_relative_error_pct": 100 * float((root_err / gt_r[:, 2]).mean()),
        "abs_mpjpe_mm": 1000 * float(np.linalg.norm(pose + root[:, None] - gt_p - gt_r[:, None], axis=-1).mean()),
        "per_joint_mm": {JOINTS[j]: 1000 * float(per[:, j].mean()) for j in range(per.shape[1])},
        "per_activity_mpjpe_mm": {a: 1000 * float(frame_err[acts == i].mean())
                                  for i, a in enumerate(names) if (acts == i).any()},
        "per_activity_p_mpjpe_mm": {a: 1000 * float(pa[acts == i].mean())
                                    for i, a in enumerate(names) if (acts == i).any()},
    }


def evaluate(model: torch.nn.Module, ps: PoseSet, max_frames: int | None = None, runner=None) -> dict:
    """:func:`score` of the model (or ``runner``) on the valid frames of ``ps`` (subsampled to ``max_frames``)."""
    idx = eval_frames(ps, max_frames)
    rf = model.config.receptive_field if model is not None else 27
    pose, root = predict(model, ps, idx, rf=rf, runner=runner)
    return score(ps, idx, pose, root)


# --------------------------------------------------------------------------- checkpoints
def save_checkpoint(path: str | Path, model: LifterNet, train_cfg: TrainConfig | None = None, **extra) -> Path:
    """``torch.save`` of the config, the weights and any JSON-able extras."""
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    torch.save({"arch": "lifter", "config": model.config.to_dict(), "state_dict": model.state_dict(),
                "train_config": train_cfg.to_dict() if train_cfg else None, **extra}, p)
    return p


def load_checkpoint(path: str | Path, strided: bool = True) -> tuple[LifterNet, dict]:
    """(model in eval mode, the whole checkpoint dict). Raises ValueError naming the file when it is not a lifter."""
    try:
        ck = torch.load(path, map_location="cpu", weights_only=False)
    except (OSError, RuntimeError, EOFError) as e:
        raise ValueError(f"{path}: not a readable checkpoint ({type(e).__name__})") from None
    if not isinstance(ck, dict) or ck.get("arch") != "lifter":
        raise ValueError(f"{path}: field 'arch': not a lifter checkpoint")
    model = LifterNet(LifterConfig.from_dict(ck["config"]), strided=strided)
    model.load_state_dict(ck["state_dict"])
    return model.eval(), ck


def state_digest(model: torch.nn.Module) -> str:
    """A short hash of the weights (reproducibility checks)."""
    import hashlib

    h = hashlib.sha256()
    for k, v in model.state_dict().items():
        h.update(k.encode())
        h.update(v.detach().cpu().numpy().tobytes())
    return h.hexdigest()[:16]


def fmt_metrics(m: dict) -> str:
    return (f"MPJPE {m['mpjpe_mm']:.1f} mm, P-MPJPE {m['p_mpjpe_mm']:.1f} mm, root {m['root_error_mm']:.0f} mm "
            f"({m['root_relative_error_pct']:.1f} % of depth), n={m['n_frames']}")


__all__ = ["TrainConfig", "fit", "evaluate", "score", "predict", "p_mpjpe", "save_checkpoint", "load_checkpoint",
           "state_digest", "fmt_metrics"]
