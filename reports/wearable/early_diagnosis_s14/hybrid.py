"""Stage 1 (issue 12, session 14): a HYBRID early policy on development drives, scored as drive-eval scores.

A prefix classifier (``prefix_net.py``, trained on the training cohort only) may open an alert event at fine
decision points in the first seconds after a trigger; the shipped ConvLSTM policy (int8 step model, the shipped
``[alerts]`` settings: 0.9 from S = 2, the manifest's full-window threshold, class weights, ``max_mean_other``,
``event_hold_s``, ``event_ends_on_other``) does everything else as shipped: it opens the event when the prefix
model did not, revises a preliminary alert at a confident different class, and confirms, revises or withdraws it at
the full window; a capture triggered while an event is active continues it (full window only, no prefix points).

    PYTHONPATH=. python reports/wearable/early_diagnosis_s14/hybrid.py PREFIX.pt[,PREFIX.pt..] HOURS SEED[,SEED] \
        OUT_PREFIX [--choose-on 1] [--thresholds 0.6,0.7,..] [--agree 1,2,3] [--first 120,..] [--last 280,..] \
        [--max-mean-other 1,0.3,..]

Several checkpoints: the mean of their probabilities (an ensemble). The grid's defaults are round 1's.

Per seed (drive-eval's ``held_out_drives(HOURS, SEED)``; only the validation seed 1 and the development seed 5
are accepted):

1. the runtime's own decisions with the shipped policy (``early_tuning.decide``: ``WearableLoop`` with the
   shipped int8 engine), scored by ``ModeScore`` (attribution "frame", drive-eval's headline, and "trigger");
2. the same captures (the triggers of the runtime's full-window decisions) re-decided by :func:`decisions`, a
   re-implementation of the loop's alert and event logic over decision points (after
   ``../early_diagnosis_s13/peeks.py``'s ``policy_decisions``), first with ConvLSTM points only: it must give the
   runtime's decisions (checked decision by decision and by the figures);
3. the hybrid on a grid of prefix policies (threshold, consecutive prefix points that must agree, the first
   and last prefix point). The policy is CHOSEN on the ``--choose-on`` seed by a rule fixed beforehand (the go
   rule's terms: first-alert class >= the shipped policy's and false alerts / h <= the shipped + 0.3 on that
   seed; then the lowest median onset -> first alert, ties to the higher class) and reported on the others.
"""
import argparse
import json
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from edge_runtime import config
from edge_runtime.wearable import alerts, classifier, detector, loop, sources  # noqa: F401 - register sections
from edge_runtime.wearable.classifier import N_SUBSEQ, Engine, needed_frames
from edge_runtime.wearable.labels import CLASSES, OTHER
from edge_runtime.wearable.loop import OTHER_EVIDENCE_FROM_STEP
from firmware_sim.scenarios.drive_eval import ModeScore, held_out_drives
from firmware_sim.scenarios.early_tuning import CachedClassifier, decide
from reports.wearable.early_diagnosis_s14.prefix_net import load, prefix_probs

DEVELOPMENT_SEEDS = (1, 5)
PRE_FRAMES = 100
PREFIX_FRAMES = list(range(120, 421, 16))
"""Prefix decision points: the capture's first n raw frames, every 0.16 s from 0.2 to 3.2 s after the trigger."""
THRESHOLDS = (0.6, 0.7, 0.8, 0.85, 0.88, 0.9, 0.92, 0.94)
AGREE = (1, 2, 3)
FIRST_FRAMES = (120, 168, 216)
"""The first prefix point that may open an event: 0.19, 0.67 or 1.15 s after the trigger."""
LAST_FRAMES = (280, 344, 408)
"""The last: 1.79, 2.43 or 3.07 s after the trigger (the ConvLSTM's S = 2 and 3 decide at 1.62 and 2.78 s)."""
FIGURES = ("event_recall", "first_alert_class_accuracy", "onset_to_first_alert_s", "false_alerts_per_hour",
           "false_alerts", "repeat_alerts", "distractions", "driving_hours", "first_alerts_after_the_distraction_ended")


def offset_s(frames: int) -> float:
    """Seconds after the trigger at which a decision on the capture's first ``frames`` frames is made (its last
    frame's time, as the loop's ``t_alert_s``)."""
    return (frames - 1 - PRE_FRAMES) / 100.0


@dataclass
class Event:
    """The alert event under way (``loop.AlertEvent``)."""
    start: float
    seq: int
    label: int
    last_end: float
    withdrawn: bool = False


def step_status(pol, q, s, threshold, st: dict, opened: bool, other_k) -> str:
    """What the policy says of the ConvLSTM's step S (``WearableLoop._classify`` before the event logic); ``st``
    carries the capture's agreement and Other evidence from step to step."""
    lab = int(q.argmax())
    st["agreeing"] = st["agreeing"] + 1 if lab == st["last"] else 1
    st["last"] = lab
    status = pol.status(CLASSES[lab], float(q[lab]), threshold)
    if status == "alert" and s < N_SUBSEQ and not pol.early_ready(s, float(q[lab] - np.sort(q)[-2]), st["agreeing"]):
        status = "uncertain"
    if other_k is not None and s >= OTHER_EVIDENCE_FROM_STEP:
        st["other_sum"] += float(q[other_k])
        st["other_n"] += 1
        if status == "alert" and not opened and st["other_sum"] > pol.max_mean_other * st["other_n"]:
            status = "uncertain"  # the capture's steps keep saying Other: no new alert
    return status


def update(own: Event | None, status: str, lab: int, full: bool) -> str | None:
    """The decision's status given the capture's own event (None: it opened none yet); None: an early step that
    changes nothing (``WearableLoop._classify``'s event logic)."""
    if own is None:
        return status if full else ("preliminary" if status == "alert" else None)
    if not full:
        return "revised" if status == "alert" and lab != own.label else None
    if status != "alert":
        return "withdrawn"
    return "confirmed" if lab == own.label else "revised"


def decisions(t_trig, conv, pre, *, pol, thresholds, other_k, prefix=None):
    """The loop's decisions for one drive's captures (trigger times ``t_trig``, in order) whose ConvLSTM
    probabilities (class weights applied) after S = 1..6 sub-windows are ``conv`` (n, 6, K) and whose prefix
    model's at PREFIX_FRAMES are ``pre`` (n, P, K). ``prefix``: None (the shipped policy) or
    {"threshold", "agree", "first", "last"} (indices into PREFIX_FRAMES): a prefix point may open the capture's
    event when its top class is a distraction with probability >= threshold, the ``agree`` prefix points up
    to it had that top class and (optional "max_mean_other", round 3: a gate like the shipped ``max_mean_other``)
    the mean P(Other) of the prefix points so far is at most that."""
    out, ev, seq = [], None, 0
    conv_pts = [(offset_s(needed_frames(s)), 0, s) for s in range(1, N_SUBSEQ + 1)]
    pre_pts = [] if prefix is None else [(offset_s(PREFIX_FRAMES[j]), 1, j)
                                         for j in range(prefix["first"], prefix["last"] + 1)]
    points = sorted(conv_pts + pre_pts)  # at an equal time the ConvLSTM's step first
    for c, tt in enumerate(t_trig):
        tt = round(float(tt), 3)
        if ev is not None and (ev.withdrawn or tt > ev.last_end + pol.event_hold_s):
            ev = None
        continues, own = ev is not None, None
        st = {"agreeing": 0, "last": None, "other_sum": 0.0, "other_n": 0, "p_last": None, "p_agree": 0,
              "p_other": 0.0, "p_n": 0}
        for off, kind, i in points:
            t_alert = round(tt + off, 3)
            row = {"t_trigger_s": tt, "t_alert_s": t_alert, "steps": i, "source": "convlstm"}
            if kind == 1:  # a prefix point: it can only open the capture's event
                if continues or own is not None:
                    continue
                q = pre[c, i]
                lab = int(q.argmax())
                st["p_agree"] = st["p_agree"] + 1 if lab == st["p_last"] else 1
                st["p_last"] = lab
                st["p_other"] += float(q[other_k])
                st["p_n"] += 1
                if (CLASSES[lab] in pol.never_alert or q[lab] < prefix["threshold"] or st["p_agree"] < prefix["agree"]
                        or st["p_other"] > prefix.get("max_mean_other", 1.0) * st["p_n"]):
                    continue
                seq += 1
                own = ev = Event(tt, seq, lab, t_alert)
                out.append({**row, "label": CLASSES[lab], "confidence": float(q[lab]), "status": "preliminary",
                            "steps": f"prefix:{PREFIX_FRAMES[i]}", "source": "prefix", "alerted": True,
                            "alert_seq": seq, "event_start_s": tt})
                continue
            full = i == N_SUBSEQ
            if continues and not full:
                continue
            q = conv[c, i - 1]
            lab = int(q.argmax())
            status = step_status(pol, q, i, thresholds[i], st, own is not None, other_k)
            row.update(label=CLASSES[lab], confidence=float(q[lab]))
            if continues:  # the full window of a capture that continues the event under way
                out.append({**row, "status": "continued", "alerted": False, "event_start_s": ev.start,
                            "alert_seq": ev.seq})
                if pol.event_ends_on_other and CLASSES[lab] in pol.never_alert:
                    ev = None
                else:
                    ev.last_end = max(ev.last_end, t_alert)
                break
            status = update(own, status, lab, full)
            if status is None:
                continue
            if own is None and status in ("preliminary", "alert"):
                seq += 1
                own = ev = Event(tt, seq, lab, t_alert)
            elif own is not None:
                own.withdrawn = status == "withdrawn"
                own.label = lab if status == "revised" else own.label
            out.append({**row, "status": status, "alerted": status not in ("uncertain", "not_alerted"),
                        "event_start_s": own.start if own else None, "alert_seq": own.seq if own else None})
            if full:
                if own is not None:
                    own.last_end = max(own.last_end, t_alert)
                break
    return out


def scores(drives, per_drive, cfg, why_missed: bool = True) -> dict:
    """The figures by both attributions; ``why_missed`` False: a miss with no trigger is not told apart (the
    detector's P3 is not recomputed: the grid's rows need only the figures)."""
    out = {}
    for attribution in ("frame", "trigger"):
        s = ModeScore(attribution=attribution, detector=cfg.detector if why_missed else None)
        for drive, ds in zip(drives, per_drive):
            s.add(drive, ds)
        r = s.as_dict()
        out[attribution] = {k: r[k] for k in FIGURES}
    return out


def key(d) -> tuple:
    return (d["t_trigger_s"], d["t_alert_s"], d["label"], d["status"], bool(d["alerted"]))


def seed_data(seed, hours, cfg, engine, nets, cache_dir):
    """The drives, the runtime's own decisions, and every capture's ConvLSTM and prefix probabilities."""
    t0 = time.time()
    drives = list(held_out_drives(hours, seed))
    print(f"seed {seed}: {len(drives)} drives simulated ({time.time() - t0:.0f} s)", flush=True)
    clf = CachedClassifier(engine, Path(cache_dir) / f"convlstm_seed{seed}_{hours:g}h.npz")
    runtime = decide(drives, clf, cfg)
    clf.save()
    print(f"seed {seed}: runtime decided ({time.time() - t0:.0f} s)", flush=True)
    w = np.asarray(cfg.alerts.class_weights)
    caps = []
    for drive, ds in zip(drives, runtime):
        trig = sorted({round(d["t_trigger_s"] * 100) for d in ds if d["steps"] == N_SUBSEQ})
        X = np.stack([drive.acc_mps2[t - PRE_FRAMES:t - PRE_FRAMES + 700] for t in trig]).astype(np.float32) \
            if trig else np.zeros((0, 700, 3), np.float32)
        if len(X):
            g = engine.classify_capture_groups([(X, tuple(range(1, N_SUBSEQ + 1)))])[0]
            conv = np.stack([g[s] for s in range(1, N_SUBSEQ + 1)], 1) * w
            conv /= conv.sum(-1, keepdims=True)
            pre = np.mean([prefix_probs(net, X, PREFIX_FRAMES) for net in nets], axis=0)
        else:
            conv = pre = np.zeros((0, 1, 1))
        caps.append((np.asarray(trig) / 100.0, conv, pre))
    return drives, runtime, caps


def main(a) -> None:
    t0 = time.time()
    import torch
    torch.set_num_threads(1)
    seeds = [int(s) for s in a.seeds.split(",")]
    if any(s not in DEVELOPMENT_SEEDS for s in seeds) or a.choose_on not in seeds:
        raise SystemExit(f"seeds: development seeds {DEVELOPMENT_SEEDS} only, --choose-on among them")
    cfg = config.load(None)
    pol = cfg.alerts
    engine = Engine.from_params(cfg.model)
    manifest = dict(getattr(engine.early, "min_confidence_by_steps", {}) or {})
    thresholds = {s: pol.threshold(s, manifest) for s in range(1, N_SUBSEQ + 1)}
    other_k = CLASSES.index(OTHER)
    nets = [load(p) for p in a.prefix.split(",")]

    def ints(v):
        return [int(x) for x in v.split(",")]

    grid = [{"threshold": t, "agree": k, "first": PREFIX_FRAMES.index(f), "last": PREFIX_FRAMES.index(l_),
             "max_mean_other": m}
            for t in [float(x) for x in a.thresholds.split(",")] for k in ints(a.agree) for f in ints(a.first)
            for l_ in ints(a.last) for m in [float(x) for x in a.max_mean_other.split(",")]]
    report = {"prefix_model": a.prefix, "hours": a.hours, "seeds": seeds, "choose_on": a.choose_on,
              "thresholds_by_step": thresholds, "prefix_frames": PREFIX_FRAMES, "per_seed": {}}
    for seed in seeds:
        drives, runtime, caps = seed_data(seed, a.hours, cfg, engine, nets, a.cache)
        mine = [decisions(t, cv, pr, pol=pol, thresholds=thresholds, other_k=other_k) if len(t) else []
                for t, cv, pr in caps]
        same = sum(len({key(d) for d in r} & {key(d) for d in m}) for r, m in zip(runtime, mine))
        total = (sum(len(r) for r in runtime), sum(len(m) for m in mine))
        rows = []
        for p in grid:
            ds = [decisions(t, cv, pr, pol=pol, thresholds=thresholds, other_k=other_k, prefix=p) if len(t) else []
                  for t, cv, pr in caps]
            n_pre = sum(1 for x in ds for d in x if d.get("source") == "prefix")
            rows.append({**p, "first_s": round(offset_s(PREFIX_FRAMES[p["first"]]), 2),
                         "last_s": round(offset_s(PREFIX_FRAMES[p["last"]]), 2), "prefix_alerts": n_pre,
                         "scores": scores(drives, ds, cfg, why_missed=False)})
        report["per_seed"][seed] = {
            "drives": len(drives), "captures": int(sum(len(t) for t, _, _ in caps)),
            "runtime_shipped": scores(drives, runtime, cfg),
            "reimplemented_shipped": scores(drives, mine, cfg),
            "reimplementation_check": {"runtime_decisions": total[0], "reimplemented_decisions": total[1],
                                       "identical": same},
            "hybrid": rows}
        print(f"seed {seed}: {len(drives)} drives, runtime/re-implemented decisions {total}, identical {same} "
              f"({time.time() - t0:.0f} s)", flush=True)
    ship = report["per_seed"][a.choose_on]["runtime_shipped"]["frame"]
    ok = [(i, r) for i, r in enumerate(report["per_seed"][a.choose_on]["hybrid"])
          if r["scores"]["frame"]["first_alert_class_accuracy"] >= ship["first_alert_class_accuracy"]
          and r["scores"]["frame"]["false_alerts_per_hour"] <= ship["false_alerts_per_hour"] + 0.3]
    best = min(ok, key=lambda ir: (ir[1]["scores"]["frame"]["onset_to_first_alert_s"]["median"],
                                   -ir[1]["scores"]["frame"]["first_alert_class_accuracy"]))[0] if ok else None
    report["chosen_index"] = best
    report["wall_s"] = round(time.time() - t0)
    Path(a.out + ".json").write_text(json.dumps(report, indent=1, default=lambda o: o.item()))
    print(f"chosen on seed {a.choose_on}: {None if best is None else grid[best]} ({len(ok)} of {len(grid)} eligible)")


if __name__ == "__main__":
    p = argparse.ArgumentParser()
    p.add_argument("prefix")
    p.add_argument("hours", type=float)
    p.add_argument("seeds")
    p.add_argument("out")
    p.add_argument("--choose-on", type=int, default=1)
    p.add_argument("--cache", default="/tmp/s14p/cache")
    p.add_argument("--thresholds", default=",".join(map(str, THRESHOLDS)))
    p.add_argument("--agree", default=",".join(map(str, AGREE)))
    p.add_argument("--first", default=",".join(map(str, FIRST_FRAMES)))
    p.add_argument("--last", default=",".join(map(str, LAST_FRAMES)))
    p.add_argument("--max-mean-other", default="1.0", help="round 3: gates on the prefix points' mean P(Other)")
    main(p.parse_args())
