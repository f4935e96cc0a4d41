"""Training: one loop for every neural architecture, readable in one sitting.

    model = fit("convlstm", X, y, n_classes=6, epochs=40, seed=0)

* Input: capture windows ``X`` (N, 700, 3) m/s^2 at 100 Hz and labels ``y``.
  They go through :func:`edge_runtime.wearable.classifier.preprocess`, the one
  preprocessing path the product also runs (700 -> 200 frames, 6 x 33 x 3),
  once per run (or pass ``X`` already preprocessed, (N, 6, 33, 3)).
* Loss: cross-entropy with class-balanced weights (N / (K * count)), so the
  rare "Other" class counts as much as a distraction; optionally with label
  smoothing or a focal term (``label_smoothing``, ``focal_gamma``: recipe
  choices compared on the selection cohort, :mod:`models.selection` stage 3). The ConvLSTM is trained
  with deep supervision over prefixes (issue 12): the same head reads the
  LSTM's state after every one of the 6 sub-windows and the loss is the
  ``STEP_LOSS_WEIGHTS``-weighted mean of the six cross-entropies, so one model
  (same 79,598 parameters) decides after S = 1..6 sub-windows; the full
  capture weighs most because it stays the confirming decision. Adam (lr 1e-3; 1e-2 for
  the LSTM, see ``DEFAULT_LR``), cosine
  decay to lr/10 over the run, gradient norm clipped at 5.
* Augmentation (training windows only). The training set goes through
  ``preprocess`` once; augmentation then acts on the model input, seen as 198
  resampled frames (200/7 Hz) x 3 axes. It models what differs between a
  ground-truth window and a detector capture, and between wrists:
    - time shift: the window starts up to ``SHIFT_BACK`` resampled frames
      earlier or ``SHIFT_FWD`` later (1 frame = 35 ms; edge frames repeated).
      A detector trigger comes after the truth onset (on the simulated cohort
      the median delay is 0.8-1.1 s, for Drink 2.2 s), so captures start later
      than the truth window: the shift is skewed that way. How far forward
      (``shift_fwd``), the epochs and whether the training subjects' detector
      captures join the training set are chosen on a separate simulated
      validation cohort, never on the held-out subjects (:mod:`models.selection`;
      an earlier version chose the shift on held-out subjects' figures);
    - gain x U(1 - GAIN, 1 + GAIN) (sensor scale error);
    - rotation by up to ``ROT_DEG`` degrees about a random axis (strap fit);
    - Gaussian noise ``NOISE_MPS2``;
    - optionally (``time_warp``) the motion played faster or slower by a factor
      up to 1 + time_warp either way, about the trigger (people differ in how
      long they dwell and move: the simulator draws per-subject dwell factors
      with a log-normal sd of 0.25 and movement-time factors with sd 0.12).
  Rotation and gain commute with the (linear, per-axis) resampler, so they
  are exactly what the same change of the raw stream would give.
* Determinism: for a given seed and thread count, two runs give identical
  weights (torch.manual_seed, a seeded numpy Generator for shuffling and
  augmentation, torch.use_deterministic_algorithms, one intra-op thread by
  default).
* Data parallel: when a torch.distributed process group is up (``torchrun
  --nproc_per_node=2 -m models train ...``), the model is wrapped in
  DistributedDataParallel and a DistributedSampler gives each rank its shard;
  every rank ends with the same weights; only rank 0 writes files.

The LDA baseline (``arch="lda"``) is fitted in closed form by :mod:`models.lda`.

Checkpoint (export/ relies on it):
``torch.save({"arch", "state_dict", "classes", "n_classes", "seed", "epochs",
"metrics", "data"}, DIR/"model.pt")``; the LDA baseline is pickled to
``DIR/"model.pkl"`` (``{"arch": "lda", "model", "classes", "n_classes", ...}``).
"""
from __future__ import annotations

import math
import os
import pickle
import random
from pathlib import Path

import numpy as np
import torch
import torch.utils.deterministic
from scipy.spatial.transform import Rotation
from torch import nn
from torch.nn.parallel import DistributedDataParallel as DDP
from torch.utils.data.distributed import DistributedSampler
from tqdm import tqdm

from edge_runtime.wearable.classifier import preprocess
from models.lda import LDAClassifier
from models.nets import ARCHS, build

SHIFT_BACK, SHIFT_FWD = 3, 50  # resampled frames (35 ms each): -0.1 s ... +1.75 s
GAIN = 0.05
ROT_DEG = 8.0
NOISE_MPS2 = 0.05
DEFAULT_EPOCHS = {"convlstm": 25, "cnn": 25, "lstm": 20, "lda": 0, "lda_summary": 0}  # ~1 min per LOSO fold on 1 core
STEP_LOSS_WEIGHTS = (0.5, 0.5, 0.5, 0.5, 0.5, 1.0)
"""ConvLSTM loss weight of the decision after 1..6 sub-windows: the full-capture decision weighs twice
any early one so that it stays today's decision. Compared on the selection cohort with every step at
1.0 and with S = 2, 3 at 1.0 (``python -m models select --stage early``): kept, the others within
0.005 of its early-step macro-F1 (reports/wearable/selection/selection.md)."""
LDA_FEATURES = {"lda": "input", "lda_summary": "summary"}
"""The LDA baselines: on the 594-number model input, and on 12 summary statistics (issue 12)."""
DEFAULT_LR = {"convlstm": 1e-3, "cnn": 1e-3, "lstm": 1e-2}
"""The LSTM over 198 raw frames learns slowly at 1e-3: on 16 -> 4 held-out simulated subjects it
reached onset-capture macro-F1 0.62 after 12 epochs at 3e-3 and 0.79 after 20 epochs at 1e-2."""


# --------------------------------------------------------------------------- helpers

def seed_everything(seed: int, threads: int | None = 1) -> None:
    random.seed(seed)
    np.random.seed(seed % 2**32)
    torch.manual_seed(seed)
    torch.use_deterministic_algorithms(True, warn_only=True)
    # Deterministic mode also fills every new tensor with NaN to expose reads of uninitialised memory;
    # every op here writes its whole output, so the fill changes no value and cost ~5 % of a step.
    torch.utils.deterministic.fill_uninitialized_memory = False
    if threads:
        torch.set_num_threads(threads)


def dist_info() -> tuple[bool, int, int]:
    """(distributed?, rank, world size)."""
    if torch.distributed.is_available() and torch.distributed.is_initialized():
        return True, torch.distributed.get_rank(), torch.distributed.get_world_size()
    return False, 0, 1


def is_main_process() -> bool:
    return dist_info()[1] == 0


def class_weights(y: np.ndarray, n_classes: int) -> torch.Tensor:
    counts = np.bincount(y, minlength=n_classes).astype(np.float64)
    w = np.where(counts > 0, len(y) / (n_classes * np.maximum(counts, 1)), 0.0)
    return torch.tensor(w, dtype=torch.float32)


RECIPE_FIT_KEYS = ("shift_fwd", "schedule_epochs", "step_loss_weights", "label_smoothing", "focal_gamma", "rot_deg",
                   "time_warp")
"""The keys of a selection recipe (models.selection) that are arguments of :func:`fit`."""
TRIGGER_FRAME = 100 * 200 / 700
"""The trigger's place in the 198 resampled frames (a capture starts 1 s = 100 raw frames before it)."""


def recipe_fit_kwargs(recipe: dict) -> dict:
    """The :func:`fit` keyword arguments a recipe sets (absent keys keep fit's defaults), so that the
    selection, the LOSO folds and the shipped assets train one recipe the same way."""
    return {k: recipe[k] for k in RECIPE_FIT_KEYS if recipe.get(k) is not None}


class WeightedLoss(nn.Module):
    """Class-weighted cross-entropy, with optional label smoothing and focal term (Lin et al. 2017:
    the loss of an example is scaled by (1 - p_true)^gamma, so that the hard, confusable captures
    weigh more than the many easy ones). gamma = 0 is torch's weighted cross-entropy (with its label
    smoothing); with gamma > 0 the smoothed target of an example is weighted by its own class's weight."""

    def __init__(self, weight: torch.Tensor, label_smoothing: float = 0.0, focal_gamma: float = 0.0):
        super().__init__()
        self.register_buffer("weight", weight)
        self.smoothing, self.gamma = float(label_smoothing), float(focal_gamma)

    def forward(self, logits: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
        if self.gamma == 0.0:
            return nn.functional.cross_entropy(logits, target, weight=self.weight, label_smoothing=self.smoothing)
        logp = torch.log_softmax(logits, dim=1)
        k = logits.shape[1]
        soft = torch.full_like(logp, self.smoothing / k).scatter_(1, target[:, None], 1 - self.smoothing + self.smoothing / k)
        focal = (1 - logp.gather(1, target[:, None]).exp()).pow(self.gamma)
        w = self.weight[target]
        return (w * focal[:, 0] * -(soft * logp).sum(1)).sum() / w.sum()


def time_warped(seq: torch.Tensor, factor: np.ndarray) -> torch.Tensor:
    """(B, n, 3) frames played ``factor`` (B,) times as fast about ``TRIGGER_FRAME`` (linear
    interpolation; frames past either end repeat the edge frame, as the time shift's do)."""
    n = seq.shape[1]
    pos = np.clip(TRIGGER_FRAME + (np.arange(n)[None, :] - TRIGGER_FRAME) * factor[:, None], 0, n - 1)
    lo = np.floor(pos).astype(np.int64)
    hi = np.minimum(lo + 1, n - 1)
    w = torch.from_numpy((pos - lo).astype(np.float32))[:, :, None]
    take = lambda i: torch.gather(seq, 1, torch.from_numpy(i)[:, :, None].expand(-1, -1, 3))  # noqa: E731
    return take(lo) * (1 - w) + take(hi) * w


def augment(x: torch.Tensor, rng: np.random.Generator, shift_fwd: int = SHIFT_FWD,
            rot_deg: float = ROT_DEG, time_warp: float = 0.0) -> torch.Tensor:
    """Random shift / gain / rotation / noise of model inputs (B, 6, 33, 3) (see the module docstring)."""
    b = x.shape[0]
    seq = x.reshape(b, -1, 3)  # (B, 198, 3): the resampled frames in time order
    n = seq.shape[1]
    shift = rng.integers(-SHIFT_BACK, shift_fwd + 1, size=b)
    idx = torch.from_numpy(np.clip(np.arange(n)[None, :] + shift[:, None], 0, n - 1))
    seq = torch.gather(seq, 1, idx[:, :, None].expand(b, n, 3))
    if time_warp > 0:  # drawn only when asked, so that the other draws stay those of earlier recipes
        seq = time_warped(seq, np.exp(rng.uniform(-np.log1p(time_warp), np.log1p(time_warp), size=b)))
    axis = rng.normal(size=(b, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    angle = np.deg2rad(rng.uniform(-rot_deg, rot_deg, size=(b, 1)))
    rot = Rotation.from_rotvec(axis * angle).as_matrix() * rng.uniform(1 - GAIN, 1 + GAIN, size=(b, 1, 1))
    seq = seq @ torch.from_numpy(rot.transpose(0, 2, 1).astype(np.float32))
    seq = seq + torch.from_numpy(rng.normal(scale=NOISE_MPS2, size=seq.shape).astype(np.float32))
    return seq.reshape(x.shape)


def preprocess_all(X: np.ndarray, chunk: int = 1024) -> torch.Tensor:
    """(N, 700, 3) m/s^2 -> (N, 6, 33, 3) model inputs, through the product's ``preprocess``."""
    if len(X) == 0:
        return torch.zeros((0, 6, 33, 3))
    return torch.from_numpy(np.concatenate([preprocess(X[i:i + chunk]) for i in range(0, len(X), chunk)]))


# --------------------------------------------------------------------------- the loop

def fit(arch: str, X: np.ndarray, y: np.ndarray, n_classes: int, *, epochs: int, seed: int,
        batch_size: int = 64, lr: float | None = None, val: tuple[np.ndarray, np.ndarray] | None = None,
        progress: bool = True, augmentation: bool = True, threads: int | None = 1, desc: str = "",
        shift_fwd: int = SHIFT_FWD, schedule_epochs: int | None = None, on_epoch=None,
        step_loss_weights=None, label_smoothing: float = 0.0, focal_gamma: float = 0.0,
        rot_deg: float = ROT_DEG, time_warp: float = 0.0, peek_frames=(), peek_loss_weight: float = 0.5):
    """Train ``arch`` on windows X (N, 700, 3) m/s^2 (or already preprocessed, (N, 6, 33, 3)) with labels
    y; returns the model in eval mode. ``lr`` defaults to ``DEFAULT_LR[arch]``. The cosine decay
    spans ``schedule_epochs`` (default ``epochs``): stopping at an epoch the validation chose keeps
    the schedule it was chosen under. ``on_epoch(epoch, model)`` is called after every epoch.
    ``step_loss_weights``: the ConvLSTM's weight of the decision after 1..6 sub-windows (default
    ``STEP_LOSS_WEIGHTS``; the selection compares others). ``label_smoothing``, ``focal_gamma``: see
    :class:`WeightedLoss`; ``rot_deg``: the rotation augmentation's reach; ``time_warp``: see :func:`augment`.
    ``peek_frames``: the ConvLSTM is also supervised on the decisions after the first k frames of every
    sub-window, k in ``peek_frames`` (:meth:`models.nets.ConvLSTM.peeks`), each weighted
    ``peek_loss_weight`` on the scale of ``step_loss_weights``."""
    y = np.asarray(y, dtype=np.int64)
    if arch in LDA_FEATURES:
        return LDAClassifier(n_classes, LDA_FEATURES[arch]).fit(X, y)
    if arch not in ARCHS:
        raise ValueError(f"unknown architecture {arch!r}; choose one of {sorted(ARCHS) + ['lda']}")
    X = np.asarray(X, dtype=np.float32)
    inputs = torch.from_numpy(X) if X.shape[1:] == (6, 33, 3) else preprocess_all(X)
    labels = torch.from_numpy(y)
    distributed, rank, world = dist_info()
    seed_everything(seed, threads)
    model = build(arch, n_classes)  # same init on every rank (same seed); DDP also broadcasts it
    net = DDP(model) if distributed else model
    opt = torch.optim.Adam(model.parameters(), lr=DEFAULT_LR[arch] if lr is None else lr)
    loss_fn = WeightedLoss(class_weights(y, n_classes), label_smoothing, focal_gamma)
    sw = STEP_LOSS_WEIGHTS if step_loss_weights is None else tuple(float(w) for w in step_loss_weights)
    peek_frames = tuple(int(k) for k in peek_frames) if arch == "convlstm" else ()
    total_w = sum(sw) + len(peek_frames) * len(sw) * peek_loss_weight
    step_w = torch.tensor(sw) / total_w if arch == "convlstm" else None
    sampler = DistributedSampler(range(len(y)), num_replicas=world, rank=rank, shuffle=True, seed=seed)
    rng = np.random.default_rng([seed, rank])  # augmentation differs per rank
    steps_per_epoch = math.ceil(len(sampler) / batch_size)
    total = max(1, (schedule_epochs or epochs) * steps_per_epoch)
    sched = torch.optim.lr_scheduler.LambdaLR(opt, lambda s: 0.1 + 0.9 * 0.5 * (1 + math.cos(math.pi * min(s, total) / total)))

    bar = tqdm(range(epochs), desc=desc or arch, unit="epoch", disable=not (progress and rank == 0),
               leave=False, dynamic_ncols=True)
    for epoch in bar:
        net.train()
        sampler.set_epoch(epoch)
        order = np.fromiter(iter(sampler), dtype=np.int64)
        running, seen = 0.0, 0
        for i in range(0, len(order), batch_size):
            idx = order[i:i + batch_size]
            ti = torch.from_numpy(idx)
            xb, yb = inputs[ti], labels[ti]
            if augmentation:
                xb = augment(xb, rng, shift_fwd, rot_deg, time_warp)
            if step_w is None:
                loss = loss_fn(net(xb), yb)
            else:  # deep supervision: the decision after every sub-window
                steps = net(xb, all_steps=True)  # (B, 6, K)
                loss = sum(w * loss_fn(steps[:, s], yb) for s, w in enumerate(step_w))
                if peek_frames:  # and the decisions on partial sub-windows
                    peeks = model.peeks(xb, peek_frames)  # (B, 6, P, K)
                    loss = loss + peek_loss_weight / total_w * sum(
                        loss_fn(peeks[:, s, j], yb) for s in range(peeks.shape[1]) for j in range(len(peek_frames)))
            opt.zero_grad(set_to_none=True)
            loss.backward()
            nn.utils.clip_grad_norm_(model.parameters(), 5.0)
            opt.step()
            sched.step()
            running += loss.item() * len(idx)
            seen += len(idx)
        post = {"loss": f"{running / max(seen, 1):.3f}"}
        if val is not None and rank == 0 and (epoch == epochs - 1 or epoch % 5 == 4):
            from models.evaluate import predict
            post["val_acc"] = f"{np.mean(predict(model, val[0]).argmax(1) == np.asarray(val[1])):.3f}"
        bar.set_postfix(post)
        if on_epoch is not None:
            on_epoch(epoch, model)
    bar.close()
    if distributed:  # DDP keeps replicas in lockstep; check it rather than trust it
        flat = torch.cat([p.detach().flatten() for p in model.parameters()])
        lo, hi = flat.clone(), flat.clone()
        torch.distributed.all_reduce(lo, op=torch.distributed.ReduceOp.MIN)
        torch.distributed.all_reduce(hi, op=torch.distributed.ReduceOp.MAX)
        model.ddp_info = {"world_size": world, "backend": torch.distributed.get_backend(),
                          "ranks_identical": bool(torch.equal(lo, hi))}
    return model.eval()


# --------------------------------------------------------------------------- checkpoints

def save_checkpoint(out_dir, model, *, arch: str, classes, seed: int, epochs: int, metrics: dict,
                    data: dict) -> Path:
    """DIR/model.pt (neural) or DIR/model.pkl (LDA); see the module docstring for the layout."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    meta = {"arch": arch, "classes": list(classes), "n_classes": len(classes), "seed": int(seed),
            "epochs": int(epochs), "metrics": metrics, "data": data}
    if arch in LDA_FEATURES:
        path = out / "model.pkl"
        with open(path, "wb") as f:
            pickle.dump({**meta, "model": model}, f)
        return path
    path = out / "model.pt"
    torch.save({**meta, "state_dict": {k: v.detach().cpu() for k, v in model.state_dict().items()}}, path)
    return path


def load_checkpoint(path):
    """(model in eval mode, meta dict) from DIR/model.pt, DIR/model.pkl or a directory holding one."""
    p = Path(path)
    if p.is_dir():
        p = p / "model.pt" if (p / "model.pt").exists() else p / "model.pkl"
    if not p.exists():
        from models.dataset import DataError
        raise DataError(f"{p}: checkpoint not found")
    if p.suffix == ".pkl":
        with open(p, "rb") as f:
            meta = pickle.load(f)
        return meta.pop("model"), meta
    ckpt = torch.load(p, map_location="cpu", weights_only=False)
    model = build(ckpt["arch"], ckpt["n_classes"])
    model.load_state_dict(ckpt["state_dict"])
    meta = {k: v for k, v in ckpt.items() if k != "state_dict"}
    return model.eval(), meta


def init_distributed_from_env() -> bool:
    """Join the torchrun process group (gloo, CPU) when launched by torchrun with WORLD_SIZE > 1."""
    if int(os.environ.get("WORLD_SIZE", "1")) > 1 and not torch.distributed.is_initialized():
        torch.distributed.init_process_group("gloo")
        return True
    return False
