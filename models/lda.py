"""The LDA baseline (dissertation section 2.3.5: F1 0.38).

Features per capture window: mean, standard deviation, minimum and maximum of
each axis of the 200-frame resampled window (12 numbers), from the same
resampler the product uses (``edge_runtime.preprocess.resample_capture``).
Classifier: scikit-learn's ``LinearDiscriminantAnalysis`` (lsqr solver with
Ledoit-Wolf shrinkage, which is stable when a class has few windows).
"""
from __future__ import annotations

import numpy as np
from sklearn.discriminant_analysis import LinearDiscriminantAnalysis

from edge_runtime.preprocess import resample_capture


def window_features(X700: np.ndarray) -> np.ndarray:
    """(N, 700, 3) m/s^2 -> (N, 12): mean, std, min, max of x, y, z after resampling to 200 frames."""
    x = resample_capture(np.asarray(X700, dtype=np.float32)).astype(np.float64)
    return np.concatenate([x.mean(1), x.std(1), x.min(1), x.max(1)], axis=1)


class LDAClassifier:
    """LDA on :func:`window_features`; ``predict_proba`` gives (N, n_classes) for any n_classes."""

    arch = "lda"

    def __init__(self, n_classes: int):
        self.n_classes = int(n_classes)
        self.lda = LinearDiscriminantAnalysis(solver="lsqr", shrinkage="auto")

    def fit(self, X700: np.ndarray, y: np.ndarray) -> "LDAClassifier":
        self.lda.fit(window_features(X700), np.asarray(y))
        return self

    def predict_proba(self, X700: np.ndarray) -> np.ndarray:
        p = self.lda.predict_proba(window_features(X700))
        out = np.zeros((len(p), self.n_classes))
        out[:, self.lda.classes_.astype(int)] = p  # classes never seen in training get 0
        return out

    def predict(self, X700: np.ndarray) -> np.ndarray:
        return self.predict_proba(X700).argmax(1)
