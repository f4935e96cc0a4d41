"""Predictions and metrics: accuracy, macro-F1, per-class and per-subject tables, confusion PNG.

Conventions
-----------
* ``macro_f1`` averages the per-class F1 over the classes that occur in the
  truth or the predictions (scikit-learn's default label set), so a class absent
  from a test subset neither helps nor hurts unless it is predicted.
* ``macro_f1_distractions`` is the same average over every class except "Other"
  (the dissertation's Table 2.3 lists the five distractions).
* Per-subject rows (Tables 2.1/2.2): macro recall, precision and F1 over the
  labels that occur in that subject's truth or predictions, plus accuracy and n.
* ``confusion``: rows = truth, columns = prediction, in ``classes`` order.
"""
from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np
from sklearn.metrics import accuracy_score, confusion_matrix, precision_recall_fscore_support

from edge_runtime.wearable.classifier import preprocess
from edge_runtime.wearable.labels import OTHER


def predict(model, X700: np.ndarray, batch_size: int = 512) -> np.ndarray:
    """Class probabilities (N, K) for capture windows (N, 700, 3) m/s^2.

    ``model``: a torch module (applies :func:`edge_runtime.wearable.classifier.preprocess`,
    then softmax; windows already preprocessed, (N, 6, 33, 3), are used as they are) or anything
    with ``predict_proba(X700)`` (the LDA baseline).
    """
    X700 = np.asarray(X700, dtype=np.float32)
    if hasattr(model, "predict_proba"):
        return np.asarray(model.predict_proba(X700), dtype=np.float64)
    import torch

    out = _torch_batches(model, X700, batch_size, lambda x: torch.softmax(model(x), dim=1))
    return np.concatenate(out) if out else np.zeros((0, 0))


def _torch_batches(model, X700: np.ndarray, batch_size: int, forward) -> list[np.ndarray]:
    """``forward`` (a function of the model input) on preprocessed batches of X700 (or of X700 itself
    when it is already preprocessed, (N, 6, 33, 3): a LOSO run preprocesses each set once, not per
    fold), the model in eval mode and without autograd; the model's training flag restored afterwards."""
    import torch

    ready = X700.shape[1:] == (6, 33, 3)
    was_training = model.training
    model.eval()
    out = []
    with torch.inference_mode():
        for i in range(0, len(X700), batch_size):
            x = X700[i:i + batch_size]
            out.append(forward(torch.from_numpy(x if ready else preprocess(x))).double().numpy())
    model.train(was_training)
    return out


def predict_steps(model, X700: np.ndarray, batch_size: int = 512) -> np.ndarray:
    """The ConvLSTM's class probabilities after every sub-window: (S = 6, N, K) for capture windows
    (N, 700, 3) m/s^2; ``[s - 1]`` is the early decision on ``preprocess(capture)[:, :s]``."""
    import torch

    out = _torch_batches(model, np.asarray(X700, dtype=np.float32), batch_size,
                         lambda x: torch.softmax(model(x, all_steps=True), dim=2))
    return np.concatenate(out, axis=0).transpose(1, 0, 2) if out else np.zeros((6, 0, 0))


def _prf(y_true, y_pred, labels, average):
    p, r, f, s = precision_recall_fscore_support(y_true, y_pred, labels=labels, average=average,
                                                 zero_division=0)
    return p, r, f, s


def compute_metrics(y_true: Sequence[int], y_pred: Sequence[int], classes: Sequence[str],
                    subject: Sequence[int] | None = None) -> dict:
    """Everything the reports need, JSON-ready."""
    y_true = np.asarray(y_true, dtype=np.int64)
    y_pred = np.asarray(y_pred, dtype=np.int64)
    classes = list(classes)
    k = len(classes)
    present = sorted(set(y_true.tolist()) | set(y_pred.tolist()))
    out: dict = {"n": int(len(y_true)), "classes": classes}
    if len(y_true) == 0:
        out.update(accuracy=float("nan"), macro_f1=float("nan"), macro_precision=float("nan"),
                   macro_recall=float("nan"), per_class={}, confusion=[[0] * k for _ in range(k)])
        return out
    out["accuracy"] = float(accuracy_score(y_true, y_pred))
    p, r, f, _ = _prf(y_true, y_pred, present, "macro")
    out.update(macro_f1=float(f), macro_precision=float(p), macro_recall=float(r))
    _, _, wf, _ = _prf(y_true, y_pred, present, "weighted")
    out["weighted_f1"] = float(wf)
    dis = [i for i in present if classes[i] != OTHER]
    if OTHER in classes and dis:
        p, r, f, _ = _prf(y_true, y_pred, dis, "macro")
        out.update(macro_f1_distractions=float(f), macro_precision_distractions=float(p),
                   macro_recall_distractions=float(r))
    p, r, f, s = _prf(y_true, y_pred, list(range(k)), None)
    out["per_class"] = {classes[i]: {"precision": float(p[i]), "recall": float(r[i]), "f1": float(f[i]),
                                     "support": int(s[i])} for i in range(k)}
    out["confusion"] = confusion_matrix(y_true, y_pred, labels=list(range(k))).astype(int).tolist()
    if subject is not None:
        out["per_subject"] = per_subject_table(y_true, y_pred, subject)
        f1s = [row["f1"] for row in out["per_subject"].values()]
        out["per_subject_mean"] = {key: float(np.mean([row[key] for row in out["per_subject"].values()]))
                                   for key in ("recall", "precision", "f1", "accuracy")} if f1s else {}
    return out


def per_subject_table(y_true, y_pred, subject) -> dict:
    """{subject id (str): {recall, precision, f1, accuracy, n}} (macro over that subject's labels)."""
    y_true, y_pred, subject = map(np.asarray, (y_true, y_pred, subject))
    rows = {}
    for s in np.unique(subject):
        m = subject == s
        labels = sorted(set(y_true[m].tolist()) | set(y_pred[m].tolist()))
        p, r, f, _ = _prf(y_true[m], y_pred[m], labels, "macro")
        rows[str(int(s))] = {"recall": float(r), "precision": float(p), "f1": float(f),
                             "accuracy": float(np.mean(y_true[m] == y_pred[m])), "n": int(m.sum())}
    return rows


def save_confusion_png(confusion, classes: Sequence[str], path, title: str = "") -> Path:
    """Row-normalised confusion matrix with counts, rows = truth."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    cm = np.asarray(confusion, dtype=float)
    norm = cm / np.maximum(cm.sum(axis=1, keepdims=True), 1)
    k = len(classes)
    fig, ax = plt.subplots(figsize=(1.1 * k + 2.2, 1.0 * k + 1.6), dpi=110)
    im = ax.imshow(norm, cmap="Blues", vmin=0, vmax=1)
    for i in range(k):
        for j in range(k):
            ax.text(j, i, f"{int(cm[i, j])}\n{norm[i, j]:.2f}", ha="center", va="center", fontsize=8,
                    color="white" if norm[i, j] > 0.55 else "black")
    ax.set_xticks(range(k), classes, rotation=35, ha="right")
    ax.set_yticks(range(k), classes)
    ax.set_xlabel("predicted")
    ax.set_ylabel("truth")
    if title:
        ax.set_title(title, fontsize=10)
    fig.colorbar(im, ax=ax, fraction=0.046, pad=0.04, label="row fraction")
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path
