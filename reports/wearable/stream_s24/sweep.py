"""Session 24 (issue 12): a candidate's operating point on drive seed 1 by rule.md (fixed before any candidate
output). The probabilities are session 23's cache (reports/wearable/stream_s23/sweep.py probs CKPT_DIR NAME SEED:
/work/s9-runs/stream23/probs_NAME_seedSEED_wW.npz, every 0.12 s, W 3 and 4 s); the scoring is session 21's
policy.py (drive-eval's frame scoring; its fp32 figures equal the product path's, reports/wearable/stream_s22).

    PYTHONPATH=. python reports/wearable/stream_s24/sweep.py NAME SEED OUT.json
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "stream_s23"))
from sweep import DIR, load_streams, sweep_points  # noqa: E402

GRID = {"window_s": (3.0, 4.0), "hop_mult": (2, 4), "score": ("top", "any"), "k": (2, 3, 4),
        "thr": (0.5, 0.55, 0.6, 0.65, 0.7, 0.75, 0.8, 0.85, 0.9), "off_s": (1.0, 2.0)}
MUST = {"recall": 0.95, "class": 0.90, "false_per_h": 0.5}


def choose(points: list[dict]) -> dict | None:
    """rule.md: among the points with recall >= 0.95, class >= 0.90 and false alerts <= 0.5 / h, the lowest median;
    ties: the lower p95, then the fewer false alerts. None if no point qualifies."""
    ok = [q for q in points if q["figures"]["recall"] >= MUST["recall"] and (q["figures"]["class"] or 0) >= MUST["class"]
          and q["figures"]["false_per_h"] <= MUST["false_per_h"] and q["figures"]["median_s"] is not None]
    return min(ok, key=lambda q: (q["figures"]["median_s"], q["figures"]["p95_s"], q["figures"]["false_per_h"]),
               default=None)


def main(argv: list[str]) -> int:
    name, seed, out = argv[0], int(argv[1]), Path(argv[2])
    if seed != 1:
        raise SystemExit("rule.md: the operating point is chosen on drive seed 1 only")
    points = sweep_points(name, seed, load_streams(DIR / f"drives_seed{seed}"), GRID)
    best = choose(points)
    out.write_text(json.dumps({"seed": seed, "model": name, "rule": choose.__doc__, "chosen": best, "points": points},
                              indent=1))
    print("chosen:", json.dumps(best))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
