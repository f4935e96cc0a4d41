"""Confidence of the early decisions: temperature scaling, calibration error, preliminary-alert thresholds.

Everything here is numpy on class probabilities (N, K) and is fitted on validation captures only
(the separate simulated cohort of :mod:`models.selection`), never on the subjects a figure is
reported for.

* :func:`fit_temperature`: one temperature T per decision step, minimising the negative
  log-likelihood of ``softmax(log p / T)`` (= ``softmax(logits / T)``: the softmax's
  normaliser cancels) on a log-spaced grid refined by golden-section search.
* :func:`expected_calibration_error`: ECE over ``ECE_BINS`` equal-width confidence bins.
* :func:`min_confidence_for_precision`: the preliminary-alert threshold. An alert is a
  prediction other than Other with calibrated confidence >= t; its *alert precision* is the
  fraction of those alerts whose truth is a distraction (not Other: a driver warned for
  scratching an ear is the false alert that costs trust). The threshold is the smallest t on a
  0.01 grid whose precision is >= ``target`` with at least ``min_alerts`` alerts at and above
  it; 1.0 (no preliminary alert at that step) when no t reaches it.
"""
from __future__ import annotations

import math

import numpy as np

ECE_BINS = 15
T_MIN, T_MAX = 0.05, 20.0
ALERT_PRECISION_TARGET = 0.95
MIN_ALERTS = 30


def temper(probs: np.ndarray, temperature: float) -> np.ndarray:
    """Probabilities (N, K) re-scaled by a temperature: softmax(log p / T)."""
    z = np.log(np.clip(np.asarray(probs, np.float64), 1e-12, 1.0)) / float(temperature)
    z -= z.max(axis=1, keepdims=True)
    e = np.exp(z)
    return e / e.sum(axis=1, keepdims=True)


def nll(probs: np.ndarray, y: np.ndarray) -> float:
    p = np.clip(np.asarray(probs)[np.arange(len(y)), np.asarray(y)], 1e-12, 1.0)
    return float(-np.mean(np.log(p)))


def fit_temperature(probs: np.ndarray, y: np.ndarray) -> float:
    """The temperature in [T_MIN, T_MAX] that minimises the NLL of ``temper(probs, T)`` on labels y."""
    y = np.asarray(y)
    if len(y) == 0:
        raise ValueError("no validation windows to fit a temperature on")
    f = lambda log_t: nll(temper(probs, math.exp(log_t)), y)  # noqa: E731
    grid = np.linspace(math.log(T_MIN), math.log(T_MAX), 41)
    k = int(np.argmin([f(g) for g in grid]))
    lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
    r = (math.sqrt(5) - 1) / 2  # golden section inside the best grid cell's neighbours
    a, b = hi - r * (hi - lo), lo + r * (hi - lo)
    for _ in range(40):
        if f(a) < f(b):
            hi, b = b, a
            a = hi - r * (hi - lo)
        else:
            lo, a = a, b
            b = lo + r * (hi - lo)
    return float(math.exp((lo + hi) / 2))


def expected_calibration_error(probs: np.ndarray, y: np.ndarray, bins: int = ECE_BINS) -> float:
    """Sum over confidence bins of |accuracy - mean confidence| weighted by the bin's share."""
    probs, y = np.asarray(probs), np.asarray(y)
    if len(y) == 0:
        return float("nan")
    conf, correct = probs.max(1), probs.argmax(1) == y
    idx = np.minimum((conf * bins).astype(int), bins - 1)
    err = 0.0
    for b in range(bins):
        m = idx == b
        if m.any():
            err += m.mean() * abs(correct[m].mean() - conf[m].mean())
    return float(err)


def alert_precision(probs: np.ndarray, y: np.ndarray, other: int, threshold: float) -> tuple[float, int]:
    """(fraction of alerts whose truth is a distraction, number of alerts) at ``threshold``."""
    probs, y = np.asarray(probs), np.asarray(y)
    alert = (probs.argmax(1) != other) & (probs.max(1) >= threshold)
    n = int(alert.sum())
    return (float(np.mean(y[alert] != other)) if n else float("nan")), n


def min_confidence_for_precision(probs: np.ndarray, y: np.ndarray, other: int,
                                 target: float = ALERT_PRECISION_TARGET, min_alerts: int = MIN_ALERTS) -> float:
    """The smallest threshold on a 0.01 grid with alert precision >= target (see the module docstring)."""
    for t in np.round(np.arange(0.0, 1.0, 0.01), 2):
        prec, n = alert_precision(probs, y, other, t)
        if n < min_alerts:
            break
        if prec >= target:
            return float(t)
    return 1.0
