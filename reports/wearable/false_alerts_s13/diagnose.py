"""Why the wearable's false alerts happen, and what each policy lever would cost: development drives only.

    PYTHONPATH=. python reports/wearable/false_alerts_s13/diagnose.py --seed 1 --cache CACHE.npz \
        --out OUT.json [--hours 10] [--config BOX.toml] [--sweep]

The drives are ``drive-eval``'s for ``--seed`` (:func:`firmware_sim.scenarios.drive_eval.held_out_drives`); only the
validation seed 1 and the development seed 5 are accepted. The decisions are the runtime's own
(:class:`~edge_runtime.wearable.loop.WearableLoop`, via ``early_tuning.decide``) with the model's outputs cached per
capture and step (``early_tuning.CachedClassifier``), so a lever re-runs the policy exactly, not a filter on recorded
decisions. Printed and written (``--out``, JSON): every false alert with what the driver was doing, its class,
confidence, step, status, whether a later decision withdrew it and whether the full window alone would have
alerted; every missed distraction with where it was lost; with ``--sweep`` the levers' figures.
"""
from __future__ import annotations

import argparse
import json
import sys
from collections import Counter
from pathlib import Path

from edge_runtime import config
from edge_runtime.wearable import alerts, classifier, detector, loop, sources  # noqa: F401 - their sections
from edge_runtime.wearable.classifier import Engine
from edge_runtime.wearable.labels import DISTRACTIONS, OTHER
from firmware_sim.scenarios.drive_eval import MATCH_BEFORE_S, held_out_drives, miss_reason
from firmware_sim.scenarios.early_tuning import CachedClassifier, _figures, decide, score
from firmware_sim.scenarios.scoring import raises_alert

DEVELOPMENT_SEEDS = (1, 5)
RETURN_S = 3.0
"""A trigger this soon after a distraction ended: the hand returning from it (early_tuning's AFTER_DISTRACTION_S)."""
AFTER_S = 15.0
"""Within this after a distraction ended (and not the return): a repeat of the ended distraction's motion."""
BEFORE_S = 10.0
"""Within this before a distraction's matching window opens: the stretch right before a distraction."""


def context(drive, t: float) -> str:
    """What the driver was doing at a trigger that belongs to no distraction."""
    others = [e for e in drive.events if e["label"] == OTHER and e["start_s"] - MATCH_BEFORE_S <= t <= e["end_s"] + 1.0]
    truth = [e for e in drive.events if e["label"] in DISTRACTIONS]
    ended = [t - e["end_s"] for e in truth if e["end_s"] < t]
    ahead = [e["start_s"] - MATCH_BEFORE_S - t for e in truth if e["start_s"] - MATCH_BEFORE_S > t]
    near = ("after a distraction" if ended and min(ended) <= AFTER_S else
            "before a distraction" if ahead and min(ahead) <= BEFORE_S else "")
    if others:
        return f"Other {others[0].get('kind', '?')}" + (f" ({near})" if near else "")
    if ended and min(ended) <= RETURN_S:
        return "hand returning after a distraction"
    if near:
        return f"no Other motion, {near}"
    return "driving, no hand event"


CAPTURE_AFTER_S = 6.0
"""A capture holds its trigger's 1 s before and 6 s after (700 frames at 100 Hz)."""


def neighbours(truth: list[dict], ds: list[dict], d: dict) -> dict:
    """The distractions next to a false alert's trigger: the one after (does the capture reach into it, the same
    class, when its alert frame went out relative to its onset, what became of it) and the one before."""
    t = d["t_trigger_s"]
    nxt = min((e for e in truth if e["start_s"] - MATCH_BEFORE_S > t), key=lambda e: e["start_s"], default=None)
    prv = max((e for e in truth if e["end_s"] < t), key=lambda e: e["end_s"], default=None)
    out: dict = {}
    if nxt is not None:
        own = [u for u in ds if nxt["start_s"] - MATCH_BEFORE_S <= u["t_trigger_s"] <= nxt["end_s"]]
        out["next"] = {"label": nxt["label"], "onset_after_trigger_s": round(nxt["start_s"] - t, 2),
                       "capture_reaches_it": nxt["start_s"] < t + CAPTURE_AFTER_S,
                       "same_class": nxt["label"] == d["label"],
                       "alert_frame_after_onset_s": round(d["t_alert_s"] - nxt["start_s"], 2),
                       "own_alert": any(raises_alert(u) for u in own),
                       "own_statuses": sorted({u["status"] for u in own})}
    if prv is not None:
        out["previous"] = {"label": prv["label"], "ended_before_trigger_s": round(t - prv["end_s"], 2),
                           "same_class": prv["label"] == d["label"]}
    return out


def full_window_of(ds: list[dict], trigger: float) -> dict | None:
    return next((d for d in ds if d["t_trigger_s"] == trigger and d["steps"] == 6), None)


def false_alerts(drives, decisions, fw_decisions, policy, manifest6: float) -> list[dict]:
    thr6 = policy.min_confidence_by_steps[5] if policy.min_confidence_by_steps[5] >= 0 else manifest6
    rows = []
    for drive, ds, fw in zip(drives, decisions, fw_decisions):
        truth = [e for e in drive.events if e["label"] in DISTRACTIONS]
        for d in sorted((d for d in ds if raises_alert(d)), key=lambda d: d["t_alert_s"]):
            if any(e["start_s"] - MATCH_BEFORE_S <= d["t_trigger_s"] <= e["end_s"] for e in truth):
                continue
            own = [u for u in ds if u["t_trigger_s"] == d["t_trigger_s"]]
            last = full_window_of(ds, d["t_trigger_s"])
            alone = full_window_of(fw, d["t_trigger_s"])
            p = sorted(d["probs"].values())
            other = next((e for e in drive.events if e["label"] == OTHER
                          and e["start_s"] - MATCH_BEFORE_S <= d["t_trigger_s"] <= e["end_s"] + 1.0), None)
            rows.append({
                **neighbours(truth, ds, d),
                "other_motion": None if other is None else {
                    "kind": other.get("kind"), "trigger_after_its_start_s": round(d["t_trigger_s"] - other["start_s"], 2),
                    "duration_s": round(other["end_s"] - other["start_s"], 2),
                    "after_previous_distraction_end_s": min(
                        (round(other["start_s"] - e["end_s"], 2) for e in truth if e["end_s"] <= other["start_s"]),
                        default=None)},
                "drive": drive.name, "kind": drive.kind, "t_trigger_s": d["t_trigger_s"],
                "context": context(drive, d["t_trigger_s"]), "label": d["label"],
                "confidence": round(d["confidence"], 3), "margin": round(p[-1] - p[-2], 3),
                "p_other": round(d["probs"][OTHER], 3), "steps": d["steps"], "status": d["status"],
                "withdrawn": any(u["status"] == "withdrawn" for u in own),
                "final": None if last is None else {"label": last["label"], "status": last["status"],
                                                     "confidence": round(last["confidence"], 3),
                                                     "p_other": round(last["probs"][OTHER], 3)},
                "full_window_alone_alerts": alone is not None and raises_alert(alone),
                "full_window_alone": None if alone is None else {"label": alone["label"], "status": alone["status"],
                                                                 "confidence": round(alone["confidence"], 3)},
                "threshold_full_window": thr6})
    return rows


def misses(drives, decisions, detector_cfg) -> list[dict]:
    rows = []
    for drive, ds in zip(drives, decisions):
        truth = [e for e in drive.events if e["label"] in DISTRACTIONS]

        def owner(d, truth=truth):
            return next((e for e in truth if e["start_s"] - MATCH_BEFORE_S <= d["t_trigger_s"] <= e["end_s"]), None)

        hit = {id(owner(d)) for d in ds if raises_alert(d) and owner(d) is not None}
        for e in truth:
            if id(e) in hit:
                continue
            own = [d for d in ds if owner(d) is e]
            finals = [d for d in own if d["steps"] == 6]
            top = max(finals, key=lambda d: max(v for k, v in d["probs"].items() if k != OTHER), default=None)
            rows.append({"drive": drive.name, "label": e["label"], "start_s": e["start_s"],
                         "duration_s": round(e["end_s"] - e["start_s"], 2),
                         "reason": miss_reason(own, drive.acc_mps2, e, detector_cfg),
                         "final_labels": [d["label"] for d in finals],
                         "best_p_true": None if top is None else round(top["probs"][e["label"]], 3),
                         "best_p_other": None if top is None else round(top["probs"][OTHER], 3)})
    return rows


def category(r: dict) -> str:
    """A false alert's row of the breakdown table (exclusive)."""
    nxt = r.get("next") or {}
    if r["context"].startswith("Other") and nxt.get("capture_reaches_it"):
        return ("Other just before a distraction: frame after its onset" if nxt["alert_frame_after_onset_s"] >= 0
                else "Other just before a distraction: frame before its onset")
    if r["context"].startswith("Other"):
        return "Other motion, capture clear of any distraction"
    return r["context"]


def score_by_frame(drives, decisions) -> dict:
    """A second reading, NOT drive-eval's: an alert whose first frame went out while a distraction was under way
    (onset <= t_alert_s <= end) belongs to that distraction, whatever its trigger; other alerts by trigger as
    drive-eval matches them. What a vehicle sees: a warning while the driver is distracted."""
    n = hit = right = false = 0
    for drive, ds in zip(drives, decisions):
        truth = [e for e in drive.events if e["label"] in DISTRACTIONS]
        firsts: dict[int, dict] = {}
        for d in sorted((d for d in ds if raises_alert(d)), key=lambda d: d["t_alert_s"]):
            e = next((e for e in truth if e["start_s"] <= d["t_alert_s"] <= e["end_s"]), None) or next(
                (e for e in truth if e["start_s"] - MATCH_BEFORE_S <= d["t_trigger_s"] <= e["end_s"]), None)
            if e is None:
                false += 1
            else:
                firsts.setdefault(id(e), d)
        n += len(truth)
        hit += len(firsts)
        right += sum(d["label"] == e["label"] for e in truth for d in [firsts.get(id(e))] if d is not None)
    hours = sum(d.hours for d in drives)
    return {"event_recall": round(hit / n, 4), "class_accuracy": round(right / hit, 4), "false_alerts": false,
            "false_alerts_per_hour": round(false / hours, 2)}


def table(rows: list[dict], key) -> list[tuple]:
    return Counter(key(r) for r in rows).most_common()


LEVERS: list[tuple[str, dict]] = [
    ("shipped", {}),
    *[(f"full-window threshold {t}", {"min_confidence_by_steps": [0.9] * 5 + [t]}) for t in (0.5, 0.6, 0.7, 0.8, 0.9)],
    *[(f"max_mean_other {m}", {"max_mean_other": m}) for m in (0.3, 0.2, 0.1, 0.05)],
    *[(f"early_min_margin {m}", {"early_min_margin": m}) for m in (0.3, 0.5)],
    ("early_agreement_steps 2", {"early_agreement_steps": 2}),
    *[(f"early threshold {t}", {"min_confidence_by_steps": [t] * 5 + [-1.0]}) for t in (0.95, 0.98)],
    *[(f"class weight Other {w}", {"class_weights": [1.0, 1.0, 1.0, 1.0, 3.0, w]}) for w in (2.0, 3.0, 5.0)],
    ("earliest_alert_step 3", {"earliest_alert_step": 3}),
]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seed", type=int, required=True)
    p.add_argument("--hours", type=float, default=10.0)
    p.add_argument("--cache", required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--config")
    p.add_argument("--sweep", action="store_true")
    p.add_argument("--levers", default="", help="extra levers as JSON: [[name, {alerts keys}], ...]")
    a = p.parse_args(argv)
    if a.seed not in DEVELOPMENT_SEEDS:
        print(f"--seed {a.seed}: development seeds only ({DEVELOPMENT_SEEDS})", file=sys.stderr)
        return 2
    cfg = config.load(a.config)
    engine = Engine.from_params(cfg.model)
    clf = CachedClassifier(engine, Path(a.cache))
    drives = list(held_out_drives(a.hours, a.seed))
    manifest6 = dict(engine.early.min_confidence_by_steps).get(6, cfg.alerts.min_confidence)
    early = decide(drives, clf, config.override(cfg, "alerts", decision="early"))
    full = decide(drives, clf, config.override(cfg, "alerts", decision="full_window"))
    clf.save()
    fa = false_alerts(drives, early, full, cfg.alerts, manifest6)
    fa_fw = false_alerts(drives, full, full, cfg.alerts, manifest6)
    ms = misses(drives, early, cfg.detector)
    out = {"seed": a.seed, "hours": a.hours, "threshold_full_window": manifest6,
           "early": _figures(score(drives, early)), "full_window": _figures(score(drives, full)),
           "false_alerts_early": fa, "false_alerts_full_window": fa_fw, "misses_early": ms}
    out["by_frame"] = {"early": score_by_frame(drives, early), "full_window": score_by_frame(drives, full)}
    print(json.dumps({k: out[k] for k in ("seed", "threshold_full_window", "early", "full_window", "by_frame")}))
    for name, key in [("category", category), ("context", lambda r: r["context"].split(" (")[0]), ("near", lambda r: r["context"]),
                      ("class", lambda r: r["label"]), ("S/status", lambda r: (r["steps"], r["status"])),
                      ("withdrawn", lambda r: r["withdrawn"]), ("fw alone alerts", lambda r: r["full_window_alone_alerts"]),
                      ("drive kind", lambda r: r["kind"])]:
        print(f"false alerts (early) by {name}: {table(fa, key)}")
    print("false alerts (full window) by context:", table(fa_fw, lambda r: r["context"].split(" (")[0]))
    print("misses by reason:", table(ms, lambda r: (r["label"], r["reason"])))
    if a.sweep:
        extra = [tuple(x) for x in json.loads(a.levers)] if a.levers else []
        out["levers"] = []
        for name, keys in LEVERS + extra:
            c = config.override(cfg, "alerts", decision="early", **keys)
            row = {"lever": name, "keys": keys, **_figures(score(drives, decide(drives, clf, c)))}
            out["levers"].append(row)
            print(json.dumps(row), flush=True)
        clf.save()
    Path(a.out).write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
