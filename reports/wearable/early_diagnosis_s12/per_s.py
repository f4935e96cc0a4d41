"""Per-S confusion of the SHIPPED int8 ConvLSTM (edge_runtime/assets, trained on cohort seed 0) on every detector
capture of the selection cohort (seed 1000; /tmp/s12w/sel.npz from sel_captures.py). No held-out data.

    PYTHONPATH=/work/main nice -n 10 /work/main/.venv/bin/python /work/notes/s12-w/per_s.py /tmp/s12w/sel.npz OUT_PREFIX

Writes OUT_PREFIX_probs.npz (calibrated probs S=1..6, the runtime's classify_prefixes) and a markdown table beside it (OUT_PREFIX + ".md").
Reads the runtime's class weights and per-step thresholds from the shipped config (edge_runtime.config.load()).
"""
import json
import sys

import numpy as np

from edge_runtime import config
from edge_runtime.wearable import alerts, classifier, detector, loop, sources  # noqa: F401 - register sections
from edge_runtime.wearable.classifier import Engine, needed_frames


def conf_md(y, p, classes, title):
    K = len(classes)
    M = np.zeros((K, K), int)
    for t, q in zip(y, p):
        M[t, q] += 1
    lines = [f"**{title}** (rows truth, columns predicted; recall on the diagonal's right)", "",
             "| truth \\ pred | " + " | ".join(classes) + " | n | recall |", "|---|" + "---:|" * (K + 2)]
    for i, c in enumerate(classes):
        n = M[i].sum()
        lines.append(f"| {c} | " + " | ".join(str(v) for v in M[i]) + f" | {n} | {M[i, i] / max(n, 1):.2f} |")
    return lines, M


def main(path, out):
    torch_free = True  # noqa: F841 - the runtime only
    cfg = config.load(None)
    eng = Engine.from_params(cfg.model)
    z = np.load(path)
    X, y, rep = z["X"], z["y"], z["repeat"]
    detail = [json.loads(d) for d in z["detail"]]
    classes = list(eng.classes)
    assert classes == list(z["classes"])
    probs = np.stack([eng.classify_prefixes(X[:, :needed_frames(s)], s) for s in range(1, 7)])  # (6, N, K)
    np.savez_compressed(out + "_probs.npz", probs=probs)
    w = np.asarray(cfg.alerts.class_weights)
    pw = probs * w
    pw /= pw.sum(-1, keepdims=True)
    thr = list(cfg.alerts.min_confidence_by_steps)
    man = {int(k): v for k, v in eng.entry["early"]["min_confidence_by_steps"].items()}
    other = classes.index("Other")
    ph, tx = classes.index("Phone"), classes.index("Texting")
    hand = np.array([ph if k == tx else k for k in range(len(classes))])
    onset = (y != other) & (rep == 0)
    L = [f"# Shipped int8 ConvLSTM on every selection-cohort capture, per S", "",
         f"Model {eng.name} ({eng.source}); {len(y)} captures of 12 subjects (seed 1000), "
         f"{int(onset.sum())} distraction onsets, {int((rep == 1).sum())} repeats, {int((y == other).sum())} Other.",
         f"Class weights (runtime) {w.tolist()}; policy thresholds by S {thr} (negative: manifest {man}).", "",
         "| S | decision after trigger (s) | acc every capture (calibrated) | acc weighted | macro-F1 weighted | acc onsets | acc onsets, Phone+Texting merged | onset distraction read as Other | Phone->Texting (onsets) | Texting->Phone (onsets) |",
         "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    from sklearn.metrics import f1_score
    for s in range(6):
        pr, pwr = probs[s].argmax(1), pw[s].argmax(1)
        L.append(f"| {s + 1} | {(needed_frames(s + 1) - 1 - 100) / 100:.2f} | {np.mean(pr == y):.3f} | {np.mean(pwr == y):.3f} | "
                 f"{f1_score(y, pwr, average='macro'):.3f} | {np.mean(pwr[onset] == y[onset]):.3f} | "
                 f"{np.mean(hand[pwr[onset]] == hand[y[onset]]):.3f} | {np.mean(pwr[onset] == other):.3f} | "
                 f"{np.sum((y == ph) & onset & (pwr == tx))} of {np.sum((y == ph) & onset)} | "
                 f"{np.sum((y == tx) & onset & (pwr == ph))} of {np.sum((y == tx) & onset)} |")
    L += [""]
    for s in (1, 2, 3, 6):
        pwr = pw[s - 1].argmax(1)
        lines, _ = conf_md(y, pwr, classes, f"S = {s}, every capture, runtime class weights")
        L += lines + [""]
        lines, _ = conf_md(y[onset], pwr[onset], classes, f"S = {s}, distraction onsets only (first capture of each distraction)")
        L += lines + [""]
    # the policy: how many onsets would a confident early step alert, and right?
    L += ["## What the shipped thresholds let through (onset captures, class weights applied)", "",
          "| S | threshold | onsets alerted at this S (top class not Other, conf >= thr) | of those right | onsets with top class right | top class right AND conf >= thr | mean conf when right | mean conf when wrong |",
          "|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for s in range(1, 6):
        t = thr[s - 1] if thr[s - 1] >= 0 else man[s]
        q = pw[s - 1][onset]; top, cf = q.argmax(1), q.max(1); yy = y[onset]
        al = (top != other) & (cf >= t)
        L.append(f"| {s} | {t} | {al.mean():.3f} | {np.mean(top[al] == yy[al]) if al.any() else float('nan'):.3f} | "
                 f"{np.mean(top == yy):.3f} | {np.mean(al & (top == yy)):.3f} | {cf[top == yy].mean():.3f} | {cf[top != yy].mean():.3f} |")
    # Phone split by look_first, Texting by position
    L += ["", "## Phone / Texting onsets by what the simulator did (look at the phone first? texting position)", "",
          "| group | n | " + " | ".join(f"S={s}: right / ->Texting / ->Phone" for s in (1, 2, 3, 4, 6)) + " |",
          "|---|---:|" + "---|" * 5]
    groups = {
        "Phone, look_first (dial in front of the chest, as Texting)": [i for i in np.flatnonzero(onset & (y == ph)) if detail[i].get("look_first")],
        "Phone, straight to ear/speaker": [i for i in np.flatnonzero(onset & (y == ph)) if not detail[i].get("look_first")],
        "Texting, front": [i for i in np.flatnonzero(onset & (y == tx)) if detail[i].get("position") == "front"],
        "Texting, side": [i for i in np.flatnonzero(onset & (y == tx)) if detail[i].get("position") == "side"],
    }
    for g, idx in groups.items():
        idx = np.asarray(idx, int)
        cells = []
        for s in (1, 2, 3, 4, 6):
            pr = pw[s - 1][idx].argmax(1)
            cells.append(f"{np.mean(pr == y[idx]):.2f} / {np.mean(pr == tx):.2f} / {np.mean(pr == ph):.2f}")
        L.append(f"| {g} | {len(idx)} | " + " | ".join(cells) + " |")
    # per-class per-S recall on onsets, and the onset trigger delay
    d = z["delay_s"][onset]
    L += ["", f"Onset captures' trigger delay after the hand left the wheel: median {np.nanmedian(d):.2f} s, "
          f"p95 {np.nanpercentile(d, 95):.2f} s (n {len(d)})", ""]
    L += ["| class | " + " | ".join(f"recall S={s}" for s in range(1, 7)) + " |", "|---|" + "---:|" * 6]
    for k, c in enumerate(classes):
        m = onset & (y == k) if c != "Other" else (y == other)
        L.append(f"| {c}{' (every Other capture)' if c == 'Other' else ' (onsets)'} | " +
                 " | ".join(f"{np.mean(pw[s][m].argmax(1) == k):.2f}" for s in range(6)) + " |")
    open(out + ".md", "w").write("\n".join(L) + "\n")
    print("\n".join(L))


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
