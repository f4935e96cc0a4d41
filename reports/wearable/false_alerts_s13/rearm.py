"""A counterfactual, not the product: re-arm the detector when a capture's early step says Other.

    PYTHONPATH=. python reports/wearable/false_alerts_s13/rearm.py --seed 1 --cache CACHE.npz [--steps 2,3]

Half of the false alerts on development drives are captures triggered by an Other motion a few seconds
before a distraction: the capture reaches into the distraction, its full window calls it one, and the
detector, paused for the capture's 6 s, never triggers on the distraction itself (scored as a false alert and
a missed distraction). This asks what would happen if a capture whose top class (class weights applied) after
S = k sub-windows is Other, and which has raised no alert and continues no event, were dropped there and the
detector re-armed at once, so that a distraction starting mid-capture gets a trigger and a capture of its own.

The runtime's loop (:class:`~edge_runtime.wearable.loop.WearableLoop`) is fed 0.1 s blocks, and a subclass
drops the capture at step k (the model's outputs are cached per capture and step, as in diagnose.py); the
figures are drive-eval's scoring. Development seeds 1 and 5 only.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

from edge_runtime import config
from edge_runtime.wearable import alerts, classifier, detector, loop, sources  # noqa: F401 - their sections
from edge_runtime.wearable.classifier import Engine
from edge_runtime.wearable.labels import OTHER
from edge_runtime.wearable.loop import WearableLoop
from edge_runtime.wearable.sources import ImuBlock
from firmware_sim.scenarios.drive_eval import held_out_drives
from firmware_sim.scenarios.early_tuning import CachedClassifier, _figures, score

BLOCK_FRAMES = 10
DEVELOPMENT_SEEDS = (1, 5)


class RearmLoop(WearableLoop):
    """The loop, but a capture whose top class after ``rearm_step`` sub-windows is Other (no alert raised, no
    event continued) is dropped there and the detector may trigger again on the next frame."""

    rearm_step: int | None = None
    dropped = 0

    def _classify(self, st, data, steps):
        verdict = super()._classify(st, data, steps)
        if (steps == self.rearm_step and st.last_label == OTHER and st.event is None and not st.continues
                and self.detector.capturing):
            st.steps.clear()  # no further decision for this capture: _steps_of forgets it
            self.detector._cap_trigger = None  # a counterfactual: reaches into the detector's state
            self.detector._allowed_from = self.detector.n_seen
            self.dropped += 1
        return verdict


def run(drives, clf, cfg, rearm_step: int | None) -> tuple[list[list[dict]], int]:
    out, dropped = [], 0
    for drive in drives:
        lp = RearmLoop(clf, cfg.detector, cfg.alerts, sample_rate_hz=cfg.imu.sample_rate_hz)
        lp.rearm_step = rearm_step
        acc = np.ascontiguousarray(drive.acc_mps2, dtype=np.float32)
        ds = []
        for i in range(0, len(acc), BLOCK_FRAMES):
            ds += lp.feed(ImuBlock(i / cfg.imu.sample_rate_hz, acc[i:i + BLOCK_FRAMES]))
        out.append([d.to_json() for d in ds])
        dropped += lp.dropped
    return out, dropped


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seed", type=int, required=True)
    p.add_argument("--hours", type=float, default=10.0)
    p.add_argument("--cache", required=True)
    p.add_argument("--steps", default="2,3", help="the step k to drop an Other capture at, comma-separated")
    p.add_argument("--out")
    a = p.parse_args(argv)
    if a.seed not in DEVELOPMENT_SEEDS:
        print(f"--seed {a.seed}: development seeds only ({DEVELOPMENT_SEEDS})", file=sys.stderr)
        return 2
    cfg = config.load(None)
    clf = CachedClassifier(Engine.from_params(cfg.model), Path(a.cache))
    drives = list(held_out_drives(a.hours, a.seed))
    rows = []
    for k in [None] + [int(s) for s in a.steps.split(",") if s.strip()]:
        ds, dropped = run(drives, clf, cfg, k)
        row = {"seed": a.seed, "rearm_step": k, "captures_dropped": dropped, **_figures(score(drives, ds))}
        rows.append(row)
        print(json.dumps(row), flush=True)
    clf.save()
    if a.out:
        Path(a.out).write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
