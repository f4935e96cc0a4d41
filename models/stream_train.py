"""Training of the streaming classifier (:mod:`models.stream_net`) on the cohort's continuous streams.

    model = fit_stream(recordings, width=64, epochs=16, seed=0)     # python -m models stream-train

The capture models (:mod:`models.train`) learn from detector windows; this one learns from every 25 Hz
step of the recordings, as the box will run it. It reproduces session 21's prototype
(reports/wearable/stream_s21/train.py) draw for draw, so that the same seed gives the same weights:

* Labels, per window end t (the class the box should report at t):
  :func:`firmware_sim.scenarios.scoring.class_at`, the rule drive-eval scores every hop by: a distraction's
  class from ``ONSET_IGNORE_S`` after its start to its end; no loss from its start to ``ONSET_IGNORE_S`` (the
  hand has only just left the wheel, as in an Other motion: either answer there teaches the wrong one) nor for
  ``AFTER_END_IGNORE_S`` after its end (the hand on its way back, the window still mostly the distraction);
  Other everywhere else.
* Each epoch draws ``SAMPLES`` window ends: half inside distractions, a quarter within ``NEAR_OTHER_S`` of
  an Other motion (the false alerts' source), a quarter anywhere else (``sampling="s21"``, the default).
  ``sampling="hard"`` (session 23) splits the Other half into ``HARD_SHARES``: near the Other motions that
  session 21 found raising false alerts (``HARD_KINDS``: the passenger-seat reach looks like Marker), the
  hand's return after a distraction (``AFTER_END_IGNORE_S`` to ``RETURN_S`` after its end, labelled Other:
  the other source of false alerts), near any Other motion, anywhere else. ``sampling="hard2"`` (session 24)
  widens the hard pool to every Other kind that still raises false alerts at a lower threshold
  (``HARD2_KIND_WEIGHTS``, chosen on a validation cohort, reports/wearable/stream_s24/rule.md) and gives it
  a larger share (``HARD2_SHARES``), each kind drawn by its weight. The window length is drawn per batch in
  ``W_RANGE_S``: one length-agnostic model, W chosen on development drives.
* Augmentation, per window: a rotation about a random axis by up to ``ROT_DEG`` (strap position), a gain
  in 1 +- ``GAIN``, a bias N(0, ``BIAS_MPS2``) per axis, white noise ``NOISE_MPS2``.
* AdamW (weight decay 1e-3), one-cycle learning rate peaking at ``LR``, batch ``BATCH``, plain
  cross-entropy (the sampling balances distraction and Other).
* Deterministic for a seed: :func:`models.train.seed_everything` (one intra-op thread), one numpy
  Generator for every draw, in the prototype's order.

Checkpoint: :func:`models.train.save_checkpoint`'s layout with ``arch = "stream"``; the width is read
back from the weights (:func:`load_stream_checkpoint`).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from edge_runtime.wearable.labels import CLASSES, OTHER
from firmware_sim.scenarios.scoring import AFTER_END_IGNORE_S, NOT_SCORED, ONSET_IGNORE_S, class_at
from models.stream_net import STEP_S, StreamNet, step_end_s, to25, width_of, windows
from models.train import save_checkpoint, seed_everything

ARCH = "stream"
NEAR_OTHER_S = 3.0
IGNORE = NOT_SCORED
W_RANGE_S = (2.0, 4.0)
SAMPLES = 120_000
"""Window ends per epoch."""
BATCH = 256
LR = 3e-3
WEIGHT_DECAY = 1e-3
ROT_DEG = 25.0
GAIN = 0.1
BIAS_MPS2 = 0.3
NOISE_MPS2 = 0.05
HARD_KINDS = ("grab_from_seat", "shift_gear")
"""Other motions behind most of stream B's false alerts on drive seed 1 (reports/wearable/stream_s21/report.md)."""
RETURN_S = 4.0
"""A window ending up to this long after a distraction's end still holds the hand's return."""
SAMPLINGS = ("s21", "hard", "hard2")
HARD_SHARES = {"distraction": 0.5, "near_hard": 0.125, "returns": 0.125, "near_other": 0.125, "far_other": 0.125}
"""``sampling="hard"``: the share of each pool in an epoch's window ends."""
HARD2_KIND_WEIGHTS = {"grab_from_seat": 27, "hand_to_knee": 9, "shift_gear": 8, "hand_to_lap": 7, "adjust_vent": 6,
                      "adjust_mirror": 4, "touch_arm": 3}
"""``sampling="hard2"``: the Other kinds drawn near, each in proportion to its weight: session 23's c1's false
alerts per kind on the validation cohort (cohort seed 3, not a training cohort or a drive) at threshold 0.65,
every kind with at least 5 % of its motions raising one (reports/wearable/stream_s24/rule.md)."""
HARD2_SHARES = {"distraction": 0.5, "near_hard": 0.2, "returns": 0.125, "near_other": 0.075, "far_other": 0.1}
"""``sampling="hard2"``: the share of each pool in an epoch's window ends (``near_hard``: near the kinds of
``HARD2_KIND_WEIGHTS``)."""
DEFAULT_WIDTH, DEFAULT_EPOCHS = 64, 16
"""Session 21's m64: width 48 for 8 epochs reached 0.870 recall at <= 1.55 false alerts / h on drive seed 1,
width 64 for 16 epochs 0.950 (reports/wearable/stream_s21/report.md)."""
I_OTHER = CLASSES.index(OTHER)


def step_labels(n_steps: int, events: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    """Per 25 Hz step of a recording: the class index to learn (``IGNORE``: none) and whether it lies within
    ``NEAR_OTHER_S`` of an Other motion. ``events``: the simulator's truth (label, start_s, end_s)."""
    t_s = step_end_s(n_steps)
    near_other = np.zeros(n_steps, bool)
    for e in events:
        if e["label"] == OTHER:
            near_other |= (t_s >= e["start_s"] - NEAR_OTHER_S) & (t_s <= e["end_s"] + NEAR_OTHER_S)
    y = class_at(t_s, events, CLASSES)
    return y, near_other


def near_kinds(n_steps: int, events: list[dict], kinds) -> dict[str, np.ndarray]:
    """Per Other kind of ``kinds``, per 25 Hz step: within ``NEAR_OTHER_S`` of a motion of that kind."""
    t_s = step_end_s(n_steps)
    near = {k: np.zeros(n_steps, bool) for k in kinds}
    for e in events:
        if e["label"] == OTHER and e.get("kind") in near:
            near[e["kind"]] |= (t_s >= e["start_s"] - NEAR_OTHER_S) & (t_s <= e["end_s"] + NEAR_OTHER_S)
    return near


def hard_masks(n_steps: int, events: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    """Per 25 Hz step: within ``NEAR_OTHER_S`` of an Other motion of ``HARD_KINDS``, and within the hand's
    return after a distraction (``AFTER_END_IGNORE_S`` to ``RETURN_S`` after its end). Both only say where
    to draw; :func:`step_labels` says what is learnt there."""
    t_s = step_end_s(n_steps)
    near_hard = np.logical_or.reduce(list(near_kinds(n_steps, events, HARD_KINDS).values()))
    returns = np.zeros(n_steps, bool)
    for e in events:
        if e["label"] != OTHER:
            returns |= (t_s > e["end_s"] + AFTER_END_IGNORE_S) & (t_s <= e["end_s"] + RETURN_S)
    return near_hard, returns


@dataclass
class StreamSet:
    """The recordings end to end at 25 Hz, with what each step teaches and which steps may end a window."""

    x25: np.ndarray
    """(n, 3) float32 m/s^2."""
    y: np.ndarray
    distraction: np.ndarray
    near_other: np.ndarray
    far_other: np.ndarray
    """Window-end step indices of the three draws (a window never reaches back into the previous recording)."""
    hours: float
    near_hard: np.ndarray | None = None
    returns: np.ndarray | None = None
    """Window-end step indices of ``sampling="hard"``'s two extra pools (Other steps only)."""
    near_kind: dict[str, np.ndarray] | None = None
    """Window-end step indices near each kind of ``HARD2_KIND_WEIGHTS`` (``sampling="hard2"``; Other steps only)."""


def stream_set(recordings) -> StreamSet:
    """``recordings``: (acc_mps2 (n, 3) at 100 Hz, truth events) pairs, in order."""
    xs, ys, nears, whole, hards, rets = [], [], [], [], [], []
    kinds = {k: [] for k in HARD2_KIND_WEIGHTS}
    for acc, events in recordings:
        x25 = to25(acc)
        y, near = step_labels(len(x25), events)
        hard, ret = hard_masks(len(x25), events)
        for k, m in near_kinds(len(x25), events, kinds).items():
            kinds[k].append(m)
        xs.append(x25)
        ys.append(y)
        nears.append(near)
        hards.append(hard)
        rets.append(ret)
        whole.append(np.arange(len(x25)) >= int(W_RANGE_S[1] / STEP_S))  # room for the longest window behind
    y, near, ok = np.concatenate(ys), np.concatenate(nears), np.concatenate(whole)
    other = ok & (y == I_OTHER)
    x25 = np.concatenate(xs)
    return StreamSet(x25, y, np.flatnonzero(ok & (y >= 0) & (y != I_OTHER)), np.flatnonzero(other & near),
                     np.flatnonzero(other & ~near), len(x25) * STEP_S / 3600.0,
                     near_hard=np.flatnonzero(other & np.concatenate(hards)),
                     returns=np.flatnonzero(other & np.concatenate(rets)),
                     near_kind={k: np.flatnonzero(other & np.concatenate(m)) for k, m in kinds.items()})


def cohort_recordings(subjects: int, seed: int | tuple[int, ...], minutes: float):
    """The simulated cohort's recordings as (float32 acc, events): what ``models.dataset.build_cohort_datasets``
    windows for the capture models, kept whole; several cohort seeds: their cohorts one after another."""
    from firmware_sim.devices.wrist import simulate_cohort  # the simulator is only needed here

    for s in cohort_seeds(seed):
        for rec in simulate_cohort(n_subjects=subjects, seed=s, minutes_per_trial=minutes):
            yield rec.acc_mps2.astype(np.float32), [e.to_json() for e in rec.events]


def cohort_seeds(seed: int | tuple[int, ...] | list[int]) -> tuple[int, ...]:
    return (seed,) if isinstance(seed, int) else tuple(seed)


def epoch_ends(data: StreamSet, sampling: str, rng: np.random.Generator) -> np.ndarray:
    """One epoch's ``SAMPLES`` window ends, shuffled (module docstring: ``sampling``)."""
    if sampling == "s21":  # the prototype's draws, in its order
        ends = np.concatenate([rng.choice(data.distraction, SAMPLES // 2), rng.choice(data.near_other, SAMPLES // 4),
                               rng.choice(data.far_other, SAMPLES - SAMPLES // 2 - SAMPLES // 4)])
    elif sampling in ("hard", "hard2"):
        counts = {k: int(SAMPLES * v) for k, v in (HARD_SHARES if sampling == "hard" else HARD2_SHARES).items()}
        counts["far_other"] += SAMPLES - sum(counts.values())
        pools = {k: [(getattr(data, k), n)] for k, n in counts.items()}
        if sampling == "hard2":
            pools["near_hard"] = kind_draws(data.near_kind, counts["near_hard"])
        ends = np.concatenate([rng.choice(pool, n) for k in counts for pool, n in pools[k]])
    else:
        raise ValueError(f"sampling {sampling!r}: one of {SAMPLINGS}")
    rng.shuffle(ends)
    return ends


def kind_draws(near_kind: dict[str, np.ndarray], n: int) -> list[tuple[np.ndarray, int]]:
    """``sampling="hard2"``'s near-hard draw: (pool, count) per kind of ``HARD2_KIND_WEIGHTS`` that occurs in
    the data, the ``n`` window ends split by the kinds' weights (the rounding's remainder to the heaviest)."""
    present = {k: w for k, w in HARD2_KIND_WEIGHTS.items() if len(near_kind.get(k, ()))}
    if not present:
        raise ValueError(f"sampling 'hard2': no motion of {', '.join(HARD2_KIND_WEIGHTS)} in the data")
    total = sum(present.values())
    counts = {k: int(n * w / total) for k, w in present.items()}
    counts[max(present, key=present.get)] += n - sum(counts.values())
    return [(near_kind[k], c) for k, c in counts.items()]


def rotations(n: int, max_deg: float, rng: np.random.Generator) -> np.ndarray:
    """n rotation matrices (n, 3, 3) about random axes by up to ``max_deg`` (Rodrigues' formula: the
    prototype's draws, so the same seed gives the same weights)."""
    axis = rng.standard_normal((n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    angle = rng.uniform(0, np.radians(max_deg), n)[:, None, None]
    k = np.zeros((n, 3, 3))
    k[:, 0, 1], k[:, 0, 2], k[:, 1, 2] = -axis[:, 2], axis[:, 1], -axis[:, 0]
    k -= k.transpose(0, 2, 1)
    return np.eye(3)[None] + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


def augment(xb: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(N, 3, T) windows -> rotated, gained, biased, noisy float32 copies (module docstring)."""
    n = len(xb)
    x = np.einsum("nij,njt->nit", rotations(n, ROT_DEG, rng), xb)
    gain = rng.uniform(1 - GAIN, 1 + GAIN, (n, 1, 1))
    x = x * gain + rng.normal(0, BIAS_MPS2, (n, 3, 1))
    return (x + rng.normal(0, NOISE_MPS2, x.shape)).astype(np.float32)


def fit_stream(data: StreamSet, *, width: int = DEFAULT_WIDTH, epochs: int = DEFAULT_EPOCHS, seed: int = 0,
               sampling: str = "s21", log=print) -> tuple[StreamNet, dict]:
    """Train a StreamNet on ``data``; returns the model in eval mode and its last epoch's loss and accuracy."""
    seed_everything(seed)
    rng = np.random.default_rng(seed)
    model = StreamNet(width=width)
    opt = torch.optim.AdamW(model.parameters(), lr=LR, weight_decay=WEIGHT_DECAY)
    steps_per_epoch = SAMPLES // BATCH
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=LR, total_steps=max(1, epochs * steps_per_epoch))
    loss_fn = nn.CrossEntropyLoss()
    lengths = (int(W_RANGE_S[0] / STEP_S), int(W_RANGE_S[1] / STEP_S) + 1)
    last = {}
    for epoch in range(epochs):
        ends = epoch_ends(data, sampling, rng)
        model.train()
        total, right, seen = 0.0, 0, 0
        for b in range(steps_per_epoch):
            e = ends[b * BATCH:(b + 1) * BATCH]
            xb = torch.from_numpy(augment(windows(data.x25, e, int(rng.integers(*lengths))), rng))
            yb = torch.from_numpy(data.y[e])
            logits = model(xb)
            loss = loss_fn(logits, yb)
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            total += loss.item() * len(e)
            right += int((logits.argmax(1) == yb).sum())
            seen += len(e)
        last = {"loss": round(total / seen, 4), "train_accuracy_augmented": round(right / seen, 4)}
        log(f"epoch {epoch + 1}/{epochs}: loss {last['loss']:.4f}, train accuracy {last['train_accuracy_augmented']:.3f}")
    return model.eval(), last


def train_stream(out_dir, *, width: int = DEFAULT_WIDTH, epochs: int = DEFAULT_EPOCHS, seed: int = 0,
                 subjects: int = 20, cohort_seed: int | tuple[int, ...] = 0, minutes: float = 15.0,
                 sampling: str = "s21", log=print):
    """``python -m models stream-train``: simulate the cohort(s), train, write OUT/model.pt; returns its path."""
    seeds = cohort_seeds(cohort_seed)
    data = stream_set(cohort_recordings(subjects, seeds, minutes))
    log(f"cohort seed {','.join(map(str, seeds))}: {subjects} subjects x 6 trials x {minutes:g} min each, "
        f"{data.hours:.1f} h; window ends: distraction {len(data.distraction)}, near Other {len(data.near_other)}, "
        f"elsewhere {len(data.far_other)}, near {'/'.join(HARD_KINDS)} {len(data.near_hard)}, "
        f"returns {len(data.returns)}; near each hard2 kind "
        f"{', '.join(f'{k} {len(v)}' for k, v in data.near_kind.items())}; sampling {sampling}")
    model, last = fit_stream(data, width=width, epochs=epochs, seed=seed, sampling=sampling, log=log)
    return save_checkpoint(out_dir, model, arch=ARCH, classes=CLASSES, seed=seed, epochs=epochs,
                           metrics={**last, "parameters": sum(p.numel() for p in model.parameters())},
                           data={"cohort_seed": seeds[0] if len(seeds) == 1 else list(seeds), "subjects": subjects,
                                 "minutes_per_trial": minutes, "onset_ignore_s": ONSET_IGNORE_S,
                                 "after_end_ignore_s": AFTER_END_IGNORE_S, "w_range_s": list(W_RANGE_S),
                                 "sampling": sampling})


def training_command(meta: dict) -> str:
    """The ``python -m models stream-train`` command that rebuilds a checkpoint of :func:`train_stream`."""
    d = meta.get("data", {})
    cs = d.get("cohort_seed")
    seeds = ",".join(map(str, cs)) if isinstance(cs, list) else cs
    sampling = f" --sampling {d['sampling']}" if d.get("sampling", "s21") != "s21" else ""
    return (f"python -m models stream-train --out DIR --width {meta.get('width')} --epochs {meta.get('epochs')} "
            f"--seed {meta.get('seed')} --subjects {d.get('subjects')} --cohort-seed {seeds} "
            f"--minutes {d.get('minutes_per_trial'):g}{sampling}")


def load_stream_checkpoint(path) -> tuple[StreamNet, dict]:
    """(model in eval mode, meta) from a ``stream-train`` DIR/model.pt (or that directory); also reads the
    prototype's checkpoints (``{"state", "width", ...}``)."""
    from pathlib import Path

    from models.dataset import DataError

    p = Path(path)
    p = p / "model.pt" if p.is_dir() else p
    if not p.is_file():
        raise DataError(f"{p}: checkpoint not found")
    ck = torch.load(p, map_location="cpu", weights_only=False)
    state = ck.get("state_dict", ck.get("state"))
    if state is None or "conv.0.weight" not in state:
        raise DataError(f"{p}: field 'state_dict': not a streaming classifier's weights")
    model = StreamNet(classes=len(ck.get("classes", CLASSES)), width=width_of(state))
    model.load_state_dict(state)
    meta = {k: v for k, v in ck.items() if k not in ("state_dict", "state")}
    meta.setdefault("classes", list(CLASSES))
    meta.setdefault("arch", ARCH)
    meta["width"] = model.width
    return model.eval(), meta
