"""What a prefix classifier on a finer decision grid could give, as a first alert: coverage, class accuracy and
onset -> alert time, on the SELECTION cohort's captures (train: cohort seed 0, as prefix_models.py). No held-out data.

    PYTHONPATH=/work/main OMP_NUM_THREADS=1 nice -n 10 /work/main/.venv/bin/python /work/notes/s12-w/prefix_latency.py OUT_PREFIX

For each model (gradient boosting on the prefix's shape, a small 1D CNN, the shipped ConvLSTM at its S grid) and
confidence threshold t: each capture's first decision point whose top class is not Other with probability >= t
is its first alert. On distraction ONSET captures (the first capture of each distraction): share alerted, class
accuracy of that first alert (6 classes, and with Phone+Texting as one class), onset -> alert time = the capture's
own trigger delay (simulator truth) + the decision point's time after the trigger. On Other captures (detector
false alarms): the share that would raise an alert (a false-alert proxy). Thresholds are scanned, not chosen:
this is a description of the trade-off on one cohort, not a tuned operating point.
"""
import sys
import time

import numpy as np

sys.path.insert(0, "/work/notes/s12-w")
from prefix_models import cnn_fit_predict, nframes, shape  # noqa: E402
from sklearn.ensemble import HistGradientBoostingClassifier  # noqa: E402

from edge_runtime.wearable.classifier import needed_frames  # noqa: E402
from models.dataset import load_npz  # noqa: E402

GRID_S = (0.47, 0.75, 1.0, 1.3, 1.62, 2.0, 2.78, 3.93, 5.99)
THRESHOLDS = (0.0, 0.5, 0.6, 0.7, 0.8, 0.9, 0.95)


def first_alerts(probs, cuts, t, other):
    """probs (C, N, K) over decision points -> (index of first alerting cut or -1, its class)."""
    n = probs.shape[1]
    idx, cls = np.full(n, -1), np.full(n, -1)
    for c in range(len(cuts)):
        p = probs[c]
        ok = (idx < 0) & (p.argmax(1) != other) & (p.max(1) >= t)
        idx[ok], cls[ok] = c, p.argmax(1)[ok]
    return idx, cls


def main(out):
    t0 = time.time()
    gt, cap = load_npz("/work/main/reports/wearable/data/train.npz"), load_npz("/work/main/reports/wearable/data/test.npz")
    Xtr = np.concatenate([gt.X, cap.X]).astype(np.float32)
    ytr = np.concatenate([gt.y, cap.y])
    z = np.load("/tmp/s12w/sel.npz")
    Xte, yte, rep, delay = z["X"], z["y"], z["repeat"], z["delay_s"]
    classes = list(z["classes"])
    other, ph, tx = classes.index("Other"), classes.index("Phone"), classes.index("Texting")
    hand = np.array([ph if k == tx else k for k in range(6)])
    onset = (yte != other) & (rep == 0)
    is_other = yte == other
    P = {"gradient boosting (prefix shape + stats)": [], "1D CNN (prefix, 25 Hz)": []}
    for c in GRID_S:
        n = nframes(c)
        gb = HistGradientBoostingClassifier(max_iter=200, learning_rate=0.1, random_state=0).fit(shape(Xtr[:, :n]), ytr)
        P["gradient boosting (prefix shape + stats)"].append(gb.predict_proba(shape(Xte[:, :n])))
        P["1D CNN (prefix, 25 Hz)"].append(cnn_fit_predict(Xtr[:, :n], ytr, Xte[:, :n]))
        print(f"cut {c}: GB acc {np.mean(P['gradient boosting (prefix shape + stats)'][-1].argmax(1) == yte):.3f}, "
              f"CNN acc {np.mean(P['1D CNN (prefix, 25 Hz)'][-1].argmax(1) == yte):.3f} ({time.time() - t0:.0f} s)", flush=True)
    cuts = {k: GRID_S for k in P}
    conv = np.load("/work/notes/s12-w/per_s_probs.npz")["probs"]
    conv_cuts = tuple((needed_frames(s) - 1 - 100) / 100 for s in range(1, 7))
    P["shipped ConvLSTM (calibrated)"] = list(conv)
    cuts["shipped ConvLSTM (calibrated)"] = conv_cuts
    w = np.array([1, 1, 1, 1, 3, 1.5])
    cw = conv * w
    P["shipped ConvLSTM (calibrated, runtime class weights)"] = list(cw / cw.sum(-1, keepdims=True))
    cuts["shipped ConvLSTM (calibrated, runtime class weights)"] = conv_cuts
    P = {k: np.stack(v) for k, v in P.items()}
    np.savez_compressed(out + "_probs.npz", **{k: v for k, v in P.items()})
    L = ["# First alert from a prefix classifier on a decision grid: selection cohort captures (train: cohort seed 0)", "",
         f"Decision points (s after the trigger): prefix models {GRID_S}; ConvLSTM {tuple(round(c, 2) for c in conv_cuts)}. "
         f"{int(onset.sum())} distraction onsets (trigger delay median {np.median(delay[onset]):.2f} s, p95 "
         f"{np.percentile(delay[onset], 95):.2f} s), {int(is_other.sum())} Other captures. Wall {time.time() - t0:.0f} s.", "",
         "## Top-class accuracy at each decision point (every capture / onsets / onsets with Phone+Texting merged)", "",
         "| model | " + " | ".join(f"{c:.2f} s" for c in GRID_S) + " |", "|---|" + "---|" * len(GRID_S)]
    for k, p in P.items():
        cells = []
        for c in GRID_S:
            if c in cuts[k] or any(abs(c - cc) < 0.02 for cc in cuts[k]):
                j = int(np.argmin([abs(c - cc) for cc in cuts[k]]))
                pr = p[j].argmax(1)
                cells.append(f"{np.mean(pr == yte):.2f} / {np.mean(pr[onset] == yte[onset]):.2f} / "
                             f"{np.mean(hand[pr[onset]] == hand[yte[onset]]):.2f}")
            else:
                cells.append("–")
        L.append(f"| {k} | " + " | ".join(cells) + " |")
    L += ["", "## First alert = first decision point with top class not Other and p >= t", "",
          "| model | t | onsets alerted | first-alert class right | right, Phone+Texting merged | onset -> alert median (s) | p95 (s) | share <= 2.0 s | Other captures alerting |",
          "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for k, p in P.items():
        for t in THRESHOLDS:
            idx, cls = first_alerts(p, cuts[k], t, other)
            a = onset & (idx >= 0)
            lat = delay[a] + np.asarray(cuts[k])[idx[a]]
            L.append(f"| {k} | {t} | {a.sum() / onset.sum():.3f} | {np.mean(cls[a] == yte[a]):.3f} | "
                     f"{np.mean(hand[cls[a]] == hand[yte[a]]):.3f} | {np.median(lat):.2f} | {np.percentile(lat, 95):.2f} | "
                     f"{np.mean(lat <= 2.0):.3f} | {np.mean(idx[is_other] >= 0):.3f} |")
    # decision point by decision point: for the prefix models, accuracy needed vs time
    L += ["", "## Per decision point: share of onsets whose top class is right with p >= t (alertable and right) / alerting but wrong", "",
          "| model | t | " + " | ".join(f"{c:.2f} s" for c in GRID_S) + " |", "|---|---:|" + "---|" * len(GRID_S)]
    for k in ("gradient boosting (prefix shape + stats)", "1D CNN (prefix, 25 Hz)"):
        for t in (0.7, 0.9):
            cells = []
            for j in range(len(GRID_S)):
                p = P[k][j][onset]
                al = (p.argmax(1) != other) & (p.max(1) >= t)
                cells.append(f"{np.mean(al & (p.argmax(1) == yte[onset])):.2f} / {np.mean(al & (p.argmax(1) != yte[onset])):.2f}")
            L.append(f"| {k} | {t} | " + " | ".join(cells) + " |")
    open(out + ".md", "w").write("\n".join(L) + "\n")
    print("\n".join(L))


if __name__ == "__main__":
    main(sys.argv[1])
