"""Why the slowest distractions are alerted late (issue 12, session 15): development drives only.

    PYTHONPATH=. python reports/wearable/tail_s15/tail.py --seed 1 --cache CACHE.npz --out OUT.json [--hours 20]

The drives are ``drive-eval``'s (:func:`firmware_sim.scenarios.drive_eval.held_out_drives`) for ``--seed`` (1 or 5
only). The decisions are the runtime's own loop (``early_tuning.decide``) with the model's outputs cached per capture
and step (``early_tuning.CachedClassifier``); scored by trigger (``early_tuning.score``, as sessions 13-14).

Per distraction: onset, the first capture overlapping it (and whose trigger it was), the capture whose alert came
first, its trigger delay, the sub-window count S of the first alert, class and calibrated (class-weighted) confidence
at every S against the step's threshold, and the onset -> first alert frame. The slowest 10 % and the misses get a
cause (:func:`cause`). Written to ``--out`` (JSON); a summary is printed.
"""
from __future__ import annotations

import argparse
import json
import sys
from collections import Counter
from pathlib import Path

import numpy as np

from edge_runtime import config
from edge_runtime.wearable import alerts, classifier, detector, loop, sources  # noqa: F401 - their sections
from edge_runtime.wearable.classifier import Engine, needed_frames
from edge_runtime.wearable.detector import detect_triggers, extract_captures, p3_series
from edge_runtime.wearable.labels import CLASSES, DISTRACTIONS, OTHER
from firmware_sim.scenarios.drive_eval import MATCH_BEFORE_S, held_out_drives, miss_reason
from firmware_sim.scenarios.early_tuning import CachedClassifier, _figures, decide, score
from firmware_sim.scenarios.scoring import raises_alert

DEVELOPMENT_SEEDS = (1, 5)
RATE = 100.0
PRE_S = 1.0
POST_S = 6.0


def step_frame_s(s: int) -> float:
    """When the decision after S sub-windows goes out, after the trigger (s)."""
    return (needed_frames(s) - 1 - 100) / RATE


def weighted(p: np.ndarray, classes: list[str], w: dict[str, float]) -> np.ndarray:
    v = np.asarray(p, float) * np.asarray([w.get(c, 1.0) for c in classes])
    return v / v.sum()


def thresholds(cfg, engine) -> dict[int, float]:
    manifest = dict(engine.early.min_confidence_by_steps)
    out = {}
    for s in range(1, 7):
        t = cfg.alerts.min_confidence_by_steps[s - 1]
        out[s] = t if t >= 0 else manifest.get(s, 0.9 if s < 6 else cfg.alerts.min_confidence)
    return out


def per_step(clf, data: np.ndarray, classes, w, thr) -> list[dict]:
    rows = []
    for s in range(1, 7):
        p = weighted(clf.classify_prefix(data[: needed_frames(s)], s), classes, w)
        k = int(p.argmax())
        rows.append({"S": s, "label": classes[k], "conf": round(float(p[k]), 3),
                     "p_other": round(float(p[classes.index(OTHER)]), 3), "thr": thr[s],
                     "over": bool(classes[k] != OTHER and p[k] >= thr[s])})
    return rows


def analyse(drive, ds, clf, cfg, thr, classes, w) -> list[dict]:
    dcfg = cfg.detector
    truth = [e for e in drive.events if e["label"] in DISTRACTIONS]
    others = [e for e in drive.events if e["label"] == OTHER]
    trig = detect_triggers(drive.acc_mps2, dcfg)
    caps = {c.trigger_index / RATE: c for c in extract_captures(drive.acc_mps2, trig, dcfg)}
    by_trig: dict[float, list[dict]] = {}
    for d in ds:
        by_trig.setdefault(d["t_trigger_s"], []).append(d)
    ax = drive.acc_mps2[:, dcfg.axis]
    p3 = p3_series(ax, dcfg)

    def owner(t):
        return next((e for e in truth if e["start_s"] - MATCH_BEFORE_S <= t <= e["end_s"]), None)

    def statuses(t):
        return sorted({d["status"] for d in by_trig.get(round(t, 3), by_trig.get(t, []))})

    rows = []
    triggers = [round(t / RATE, 3) for t in trig]
    for e in truth:
        on, end = e["start_s"], e["end_s"]
        own = [t for t in triggers if on - MATCH_BEFORE_S <= t <= end]
        overlap = [t for t in triggers if t - PRE_S < end and t + POST_S > on]
        firsts = sorted((d for t in own for d in by_trig.get(t, []) if raises_alert(d)), key=lambda d: d["t_alert_s"])
        # P3 above threshold from 1 s before the onset on (the detector's own rule, pause ignored)
        lo, hi = int((on - MATCH_BEFORE_S) * RATE), int(end * RATE) + 1
        with np.errstate(invalid="ignore"):
            above = np.flatnonzero(p3[lo:hi] > dcfg.threshold_mps2)
        cross = round((lo + int(above[0])) / RATE - on, 2) if above.size else None
        w1 = p3[int(on * RATE): int(on * RATE) + 100]
        prev_other = max((o for o in others if o["end_s"] <= on + 0.5), key=lambda o: o["end_s"], default=None)
        row = {"drive": drive.name, "label": e["label"], "onset_s": on, "duration_s": round(end - on, 2),
               "p3_cross_after_onset_s": cross,
               "p3_max_first_s": round(float(np.nanmax(w1)), 2) if np.isfinite(w1).any() else None,
               "first_overlap_trigger_rel_s": round(overlap[0] - on, 2) if overlap else None,
               "first_overlap_statuses": statuses(overlap[0]) if overlap else None,
               "first_overlap_owned": bool(overlap and overlap[0] in own),
               "first_overlap_owner": None if not overlap else (
                   "this" if overlap[0] in own else ("other distraction" if owner(overlap[0]) else "none")),
               "own_triggers_rel_s": [round(t - on, 2) for t in own],
               "own_statuses": [statuses(t) for t in own],
               "prev_other": None if prev_other is None else {
                   "kind": prev_other.get("kind"), "end_before_onset_s": round(on - prev_other["end_s"], 2)}}
        if firsts:
            f = firsts[0]
            t = f["t_trigger_s"]
            row.update(alerted=True, latency_s=round(f["t_alert_s"] - on, 3), S=f["steps"], status=f["status"],
                       first_label=f["label"], first_conf=round(f["confidence"], 3), correct=f["label"] == e["label"],
                       trigger_delay_s=round(t - on, 2), alerting_capture_index=own.index(t),
                       steps=per_step(clf, caps[int(round(t * RATE)) / RATE].data, classes, w, thr)
                       if int(round(t * RATE)) / RATE in caps else None)
        else:
            row.update(alerted=False, miss_reason=miss_reason(
                [d for t in own for d in by_trig.get(t, [])], drive.acc_mps2, e, dcfg))
        if own:
            t0 = own[0]
            c0 = caps.get(int(round(t0 * RATE)) / RATE)
            row["first_own_steps"] = per_step(clf, c0.data, classes, w, thr) if c0 is not None else None
        if overlap and overlap[0] not in own:
            c0 = caps.get(int(round(overlap[0] * RATE)) / RATE)
            row["first_overlap_steps"] = per_step(clf, c0.data, classes, w, thr) if c0 is not None else None
            ow = next((o for o in others if o["start_s"] - MATCH_BEFORE_S <= overlap[0] <= o["end_s"] + 1.0), None)
            row["first_overlap_other_kind"] = None if ow is None else ow.get("kind")
        rows.append(row)
    return rows


LATE_TRIGGER_S = 1.0
"""A trigger this long after the onset counts as late (the median trigger delay is ~0.3-0.5 s)."""


def cause(r: dict) -> str:
    """The delay's cause of a slow or missed distraction (exclusive, in this order)."""
    t0 = r["first_overlap_trigger_rel_s"]
    if t0 is not None and t0 < -MATCH_BEFORE_S:
        st = r["first_overlap_statuses"] or []
        what = ("its alert a false alert" if any(s in ("alert", "preliminary", "confirmed", "revised") for s in st)
                else "continued an event" if "continued" in st else "judged Other / not confident")
        by = "another distraction" if r["first_overlap_owner"] == "other distraction" else "something before the onset"
        return f"(e) detector busy at onset: capture set off by {by}, {what}"
    if not r["own_triggers_rel_s"]:
        return "(a) no trigger during the distraction: P3 below threshold"
    if r.get("alerted") and r["alerting_capture_index"] == 0:
        late = r["trigger_delay_s"] > LATE_TRIGGER_S
        if r["S"] >= 5:
            return f"(b) confident only at S = {r['S']}, trigger " + (
                f"> {LATE_TRIGGER_S:g} s after onset (a too)" if late else f"<= {LATE_TRIGGER_S:g} s after onset")
        return f"(a) late trigger, alerted at S = {r['S']}" if late else "(other) on-time trigger, S <= 4"
    st0 = r["own_statuses"][0]
    if "continued" in st0:
        return "(d) first own capture continued an earlier event"
    return "(c) first own capture Other / below threshold, a later one alerted" if r.get("alerted") else \
        "(c) own captures Other / below threshold (missed)"


def development_args(doc: str, argv, extra) -> argparse.Namespace | None:
    """--seed (1 or 5 only), --hours, --cache, --out and the ``extra(parser)`` options; None for another seed."""
    p = argparse.ArgumentParser(description=doc.split("\n")[0])
    p.add_argument("--seed", type=int, required=True)
    p.add_argument("--hours", type=float, default=20.0)
    p.add_argument("--cache", required=True)
    p.add_argument("--out", required=True)
    extra(p)
    a = p.parse_args(argv)
    if a.seed not in DEVELOPMENT_SEEDS:
        print(f"--seed {a.seed}: development seeds only ({DEVELOPMENT_SEEDS})", file=sys.stderr)
        return None
    return a


def main(argv=None) -> int:
    def extra(p):
        p.add_argument("--config")
        p.add_argument("--alerts", default="", help="JSON {key: value} of [alerts] keys to replace (a counterfactual)")

    a = development_args(__doc__, argv, extra)
    if a is None:
        return 2
    cfg = config.override(config.load(a.config), "alerts", decision="early", **(json.loads(a.alerts) if a.alerts else {}))
    engine = Engine.from_params(cfg.model)
    clf = CachedClassifier(engine, Path(a.cache))
    classes = list(clf.classes)
    w = dict(zip(CLASSES, cfg.alerts.class_weights))
    thr = thresholds(cfg, engine)
    drives = list(held_out_drives(a.hours, a.seed))
    ds = decide(drives, clf, cfg)
    fig = _figures(score(drives, ds))
    rows = [r for drive, d in zip(drives, ds) for r in analyse(drive, d, clf, cfg, thr, classes, w)]
    clf.save()
    lat = np.asarray([r["latency_s"] for r in rows if r["alerted"]])
    p90 = float(np.percentile(lat, 90))
    for r in rows:
        r["tail"] = (not r["alerted"]) or r["latency_s"] >= p90
        r["cause"] = cause(r) if r["tail"] else None
    out = {"seed": a.seed, "hours": a.hours, "figures": fig, "thresholds": thr, "p90_s": round(p90, 3),
           "model_calls": clf.calls, "events": rows}
    Path(a.out).write_text(json.dumps(out, indent=1))
    print(json.dumps({"seed": a.seed, **fig, "p90": round(p90, 3), "median_check": float(np.median(lat)),
                      "p95_check": float(np.percentile(lat, 95)), "calls": clf.calls}))
    slow = [r for r in rows if r["alerted"] and r["tail"]]
    print("slow by cause:", Counter(r["cause"] for r in slow).most_common())
    print("missed by cause:", Counter(r["cause"] for r in rows if not r["alerted"]).most_common())
    return 0


if __name__ == "__main__":
    sys.exit(main())
