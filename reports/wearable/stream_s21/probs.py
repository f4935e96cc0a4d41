"""Session 21 (issue 12): the streaming model's outputs on drive-eval's drives, computed once and cached.

    PYTHONPATH=. OMP_NUM_THREADS=1 nice -n 10 python reports/wearable/stream_s21/probs.py MODEL.pt SEED \
        [--window-s 2,3,4] [--base-hop-steps 3]

Every ``--base-hop-steps`` 25 Hz steps (3: every 0.12 s; the policy subsamples hops of 0.24, 0.36, 0.48 s from
it), the class probabilities of the last W s, for each W -> /work/s9-runs/stream21/probs_<model>_seedSEED_wW.npz
(per drive: times of the decisions (s, the last raw frame they saw) and probabilities (n, 6)).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from data import ALLOWED_DRIVE_SEEDS, DEFAULT_DIR, load_streams  # noqa: E402
from net import STEP_S, load, to25, windows  # noqa: E402

BATCH = 2048


def probs_path(model_path: str, seed: int, window_s: float) -> Path:
    return DEFAULT_DIR / f"probs_{Path(model_path).stem}_seed{seed}_w{window_s:g}.npz"


def drive_probs(model, acc_mps2: np.ndarray, window_s: float, hop_steps: int) -> tuple[np.ndarray, np.ndarray]:
    """(times (n,), probabilities (n, 6)) of decisions every ``hop_steps`` 25 Hz steps, from the first step at
    which a whole window is there."""
    x25 = to25(acc_mps2)
    steps = int(round(window_s / STEP_S))
    ends = np.arange(steps - 1, len(x25), hop_steps)
    out = []
    with torch.no_grad():
        for b in range(0, len(ends), BATCH):
            out.append(torch.softmax(model(torch.from_numpy(windows(x25, ends[b:b + BATCH], steps))), 1).numpy())
    return (ends * 4 + 3) / 100.0, np.concatenate(out).astype(np.float32)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("model")
    ap.add_argument("seed", type=int)
    ap.add_argument("--window-s", default="2,3,4")
    ap.add_argument("--base-hop-steps", type=int, default=3)
    a = ap.parse_args(argv)
    if a.seed not in ALLOWED_DRIVE_SEEDS:
        raise SystemExit(f"drive seed {a.seed}: development seeds {ALLOWED_DRIVE_SEEDS} only")
    torch.set_num_threads(1)
    model, _ = load(a.model)
    drives = load_streams(DEFAULT_DIR / f"drives_seed{a.seed}")
    for w in (float(v) for v in a.window_s.split(",")):
        arrays = {}
        for k, d in enumerate(drives):
            t, p = drive_probs(model, d["acc_mps2"], w, a.base_hop_steps)
            arrays[f"t{k}"], arrays[f"p{k}"] = t, p
        path = probs_path(a.model, a.seed, w)
        np.savez(path, **arrays)
        print(f"W {w:g} s: {len(drives)} drives -> {path}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
