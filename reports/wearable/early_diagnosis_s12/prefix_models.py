"""Is the information there? Prefix-only classifiers trained on the TRAINING cohort (cohort seed 0: its
ground-truth windows and detector captures: the train and test npz files that models/ writes and the shipped model
trains on) and scored on every capture of the SELECTION cohort (seed 1000, /tmp/s12w/sel.npz). No held-out data.

    PYTHONPATH=/work/main nice -n 10 /work/main/.venv/bin/python /work/notes/s12-w/prefix_models.py OUT_PREFIX [--cnn]

A prefix "cut c s after the trigger" = capture frames [0, 100 + 100 c) (the capture starts 1 s before the trigger).
Models: LDA on 12 summary statistics (mean, sd, min, max per axis); logistic regression and histogram gradient
boosting on the prefix's shape (0.1 s block means per axis, plus the summary statistics); optionally a small 1D CNN.
Compared with the shipped ConvLSTM's accuracy on the same captures (per_s_probs.npz from per_s.py).
"""
import json
import sys
import time

import numpy as np
from sklearn.discriminant_analysis import LinearDiscriminantAnalysis
from sklearn.ensemble import HistGradientBoostingClassifier
from sklearn.linear_model import LogisticRegression
from sklearn.metrics import f1_score
from sklearn.pipeline import make_pipeline
from sklearn.preprocessing import StandardScaler

from models.dataset import load_npz

CUTS = {"S=1 (0.47 s)": 0.47, "1.0 s": 1.0, "S=2 (1.62 s)": 1.62, "2.0 s": 2.0, "S=3 (2.78 s)": 2.78, "S=6 (5.99 s)": 5.99}
CONVLSTM_S = {"S=1 (0.47 s)": 1, "S=2 (1.62 s)": 2, "S=3 (2.78 s)": 3, "S=6 (5.99 s)": 6}


def nframes(c):
    return min(700, 100 + int(round(100 * c)) + 1)


def stats(X):
    return np.concatenate([X.mean(1), X.std(1), X.min(1), X.max(1)], 1)


def shape(X):
    n = X.shape[1] // 10 * 10
    b = X[:, :n].reshape(len(X), n // 10, 10, 3).mean(2).reshape(len(X), -1)
    return np.concatenate([b, stats(X), X[:, -10:].mean(1) - X[:, :100].mean(1)], 1)


def cnn_fit_predict(Xtr, ytr, Xte, epochs=12, seed=0):
    import torch
    import torch.nn as nn
    torch.set_num_threads(1)
    torch.manual_seed(seed)
    # 25 Hz: mean of 4 frames; channels first
    def prep(X):
        n = X.shape[1] // 4 * 4
        return torch.tensor(X[:, :n].reshape(len(X), n // 4, 4, 3).mean(2).transpose(0, 2, 1), dtype=torch.float32)
    a, b = prep(Xtr), prep(Xte)
    mu, sd = a.mean((0, 2), keepdim=True), a.std((0, 2), keepdim=True)
    a, b = (a - mu) / sd, (b - mu) / sd
    net = nn.Sequential(nn.Conv1d(3, 32, 5, padding=2), nn.ReLU(), nn.Conv1d(32, 32, 5, padding=2), nn.ReLU(),
                        nn.MaxPool1d(2), nn.Conv1d(32, 64, 5, padding=2), nn.ReLU(), nn.AdaptiveMaxPool1d(1),
                        nn.Flatten(), nn.Dropout(0.3), nn.Linear(64, 6))
    # a little more information than a plain max: also the last value matters (where the hand is now)
    opt = torch.optim.Adam(net.parameters(), 2e-3, weight_decay=1e-4)
    yt = torch.tensor(ytr)
    cw = torch.tensor(len(ytr) / (6 * np.bincount(ytr, minlength=6)), dtype=torch.float32)
    lossf = nn.CrossEntropyLoss(weight=cw)
    g = torch.Generator().manual_seed(seed)
    for ep in range(epochs):
        net.train()
        perm = torch.randperm(len(a), generator=g)
        for i in range(0, len(a), 64):
            idx = perm[i:i + 64]
            xb = a[idx]
            # random shift of up to 0.2 s (5 frames at 25 Hz), like the ConvLSTM's time-shift augmentation
            k = int(torch.randint(-5, 6, (1,), generator=g))
            xb = torch.roll(xb, k, dims=2)
            opt.zero_grad()
            lossf(net(xb), yt[idx]).backward()
            opt.step()
    net.eval()
    with torch.no_grad():
        return net(b).softmax(1).numpy()


def main(out, cnn=False):
    t0 = time.time()
    gt, cap = load_npz("/work/main/reports/wearable/data/train.npz"), load_npz("/work/main/reports/wearable/data/test.npz")
    Xtr = np.concatenate([gt.X, cap.X]).astype(np.float32)
    ytr = np.concatenate([gt.y, cap.y])
    z = np.load("/tmp/s12w/sel.npz")
    Xte, yte, rep = z["X"], z["y"], z["repeat"]
    classes = list(z["classes"])
    assert classes == list(gt.classes)
    other, ph, tx = classes.index("Other"), classes.index("Phone"), classes.index("Texting")
    hand = np.array([ph if k == tx else k for k in range(6)])
    onset = (yte != other) & (rep == 0)
    conv = np.load(out.rsplit("/", 1)[0] + "/per_s_probs.npz")["probs"]  # calibrated, unweighted
    res = {}
    models = {
        "LDA, 12 summary stats": lambda: (stats, make_pipeline(StandardScaler(), LinearDiscriminantAnalysis())),
        "logistic regression, shape (0.1 s blocks) + stats": lambda: (shape, make_pipeline(StandardScaler(), LogisticRegression(C=0.1, max_iter=2000))),
        "gradient boosting, shape + stats": lambda: (shape, HistGradientBoostingClassifier(max_iter=200, learning_rate=0.1, random_state=0)),
    }
    for cut_name, c in CUTS.items():
        n = nframes(c)
        for mname, mk in models.items():
            feat, m = mk()
            m.fit(feat(Xtr[:, :n]), ytr)
            pr = m.predict_proba(feat(Xte[:, :n])).argmax(1)
            res[(cut_name, mname)] = pr
            print(f"{cut_name} {mname}: acc {np.mean(pr == yte):.3f} ({time.time() - t0:.0f} s)", flush=True)
        if cnn:
            pr = cnn_fit_predict(Xtr[:, :n], ytr, Xte[:, :n]).argmax(1)
            res[(cut_name, "1D CNN on the prefix (25 Hz)")] = pr
            print(f"{cut_name} CNN: acc {np.mean(pr == yte):.3f} ({time.time() - t0:.0f} s)", flush=True)
        if cut_name in CONVLSTM_S:
            res[(cut_name, "shipped ConvLSTM int8 (calibrated, no class weights)")] = conv[CONVLSTM_S[cut_name] - 1].argmax(1)
    L = ["# Prefix-only classifiers: trained on cohort seed 0 (GT windows + captures), scored on every selection-cohort capture", "",
         f"Train {len(ytr)} windows (cohort seed 0, 20 subjects); test {len(yte)} captures (seed 1000, 12 subjects; "
         f"{int(onset.sum())} distraction onsets). Wall {time.time() - t0:.0f} s.", "",
         "| prefix (after the trigger) | model | acc every capture | macro-F1 every capture | acc onsets | acc onsets, Phone+Texting one class | Phone onsets -> Texting | Texting onsets -> Phone |",
         "|---|---|---:|---:|---:|---:|---:|---:|"]
    for (cut_name, mname), pr in res.items():
        L.append(f"| {cut_name} | {mname} | {np.mean(pr == yte):.3f} | {f1_score(yte, pr, average='macro'):.3f} | "
                 f"{np.mean(pr[onset] == yte[onset]):.3f} | {np.mean(hand[pr[onset]] == hand[yte[onset]]):.3f} | "
                 f"{np.mean(pr[onset & (yte == ph)] == tx):.2f} | {np.mean(pr[onset & (yte == tx)] == ph):.2f} |")
    # per-class recall (onsets) of the best non-ConvLSTM model at S=2
    open(out + ".md", "w").write("\n".join(L) + "\n")
    np.savez_compressed(out + "_preds.npz", **{f"{k[0]}|{k[1]}": v for k, v in res.items()})
    print("\n".join(L))


if __name__ == "__main__":
    main(sys.argv[1], "--cnn" in sys.argv)
