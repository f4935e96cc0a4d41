"""Session 21 (issue 12): the shipped policy on the same cached drives, by drive-eval's own path and scorer.

    PYTHONPATH=. OMP_NUM_THREADS=1 nice -n 10 python reports/wearable/stream_s21/shipped.py SEED OUT.json

Each drive of ``data.py drives SEED`` (drive-eval's 20 h of that seed) is replayed through the runtime as
``drive-eval`` does it (:func:`edge_runtime.wearable.command.replay` with the shipped configuration, ``[alerts]
decision = "early"``, the shipped int8 model), and scored by the same ``ModeScore`` (frame) as the streaming policy
(``policy.score_drives``). The decisions are kept in /work/s9-runs/stream21/shipped_decisions_seedSEED.json for the
hybrid (``hybrid.py``).
"""
from __future__ import annotations

import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from data import ALLOWED_DRIVE_SEEDS, DEFAULT_DIR, load_streams  # noqa: E402
from policy import meets, score_drives  # noqa: E402


def decisions_path(seed: int) -> Path:
    return DEFAULT_DIR / f"shipped_decisions_seed{seed}.json"


def main(argv: list[str]) -> int:
    from edge_runtime import config
    from edge_runtime.wearable import alerts, classifier, detector, loop, sources  # noqa: F401 - their sections
    from edge_runtime.wearable.classifier import Engine
    from edge_runtime.wearable.command import replay

    seed, out = int(argv[0]), Path(argv[1])
    if seed not in ALLOWED_DRIVE_SEEDS:
        raise SystemExit(f"drive seed {seed}: development seeds {ALLOWED_DRIVE_SEEDS} only")
    cfg = config.override(config.load(None), "alerts", decision="early")
    engine = Engine.from_params(cfg.model)
    drives = load_streams(DEFAULT_DIR / f"drives_seed{seed}")
    t0 = time.perf_counter()
    decisions = []
    for d in drives:
        dec: list[dict] = []
        replay(cfg, engine, d["acc_mps2"], outputs=[lambda x, out=dec: out.append(x.to_json())])
        decisions.append(dec)
    decisions_path(seed).write_text(json.dumps(decisions))
    f, _ = score_drives(drives, decisions)
    res = {"seed": seed, "policy": "shipped (drive-eval's replay, decision early, shipped int8 model and [alerts])",
           "model": engine.name, "figures": f, "meets": meets(f), "wall_s": round(time.perf_counter() - t0, 1)}
    out.write_text(json.dumps(res, indent=1))
    print(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
