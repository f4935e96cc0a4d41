"""Trade-offs from the saved probabilities (prefix_latency_probs.npz, per_s_probs.npz) on the selection cohort.
PYTHONPATH=/work/main python /work/notes/s12-w/extra.py > /work/notes/s12-w/extra.md"""
import numpy as np

from edge_runtime.wearable.classifier import needed_frames
from firmware_sim.devices.wrist import make_subjects

z = np.load("/tmp/s12w/sel.npz")
y, rep, delay, subj = z["y"], z["repeat"], z["delay_s"], z["subject"]
other, ph, tx = 5, 0, 1
hand = np.array([0, 0, 2, 3, 4, 5])
onset = (y != other) & (rep == 0)
isoth = y == other
P = dict(np.load("/work/notes/s12-w/prefix_latency_probs.npz"))
GRID = np.array((0.47, 0.75, 1.0, 1.3, 1.62, 2.0, 2.78, 3.93, 5.99))
CONV = np.array([(needed_frames(s) - 1 - 100) / 100 for s in range(1, 7)])
conv = P["shipped ConvLSTM (calibrated, runtime class weights)"]


def first(p, cuts, thr, smin=0, binary=False):
    n = p.shape[1]
    idx, cls = np.full(n, -1), np.full(n, -1)
    for c in range(smin, len(cuts)):
        q = p[c]
        conf = 1 - q[:, other] if binary else q.max(1)
        ok = (idx < 0) & (conf >= thr[c]) & ((q.argmax(1) != other) | binary)
        q2 = q.copy(); q2[:, other] = -1
        idx[ok], cls[ok] = c, q2.argmax(1)[ok]
    return idx, cls


def row(name, p, cuts, thr, smin=0, binary=False):
    idx, cls = first(p, cuts, thr, smin, binary)
    a = onset & (idx >= 0)
    lat = delay[a] + cuts[idx[a]]
    return (f"| {name} | {a.sum() / onset.sum():.3f} | {np.mean(cls[a] == y[a]):.3f} | {np.mean(hand[cls[a]] == hand[y[a]]):.3f} | "
            f"{np.median(lat):.2f} | {np.percentile(lat, 95):.2f} | {np.mean(lat <= 2.0):.3f} | {np.mean(lat <= 3.5):.3f} | "
            f"{np.mean(idx[isoth] >= 0):.3f} |")


print("# Trade-offs on the selection cohort (12 subjects, seed 1000; every capture), from saved probabilities\n")
print("First alert per capture = first decision point whose conditions hold; class of the first alert = its top class "
      "(binary rows: the top distraction class). Latency = simulator trigger delay + decision point. 'Other alerting' = "
      "share of Other captures (detector false alarms) that would alert: the false-alert proxy.\n")
print("| policy | onsets alerted | class right | right, Phone+Texting one class | onset->alert median | p95 | <= 2.0 s | <= 3.5 s | Other alerting |")
print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
shipped = [0.97, 0.98, 0.99, 0.97, 0.96, 0.38]
print(row("shipped ConvLSTM, shipped per-S thresholds, from S=2 (no max_mean_other, no event logic)", conv, CONV, shipped, smin=1))
print(row("shipped ConvLSTM, full window only (S=6, 0.38)", conv, CONV, [2, 2, 2, 2, 2, 0.38]))
cnn, gb = P["1D CNN (prefix, 25 Hz)"], P["gradient boosting (prefix shape + stats)"]
for t in (0.9, 0.95, 0.97, 0.98, 0.99):
    print(row(f"1D CNN grid 0.47..5.99 s, one threshold {t}", cnn, GRID, [t] * 9))
for t in (0.9, 0.95, 0.97):
    print(row(f"gradient boosting grid, one threshold {t}", gb, GRID, [t] * 9))
for t in (0.8, 0.9, 0.95, 0.97):
    print(row(f"BINARY preliminary (CNN: P(not Other) >= {t}), class = top distraction then", cnn, GRID, [t] * 9, binary=True))
for t in (0.9, 0.95, 0.97):
    print(row(f"BINARY preliminary (ConvLSTM S grid: P(not Other) >= {t}, from S=1)", conv, CONV, [t] * 6, binary=True))
# cuts limited to <= 1.3 s after the trigger: what the latency must-hold asks for
print("\nDecisions only up to 1.3 s after the trigger (what median <= 2.0 s / p95 <= 3.5 s leave room for):\n")
print("| policy | onsets alerted | class right | right, Phone+Texting one class | onset->alert median | p95 | <= 2.0 s | <= 3.5 s | Other alerting |")
print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
for t in (0.0, 0.7, 0.9):
    print(row(f"1D CNN, cuts 0.47-1.3 s, threshold {t}", cnn[:4], GRID[:4], [t] * 4))
    print(row(f"1D CNN BINARY, cuts 0.47-1.3 s, P(not Other) >= {t}", cnn[:4], GRID[:4], [t] * 4, binary=True))
# trigger delay vs the subject's detach probability (the quick pull off the rim)
subs = {s.subject_id: s for s in make_subjects(12, 1000)}
dp = np.array([subs[s].detach_prob for s in subj[onset]])
d = delay[onset]
print(f"\nTrigger delay (onsets) vs the subject's detach probability: Pearson r = {np.corrcoef(dp, d)[0, 1]:.2f}; "
      f"subjects with detach_prob >= 0.8: median {np.median(d[dp >= 0.8]):.2f} s, p95 {np.percentile(d[dp >= 0.8], 95):.2f} s "
      f"(n {int((dp >= 0.8).sum())}); < 0.65: median {np.median(d[dp < 0.65]):.2f} s, p95 {np.percentile(d[dp < 0.65], 95):.2f} s "
      f"(n {int((dp < 0.65).sum())})")
sp = np.array([subs[s].speed for s in subj[onset]])
print(f"Trigger delay vs movement-time factor (speed, >1 slower): r = {np.corrcoef(sp, d)[0, 1]:.2f}")
print("\nPer subject (onsets): subject, detach_prob, speed, trigger delay median / p95")
for s in sorted(subs):
    m = subj[onset] == s
    print(f"- {s}: {subs[s].detach_prob:.2f}, {subs[s].speed:.2f}, {np.median(d[m]):.2f} / {np.percentile(d[m], 95):.2f}")
# error pairs at early points, CNN vs ConvLSTM
from collections import Counter
names = ["Phone", "Texting", "TouchScreen", "Drink", "Marker", "Other"]
for lab, p, j in (("ConvLSTM S=2 (1.62 s)", conv, 1), ("1D CNN 1.62 s", cnn, 4), ("1D CNN 1.0 s", cnn, 2), ("ConvLSTM S=3 (2.78 s)", conv, 2)):
    pr = p[j].argmax(1)
    e = Counter((names[a], names[b]) for a, b in zip(y[onset], pr[onset]) if a != b)
    tot = sum(e.values())
    print(f"\n{lab}: {tot} onset errors of {onset.sum()}; top pairs (truth -> predicted): " +
          ", ".join(f"{a}->{b} {n} ({n / tot:.0%})" for (a, b), n in e.most_common(8)))

# "phone in hand": Phone and Texting summed into one class before the decision (CNN probabilities)
print("\nPhone+Texting merged into one class ('phone in hand') before deciding, 1D CNN, whole grid:\n")
print("| policy | onsets alerted | class right (6 classes) | right, Phone+Texting one class | onset->alert median | p95 | <= 2.0 s | <= 3.5 s | Other alerting |")
print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
m = cnn.copy()
m[..., 0] += m[..., 1]
m[..., 1] = 0
for t in (0.8, 0.9, 0.95, 0.97):
    print(row(f"CNN merged, threshold {t}", m, GRID, [t] * 9))
mc = conv.copy()
mc[..., 0] += mc[..., 1]
mc[..., 1] = 0
for t in (0.8, 0.9, 0.95):
    print(row(f"ConvLSTM merged, threshold {t} (from S=1)", mc, CONV, [t] * 6))
