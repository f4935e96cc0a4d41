"""What a change to the early-decision thresholds, the detector's threshold or the capture's placement would do to
the onset -> first alert latency, recall and false alerts: development drives only (issue 12, session 15).

    PYTHONPATH=. python reports/wearable/tail_s15/levers.py --seed 1 --cache CACHE.npz --out OUT.json \
        [--hours 20] [--levers JSON]

Each lever is the shipped configuration (early decisions) with ``alerts`` keys and/or ``detector`` keys replaced,
re-run through the runtime's own loop (``early_tuning.decide``'s loop) with the model's outputs cached per capture
and step (``early_tuning.CachedClassifier``: captures a detector change makes new go through the model once). Scored
by trigger (``early_tuning.score``), as sessions 13-14. ``detector`` keys build a ``DetectorConfig`` directly, so a
capture placed earlier around its trigger (``pre_frames`` + ``post_frames`` = 700, the model's capture) can be tried
although a box file may not set it: a counterfactual for the model as trained (captures 1 s before the trigger),
not a product setting. Seeds 1 and 5 only.
"""
from __future__ import annotations

import json
import sys
import time
from dataclasses import fields, replace
from pathlib import Path

import numpy as np

from edge_runtime import config
from edge_runtime.wearable import alerts, classifier, detector, loop, sources  # noqa: F401 - their sections
from edge_runtime.wearable.classifier import Engine
from edge_runtime.wearable.loop import WearableLoop
from edge_runtime.wearable.sources import ImuBlock
from firmware_sim.scenarios.drive_eval import ModeScore, held_out_drives
from firmware_sim.scenarios.early_tuning import CachedClassifier, _figures, score
from reports.wearable.tail_s15.tail import development_args

LEVERS: list[dict] = [
    {"name": "shipped"},
    *[{"name": f"early threshold {t} at S = 2..5", "alerts": {"min_confidence_by_steps": [t] * 5 + [-1.0]}}
      for t in (0.8, 0.7, 0.6, 0.5)],
    {"name": "manifest thresholds (S2 0.59, S3 0.46, S4-5 0)", "alerts": {"min_confidence_by_steps": [-1.0] * 6}},
    {"name": "S4-5 at 0.7 (S2-3 0.9)", "alerts": {"min_confidence_by_steps": [0.9, 0.9, 0.9, 0.7, 0.7, -1.0]}},
    {"name": "S4 0.6, S5 0.5 (S2-3 0.9)", "alerts": {"min_confidence_by_steps": [0.9, 0.9, 0.9, 0.6, 0.5, -1.0]}},
    *[{"name": f"detector threshold {t}", "detector": {"threshold_mps2": t}} for t in (4.5, 4.0, 3.5)],
    *[{"name": f"capture {p / 100:g} s before the trigger", "detector": {"pre_frames": p, "post_frames": 700 - p}}
      for p in (150, 199)],
]
"""Round 1 (seed 1). Keys: ``alerts`` and ``detector`` (replaced keys), ``merge_early`` (classes whose
probabilities are summed into the first's at S < 6: one preliminary class for a confusable pair),
``class_early`` ({class: threshold} at S < 6 for those classes instead of the configured early threshold)."""

ROUND2: list[dict] = [
    {"name": "shipped"},
    {"name": "Phone+Texting one class at S < 6", "merge_early": ["Phone", "Texting"]},
    *[{"name": f"Phone+Texting one class at S < 6, early threshold {t}", "merge_early": ["Phone", "Texting"],
       "alerts": {"min_confidence_by_steps": [t] * 5 + [-1.0]}} for t in (0.8, 0.7)],
    *[{"name": f"Drink/Marker/TouchScreen early threshold {t}",
       "class_early": {"Drink": t, "Marker": t, "TouchScreen": t}} for t in (0.8, 0.7, 0.6)],
    {"name": "detector 4.0 + Phone+Texting one class at S < 6", "merge_early": ["Phone", "Texting"],
     "detector": {"threshold_mps2": 4.0}},
    {"name": "detector 4.0 + Phone+Texting one class at S < 6, early threshold 0.8", "merge_early": ["Phone", "Texting"],
     "detector": {"threshold_mps2": 4.0}, "alerts": {"min_confidence_by_steps": [0.8] * 5 + [-1.0]}},
]
"""Round 2 (seed 1), after round 1: the early steps' errors are Phone <-> Texting (tail.py)."""


class MergedEarly:
    """The cached classifier, with the probabilities of ``group`` summed into its first class at S < 6."""

    def __init__(self, clf, group: list[str]):
        self.clf, self.classes, self.early_steps, self.early = clf, clf.classes, clf.early_steps, clf.early
        self.idx = [self.classes.index(c) for c in group]

    def classify_prefix(self, x, steps):
        p = np.array(self.clf.classify_prefix(x, steps), np.float32)
        if steps < 6:
            p[self.idx[0]] = p[self.idx].sum()
            p[self.idx[1:]] = 0.0
        return p

    def classify_capture(self, x700):
        return self.classify_prefix(x700, 6)


def class_early_policy(policy, by_class: dict[str, float], early: float = 0.9):
    """The policy with an early threshold per class (the steps whose configured threshold is ``early``)."""
    class PerClass(type(policy)):
        def status(self, label, confidence, threshold=None):
            if threshold is not None and threshold == early and label in by_class:
                threshold = by_class[label]
            return super().status(label, confidence, threshold)

    return PerClass(**{f.name: getattr(policy, f.name) for f in fields(policy)})


def decide(drives, clf, cfg, det, policy=None) -> list[list[dict]]:
    out = []
    for drive in drives:
        lp = WearableLoop(clf, det, policy or cfg.alerts, sample_rate_hz=cfg.imu.sample_rate_hz)
        out.append([d.to_json() for d in lp.feed(ImuBlock(0.0, drive.acc_mps2))])
    return out


def main(argv=None) -> int:
    a = development_args(__doc__, argv, lambda p: p.add_argument(
        "--levers", default="", help="JSON list of lever dicts instead of LEVERS, or 'round2'"))
    if a is None:
        return 2
    cfg = config.override(config.load(None), "alerts", decision="early")
    engine = Engine.from_params(cfg.model)
    clf = CachedClassifier(engine, Path(a.cache))
    drives = list(held_out_drives(a.hours, a.seed))
    levers = ROUND2 if a.levers == "round2" else json.loads(a.levers) if a.levers else LEVERS
    rows = []
    for lever in levers:
        name, akeys, dkeys = lever["name"], lever.get("alerts", {}), lever.get("detector", {})
        t0, calls0 = time.time(), clf.calls
        c = config.override(cfg, "alerts", **akeys) if akeys else cfg
        det = replace(cfg.detector, **dkeys) if dkeys else cfg.detector
        model = MergedEarly(clf, lever["merge_early"]) if lever.get("merge_early") else clf
        policy = class_early_policy(c.alerts, lever["class_early"]) if lever.get("class_early") else None
        ds = decide(drives, model, c, det, policy)
        s = score(drives, ds)
        m = ModeScore(attribution="trigger", detector=det)
        firsts = [ef for drive, d in zip(drives, ds) for ef in m.add(drive, d) if ef[1] is not None]
        t = np.asarray(m.onset_to_alert_s)
        pair = {"Phone", "Texting"}
        group_right = sum(f["label"] == e["label"] or {f["label"], e["label"]} <= pair for e, f in firsts)
        row = {"lever": name, "alerts": akeys, "detector": dkeys, **_figures(s),
               "p90_s": round(float(np.percentile(t, 90)), 3), "within_3_5_s_of_alerted": round(float((t <= 3.5).mean()), 4),
               "within_3_5_s_of_all": round(float((t <= 3.5).sum() / s["distractions"]), 4),
               "class_accuracy_phone_eq_texting": round(group_right / len(firsts), 4),
               "new_model_calls": clf.calls - calls0, "wall_s": round(time.time() - t0, 1)}
        rows.append(row)
        print(json.dumps(row), flush=True)
        clf.save()
    Path(a.out).write_text(json.dumps({"seed": a.seed, "hours": a.hours, "levers": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
