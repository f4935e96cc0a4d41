"""Class accuracy as a function of time since the hand left the wheel (onset), whatever the trigger: every
(onset capture, decision point) pair of the selection cohort placed at trigger delay + decision point, binned.
PYTHONPATH=/work/main python /work/notes/s12-w/info_vs_onset.py > /work/notes/s12-w/info_vs_onset.md"""
import numpy as np

from edge_runtime.wearable.classifier import needed_frames

z = np.load("/tmp/s12w/sel.npz")
y, rep, delay = z["y"], z["repeat"], z["delay_s"]
onset = (y != 5) & (rep == 0)
hand = np.array([0, 0, 2, 3, 4, 5])
P = dict(np.load("/work/notes/s12-w/prefix_latency_probs.npz"))
GRID = np.array((0.47, 0.75, 1.0, 1.3, 1.62, 2.0, 2.78, 3.93, 5.99))
CONV = np.array([(needed_frames(s) - 1 - 100) / 100 for s in range(1, 7)])
BINS = [(0.5, 1.0), (1.0, 1.5), (1.5, 2.0), (2.0, 2.5), (2.5, 3.0), (3.0, 3.5), (3.5, 4.5), (4.5, 6.5)]
print("# Onset-capture class accuracy by time since the hand left the wheel (selection cohort)\n")
print("Cell: top-class accuracy / with Phone+Texting one class / not Other (n pairs). A pair = one onset capture at one "
      "decision point, placed at its trigger delay + the decision point's time after the trigger.\n")
print("| model | " + " | ".join(f"{a}-{b} s" for a, b in BINS) + " |")
print("|---|" + "---|" * len(BINS))
for name, cuts in (("1D CNN (prefix, 25 Hz)", GRID), ("gradient boosting (prefix shape + stats)", GRID),
                   ("shipped ConvLSTM (calibrated)", CONV)):
    p = P[name][:, onset]
    t = delay[onset][None, :] + cuts[:, None]
    pr = p.argmax(2)
    yy = np.broadcast_to(y[onset], pr.shape)
    cells = []
    for a, b in BINS:
        m = (t >= a) & (t < b)
        cells.append(f"{np.mean(pr[m] == yy[m]):.2f} / {np.mean(hand[pr[m]] == hand[yy[m]]):.2f} / {np.mean(pr[m] != 5):.2f} ({int(m.sum())})")
    print(f"| {name} | " + " | ".join(cells) + " |")
