"""Session 23 (issue 12): a candidate's per-hop probabilities on the cached development drives, and the operating
point picked by the rule of rule.md (fixed before any candidate output). Reuses session 21's policy and scoring
(reports/wearable/stream_s21/policy.py: its fp32 figures equal the product path's, reports/wearable/stream_s22).

    PYTHONPATH=. OMP_NUM_THREADS=1 python reports/wearable/stream_s23/sweep.py probs CKPT_DIR NAME SEED
    PYTHONPATH=. OMP_NUM_THREADS=1 python reports/wearable/stream_s23/sweep.py sweep NAME SEED OUT.json

Drives: /work/s9-runs/stream23/drives_seedSEED (session 21's data.py, drive-eval's 20 h of that seed); seeds 1 and 5
only. Probabilities: /work/s9-runs/stream23/probs_NAME_seedSEED_wW.npz.
"""
from __future__ import annotations

import itertools
import json
import sys
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "stream_s21"))
from data import ALLOWED_DRIVE_SEEDS, load_streams  # noqa: E402
from policy import Policy, alerts, score_drives  # noqa: E402
from probs import drive_probs  # noqa: E402

from models.stream_train import load_stream_checkpoint  # noqa: E402

DIR = Path("/work/s9-runs/stream23")
GRID = {"window_s": (3.0, 4.0), "hop_mult": (2, 4), "score": ("top",), "k": (2, 3, 4),
        "thr": (0.5, 0.6, 0.65, 0.7, 0.75, 0.8, 0.85, 0.9), "off_s": (1.0, 2.0)}
CURRENT_SEED1 = {"recall": 0.9514, "class": 0.9361, "median_s": 2.591, "false_per_h": 1.40}


def path(name: str, seed: int, w: float) -> Path:
    return DIR / f"probs_{name}_seed{seed}_w{w:g}.npz"


def choose(points: list[dict]) -> dict | None:
    """rule.md: among the points at least as good as the current on seed-1 recall, class and median, the fewest
    false alerts per hour; ties: the higher recall, then the lower p95. None if no point qualifies."""
    c = CURRENT_SEED1
    ok = [q for q in points if q["figures"]["recall"] >= c["recall"] and (q["figures"]["class"] or 0) >= c["class"]
          and q["figures"]["median_s"] is not None and q["figures"]["median_s"] <= c["median_s"]]
    return min(ok, key=lambda q: (q["figures"]["false_per_h"], -q["figures"]["recall"], q["figures"]["p95_s"]),
               default=None)


def fallback(points: list[dict]) -> dict | None:
    """rule.md, for the record: the highest recall with false alerts <= 1.40 / h and class >= 0.90, ties to the
    lower median."""
    ok = [q for q in points if q["figures"]["false_per_h"] <= 1.40 and (q["figures"]["class"] or 0) >= 0.90]
    return min(ok, key=lambda q: (-q["figures"]["recall"], q["figures"]["median_s"]), default=None)


def sweep_points(name: str, seed: int, drives: list[dict], grid: dict) -> list[dict]:
    """Every point of ``grid`` (window_s, hop_mult, score, k, thr, off_s) scored on the cached probabilities."""
    points = []
    for w in grid["window_s"]:
        z = np.load(path(name, seed, w))
        cache = [(z[f"t{k}"], z[f"p{k}"]) for k in range(len(drives))]
        for hop, sc, k, thr, off in itertools.product(*(grid[g] for g in ("hop_mult", "score", "k", "thr", "off_s"))):
            pol = Policy(w, hop, sc, k, thr, off)
            points.append({"policy": pol.__dict__, "figures": score_drives(drives, [alerts(t, p, pol) for t, p in cache])[0]})
    return points


def main(argv: list[str]) -> int:
    what, seed = argv[0], int(argv[3] if argv[0] == "probs" else argv[2])
    if seed not in ALLOWED_DRIVE_SEEDS:
        raise SystemExit(f"drive seed {seed}: development seeds {ALLOWED_DRIVE_SEEDS} only")
    drives = load_streams(DIR / f"drives_seed{seed}")
    if what == "probs":
        torch.set_num_threads(1)
        model, _ = load_stream_checkpoint(argv[1])
        for w in GRID["window_s"]:
            arrays = {}
            for k, d in enumerate(drives):
                arrays[f"t{k}"], arrays[f"p{k}"] = drive_probs(model, d["acc_mps2"], w, 3)
            np.savez(path(argv[2], seed, w), **arrays)
            print(f"W {w:g}: {path(argv[2], seed, w)}", flush=True)
        return 0
    name, out = argv[1], Path(argv[3])
    points = sweep_points(name, seed, drives, GRID)
    best, fb = choose(points), fallback(points)
    out.write_text(json.dumps({"seed": seed, "model": name, "rule": choose.__doc__, "chosen": best,
                               "fallback_rule": fallback.__doc__, "fallback": fb, "points": points}, indent=1))
    print("chosen:", json.dumps(best), "\nfallback:", json.dumps(fb))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
