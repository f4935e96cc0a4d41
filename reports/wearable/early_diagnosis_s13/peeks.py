"""Stage 1 (issue 12, session 13): decisions on partial sub-windows ("peeks") of the ConvLSTM, offline, development
data only. For a checkpoint (the shipped model, or one trained with ``train_peeks.py``):

1. every decision point (sub-window S = 1..6, its first k = 11, 22 or 33 resampled frames): the calibrated decision
   on every capture of the selection cohort (seed 1000; temperature per point fitted there by NLL, as
   ``models.selection`` fits the manifest's per-S temperatures): accuracy, macro-F1, onset accuracy;
2. the first alert on development drives (``firmware_sim drive-eval``'s drives for ``--seed``; seed 1 is the
   validation seed, 5 development) under a threshold policy: the runtime loop's alert and event logic
   (``edge_runtime.wearable.loop``: preliminary / revised / confirmed / withdrawn, ``event_hold_s``,
   ``event_ends_on_other``, ``max_mean_other`` from sub-window 3 on, class weights, the full window's own
   threshold) re-implemented over decision points, scored by drive-eval's ``ModeScore``. "grid" policies decide
   only at complete sub-windows (today's runtime), "peek" policies at every point; one threshold for every early
   point, scanned, and the earliest point that may alert.

    PYTHONPATH=. python reports/wearable/early_diagnosis_s13/peeks.py CHECKPOINT SEL_NPZ HOURS SEED[,SEED] OUT_PREFIX

SEL_NPZ: the selection cohort's captures with their truth (``reports/wearable/early_diagnosis_s12/sel_captures.py``).
fp32 torch, no int8: a go / no-go, not a product figure.
"""
import json
import sys
import time

import numpy as np
import torch
from sklearn.metrics import f1_score

from edge_runtime import config
from edge_runtime.wearable import alerts, classifier, detector, loop, sources  # noqa: F401 - register sections
from edge_runtime.wearable.classifier import CAPTURE_FRAMES, needed_frames, resample_matrix
from edge_runtime.wearable.detector import detect_triggers
from edge_runtime.wearable.labels import CLASSES, OTHER
from firmware_sim.scenarios.drive_eval import ModeScore, held_out_drives
from models.train import load_checkpoint

PEEK_K = (11, 22, 33)
POINTS = [(s, k) for s in range(1, 7) for k in PEEK_K]
THRESHOLDS = (0.8, 0.85, 0.9, 0.93, 0.95, 0.97, 0.98, 0.99)


def frames_for(rows: int) -> int:
    """Raw capture frames the first ``rows`` resampled frames are computed from."""
    return int(np.flatnonzero(resample_matrix()[:rows].any(axis=0)).max()) + 1


def point_time_s(s: int, k: int) -> float:
    """Seconds after the trigger at which the decision on the first k frames of sub-window s can be made."""
    return max(frames_for(33 * (s - 1) + k) - 1, 100) / 100 - 1.0


def resampled_prefix(X: np.ndarray, n: int) -> np.ndarray:
    """(N, 198, 3): the resampled frames of captures of which the first n raw frames have arrived (edge-padded,
    mean-padded as ``classifier.preprocess_prefix``)."""
    x = np.asarray(X[:, :n], np.float64)
    if n < CAPTURE_FRAMES:
        x = np.concatenate([x, np.repeat(x[:, -1:], CAPTURE_FRAMES - n, axis=1)], axis=1)
    mean = x.mean(axis=1, keepdims=True)
    return (np.matmul(resample_matrix(), x - mean) + mean)[:, :198].astype(np.float32)


@torch.no_grad()
def point_logits(model, X: np.ndarray, batch: int = 1024) -> np.ndarray:
    """(N, len(POINTS), K) logits: each sub-window committed as it arrived (from needed_frames(s) frames), each
    point a step of the LSTM from the state after the complete sub-windows before it, on the frames so far."""
    out = []
    lstm, conv, head = model.lstm, model.features, model.head
    for i in range(0, len(X), batch):
        xb = X[i:i + batch]
        pre = {}
        for s, k in POINTS + [(s, 33) for s in range(1, 7)]:
            n = frames_for(33 * (s - 1) + k)
            if n not in pre:
                pre[n] = torch.from_numpy(resampled_prefix(xb, n))
        h = c = torch.zeros(1, len(xb), lstm.hidden_size)
        res = []
        for s in range(1, 7):
            for k in PEEK_K:
                sub = pre[frames_for(33 * (s - 1) + k)][:, 33 * (s - 1):33 * (s - 1) + k][:, None]  # (N, 1, k, 3)
                f = conv(sub).amax(dim=3)
                o, _ = lstm(f, (h, c))
                res.append(head(o[:, 0]))
            sub = pre[needed_frames(s)][:, 33 * (s - 1):33 * s][:, None]
            _, (h, c) = lstm(conv(sub).amax(dim=3), (h, c))
        out.append(torch.stack(res, 1).numpy())
    return np.concatenate(out)


def fit_temperature(logits: np.ndarray, y: np.ndarray) -> float:
    grid = np.exp(np.linspace(np.log(0.1), np.log(3.0), 121))
    nll = []
    for t in grid:
        z = logits / t
        z = z - z.max(1, keepdims=True)
        nll.append(-np.mean(z[np.arange(len(y)), y] - np.log(np.exp(z).sum(1))))
    return float(grid[int(np.argmin(nll))])


def softmax(z):
    z = z - z.max(-1, keepdims=True)
    e = np.exp(z)
    return e / e.sum(-1, keepdims=True)


def drive_captures(hours: float, seed: int, cfg):
    drives = list(held_out_drives(hours, seed))
    caps = []
    for j, d in enumerate(drives):
        for t in detect_triggers(d.acc_mps2, cfg.detector):
            if t - 100 >= 0 and t + 600 <= len(d.acc_mps2):
                caps.append((j, int(t), d.acc_mps2[t - 100:t + 600]))
    return drives, caps


def policy_decisions(probs, t_trig, points, *, early_from, threshold, full_threshold, pol, other_k):
    """The loop's decisions for one drive's captures (in time order) whose weighted, calibrated probabilities at
    ``points`` (indices into POINTS, in time order, the last the full window) are ``probs`` (n, P, K)."""
    out, ev, seq = [], None, 0
    for c in range(len(t_trig)):
        tt = t_trig[c]
        if ev is not None and (ev["withdrawn"] or tt > ev["last_end"] + pol.event_hold_s):
            ev = None
        continues = ev is not None
        own, other_sum, other_n = None, 0.0, 0
        for j, p in enumerate(points):
            full = p == len(POINTS) - 1
            if continues and not full:
                continue
            s, k = POINTS[p]
            q = probs[c, p]
            lab = int(q.argmax())
            conf = float(q[lab])
            t_alert = round(tt + point_time_s(s, k), 3)
            thr = full_threshold if full else threshold
            status = "not_alerted" if CLASSES[lab] in pol.never_alert else "uncertain" if conf < thr else "alert"
            if status == "alert" and not full and p < early_from:
                status = "uncertain"
            if s >= 3 and other_k is not None:
                other_sum += float(q[other_k])
                other_n += 1
                if status == "alert" and own is None and other_sum > pol.max_mean_other * other_n:
                    status = "uncertain"
            d = {"t_trigger_s": round(tt, 3), "t_alert_s": t_alert, "label": CLASSES[lab], "confidence": conf,
                 "steps": f"{s}:{k}", "alert_seq": None, "event_start_s": None}
            if continues:
                d.update(status="continued", alerted=False, event_start_s=ev["start"], alert_seq=ev["seq"])
                out.append(d)
                if pol.event_ends_on_other and CLASSES[lab] in pol.never_alert:
                    ev = None
                else:
                    ev["last_end"] = max(ev["last_end"], t_alert)
                break
            if own is None:
                if not full and status != "alert":
                    continue
                if status == "alert":
                    seq += 1
                    own = ev = {"start": round(tt, 3), "seq": seq, "label": lab, "last_end": t_alert, "withdrawn": False}
                    status = "preliminary" if not full else "alert"
            elif not full:
                if status != "alert" or lab == own["label"]:
                    continue
                status = "revised"
                own["label"] = lab
            else:
                status = ("confirmed" if lab == own["label"] else "revised") if status == "alert" else "withdrawn"
                own["withdrawn"] = status == "withdrawn"
            d.update(status=status, alerted=status not in ("uncertain", "not_alerted"),
                     event_start_s=own["start"] if own else None, alert_seq=own["seq"] if own else None)
            out.append(d)
            if full:
                if own is not None:
                    own["last_end"] = max(own["last_end"], t_alert)
                break
    return out


def evaluate_policy(drives, caps, probs, points, **kw):
    score = ModeScore(attribution="trigger")
    for j, d in enumerate(drives):
        idx = [i for i, c in enumerate(caps) if c[0] == j]
        t = [caps[i][1] / 100 for i in idx]
        score.add(d, policy_decisions(probs[idx], t, points, **kw) if idx else [])
    return score.as_dict()


def main(ckpt, sel_npz, hours, seeds, out):
    t0 = time.time()
    torch.set_num_threads(1)
    cfg = config.load(None)
    pol = cfg.alerts
    model, meta = load_checkpoint(ckpt)
    classes = list(meta["classes"])
    assert classes == list(CLASSES)
    other = classes.index(OTHER)
    w = np.asarray(pol.class_weights)
    z = np.load(sel_npz)
    Xs, ys, rep = z["X"], z["y"], z["repeat"]
    onset = (ys != other) & (rep == 0)
    L_sel = point_logits(model, Xs)
    temps = [fit_temperature(L_sel[:, p], ys) for p in range(len(POINTS))]
    rep_rows = []
    for p, (s, k) in enumerate(POINTS):
        pr = L_sel[:, p].argmax(1)
        rep_rows.append({"point": f"{s}:{k}", "t_s": round(point_time_s(s, k), 3), "temperature": temps[p],
                         "accuracy": float(np.mean(pr == ys)), "macro_f1": float(f1_score(ys, pr, average="macro")),
                         "onset_accuracy": float(np.mean(pr[onset] == ys[onset]))})
    print(f"selection cohort done ({time.time() - t0:.0f} s)", flush=True)
    full_thr = pol.threshold(6, {6: 0.39})
    grid_pts = [p for p, (s, k) in enumerate(POINTS) if k == 33]
    all_pts = list(range(len(POINTS)))
    policies = []
    for fam, pts in (("grid", grid_pts), ("peek", all_pts)):
        for ef in (p for p in pts if POINTS[p][0] <= 2):  # the earliest point that may alert: in S = 1 or 2
            for thr in THRESHOLDS:
                policies.append({"family": fam, "points": pts, "early_from": ef, "threshold": thr})
    results = []
    for seed in seeds:
        drives, caps = drive_captures(hours, seed, cfg)
        X = np.stack([c[2] for c in caps]).astype(np.float32)
        L = point_logits(model, X)
        P = softmax(L / np.asarray(temps)[None, :, None]) * w
        P /= P.sum(-1, keepdims=True)
        print(f"seed {seed}: {len(drives)} drives, {len(caps)} captures ({time.time() - t0:.0f} s)", flush=True)
        for q in policies:
            r = evaluate_policy(drives, caps, P, q["points"], early_from=q["early_from"], threshold=q["threshold"],
                                full_threshold=full_thr, pol=pol, other_k=other)
            results.append({"seed": seed, "family": q["family"], "early_from": "%d:%d" % POINTS[q["early_from"]],
                            "early_from_s": round(point_time_s(*POINTS[q["early_from"]]), 2),
                            "threshold": q["threshold"], **{k: r[k] for k in (
                                "event_recall", "first_alert_class_accuracy", "onset_to_first_alert_s",
                                "false_alerts_per_hour", "false_alerts", "repeat_alerts", "driving_hours")}})
    json.dump({"checkpoint": ckpt, "points": rep_rows, "policies": results, "hours": hours, "seeds": seeds,
               "wall_s": round(time.time() - t0)}, open(out + ".json", "w"), indent=1)
    L = [f"# Peeks: {ckpt}", "", f"Selection cohort: {len(ys)} captures ({int(onset.sum())} onsets); drives {hours} h "
         f"of seed(s) {seeds}; wall {time.time() - t0:.0f} s.", "",
         "| point S:k | s after trigger | T | accuracy | macro-F1 | onset accuracy |", "|---|---:|---:|---:|---:|---:|"]
    for r in rep_rows:
        L.append(f"| {r['point']} | {r['t_s']:.2f} | {r['temperature']:.3f} | {r['accuracy']:.3f} | {r['macro_f1']:.3f} | "
                 f"{r['onset_accuracy']:.3f} |")
    L += ["", "| seed | family | earliest | thr | recall | class | median | p95 | false/h | repeat |",
          "|---:|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    for r in results:
        o = r["onset_to_first_alert_s"]
        L.append(f"| {r['seed']} | {r['family']} | {r['early_from']} ({r['early_from_s']}) | {r['threshold']} | "
                 f"{r['event_recall']:.3f} | {r['first_alert_class_accuracy']:.3f} | {o['median']:.2f} | {o['p95']:.2f} | "
                 f"{r['false_alerts_per_hour']:.2f} | {r['repeat_alerts']} |")
    open(out + ".md", "w").write("\n".join(L) + "\n")
    print("\n".join(L[:25]))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], float(sys.argv[3]), [int(s) for s in sys.argv[4].split(",")], sys.argv[5])
