"""Session 21 (issue 12): train the trigger-free streaming classifier on the training cohort's continuous streams.

    PYTHONPATH=. OMP_NUM_THREADS=1 nice -n 10 python reports/wearable/stream_s21/train.py OUT.pt \
        [--width 48] [--epochs 12] [--seed 0] [--data /work/s9-runs/stream21/cohort_seed0]

Data: cohort seed 0 only (20 subjects x 6 trials x 15 min, what the shipped ConvLSTM trains on), cached by
``data.py cohort``. No drive and no other cohort is read.

Labels, per window end t (the class the box should report at t):
* a distraction's class while it lasts, from ONSET_IGNORE_S after its start to its end;
* ignored (no loss) from its start to ONSET_IGNORE_S (the hand has only just left the wheel: that is what an Other
  motion looks like too, and forcing either answer there teaches the wrong one) and for AFTER_END_IGNORE_S after
  its end (the hand on its way back, the window still mostly the distraction);
* Other everywhere else (driving, Other motions).

Each epoch draws SAMPLES window ends at random 25 Hz steps: half inside distractions, a quarter within 3 s of an
Other motion, a quarter anywhere else. Window length random per batch, 2-4 s (one length-agnostic model; W is
chosen on drive seed 1). Augmentation (what generalises to a real wrist rather than fitting the simulator): a random
3D rotation of up to 25 deg per window (strap position, left/right tilt), a gain of 0.9-1.1, a bias of N(0, 0.3)
m/s^2 per axis, white noise of 0.05 m/s^2.
"""
from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn as nn

sys.path.insert(0, str(Path(__file__).resolve().parent))
from data import DEFAULT_DIR, load_streams  # noqa: E402
from net import STEP_S, StreamNet, params, to25, windows  # noqa: E402

from edge_runtime.wearable.labels import CLASSES, OTHER  # noqa: E402

ONSET_IGNORE_S = 0.3
AFTER_END_IGNORE_S = 1.0
NEAR_OTHER_S = 3.0
IGNORE = -1
W_RANGE_S = (2.0, 4.0)
SAMPLES = 120_000
BATCH = 256


def step_labels(n_steps: int, events: list[dict]) -> tuple[np.ndarray, np.ndarray]:
    """Per 25 Hz step: the class index to learn (IGNORE: none) and whether it is near an Other motion."""
    t = (np.arange(n_steps) * 4 + 3) / 100.0
    y = np.full(n_steps, CLASSES.index(OTHER), dtype=np.int64)
    near_other = np.zeros(n_steps, bool)
    for e in events:
        if e["label"] == OTHER:
            near_other |= (t >= e["start_s"] - NEAR_OTHER_S) & (t <= e["end_s"] + NEAR_OTHER_S)
    for e in events:
        if e["label"] != OTHER:
            y[(t >= e["start_s"]) & (t <= e["end_s"] + AFTER_END_IGNORE_S)] = IGNORE
            y[(t >= e["start_s"] + ONSET_IGNORE_S) & (t <= e["end_s"])] = CLASSES.index(e["label"])
    return y, near_other


def random_rotations(n: int, max_deg: float, rng: np.random.Generator) -> np.ndarray:
    """n rotation matrices (n, 3, 3) about random axes by up to max_deg (Rodrigues)."""
    axis = rng.standard_normal((n, 3))
    axis /= np.linalg.norm(axis, axis=1, keepdims=True)
    a = rng.uniform(0, np.radians(max_deg), n)[:, None, None]
    K = np.zeros((n, 3, 3))
    K[:, 0, 1], K[:, 0, 2], K[:, 1, 2] = -axis[:, 2], axis[:, 1], -axis[:, 0]
    K -= K.transpose(0, 2, 1)
    return np.eye(3)[None] + np.sin(a) * K + (1 - np.cos(a)) * K @ K


def augment(xb: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """(N, 3, T) windows -> rotated, gained, biased, noisy copies."""
    n = len(xb)
    R = random_rotations(n, 25.0, rng)
    x = np.einsum("nij,njt->nit", R, xb)
    x = x * rng.uniform(0.9, 1.1, (n, 1, 1)) + rng.normal(0, 0.3, (n, 3, 1))
    return (x + rng.normal(0, 0.05, x.shape)).astype(np.float32)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("out")
    ap.add_argument("--width", type=int, default=48)
    ap.add_argument("--epochs", type=int, default=12)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--data", default=str(DEFAULT_DIR / "cohort_seed0"))
    a = ap.parse_args(argv)
    torch.set_num_threads(1)
    torch.manual_seed(a.seed)
    rng = np.random.default_rng(a.seed)

    recs = load_streams(Path(a.data))
    xs, ys, nears = [], [], []
    for r in recs:
        x25 = to25(r["acc_mps2"])
        y, near = step_labels(len(x25), r["events"])
        xs.append(x25)
        ys.append(y)
        nears.append(near)
    offsets = np.cumsum([0] + [len(x) for x in xs])
    X = np.concatenate(xs)
    Y = np.concatenate(ys)
    near = np.concatenate(nears)
    # a window may not reach back into the previous recording: its earliest end is the longest window in
    first = np.concatenate([np.arange(len(x)) >= int(W_RANGE_S[1] / STEP_S) for x in xs])
    dis = np.flatnonzero(first & (Y >= 0) & (Y != CLASSES.index(OTHER)))
    oth_near = np.flatnonzero(first & (Y == CLASSES.index(OTHER)) & near)
    oth_far = np.flatnonzero(first & (Y == CLASSES.index(OTHER)) & ~near)
    print(f"{len(recs)} recordings, {len(X) * STEP_S / 3600:.1f} h; window ends: distraction {len(dis)}, "
          f"near Other {len(oth_near)}, driving {len(oth_far)}; offsets {offsets[-1]}", flush=True)

    model = StreamNet(width=a.width)
    opt = torch.optim.AdamW(model.parameters(), lr=3e-3, weight_decay=1e-3)
    steps_per_epoch = SAMPLES // BATCH
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, max_lr=3e-3, total_steps=a.epochs * steps_per_epoch)
    lossf = nn.CrossEntropyLoss()
    t0 = time.perf_counter()
    for ep in range(a.epochs):
        ends = np.concatenate([rng.choice(dis, SAMPLES // 2), rng.choice(oth_near, SAMPLES // 4),
                               rng.choice(oth_far, SAMPLES - SAMPLES // 2 - SAMPLES // 4)])
        rng.shuffle(ends)
        model.train()
        tot, right, seen = 0.0, 0, 0
        for b in range(steps_per_epoch):
            e = ends[b * BATCH:(b + 1) * BATCH]
            steps = int(rng.integers(int(W_RANGE_S[0] / STEP_S), int(W_RANGE_S[1] / STEP_S) + 1))
            xb = torch.from_numpy(augment(windows(X, e, steps), rng))
            yb = torch.from_numpy(Y[e])
            logits = model(xb)
            loss = lossf(logits, yb)
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            tot += loss.item() * len(e)
            right += int((logits.argmax(1) == yb).sum())
            seen += len(e)
        print(f"epoch {ep + 1}/{a.epochs}: loss {tot / seen:.4f}, train acc {right / seen:.3f}, "
              f"{time.perf_counter() - t0:.0f} s", flush=True)
    torch.save({"state": model.state_dict(), "width": a.width, "epochs": a.epochs, "seed": a.seed,
                "params": params(model), "data": a.data, "onset_ignore_s": ONSET_IGNORE_S,
                "after_end_ignore_s": AFTER_END_IGNORE_S, "w_range_s": W_RANGE_S}, a.out)
    print(f"saved {a.out}: {params(model)} parameters", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
