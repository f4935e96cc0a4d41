"""Small numeric helpers for the per-frame path, each with numpy's own result to the bit (the medians: but for
the sign of a zero result, which compares equal and changes no decision)."""
from __future__ import annotations

import math

import numpy as np


def median(a, axis: int | None = None):
    """``np.median(a, axis)`` of a small float64 array (None or 0 for ``axis``), to the bit but for the sign of
    a zero result (numpy's mean adds from +0.0, so a middle value of -0.0 comes out +0.0 there), about ten times
    faster: numpy's median spends some 40 us per call on its generality, and the robot's per-frame path takes
    three medians of a handful of numbers per person (the tracker's match cost, the lifter's image motion, the
    floor anchoring's factor). The same arithmetic: the middle value of the sorted numbers, or the mean of the
    middle two ((lo + hi) / 2, as ``np.mean`` of two); NaN when any number along the axis is NaN (no warning).
    Anything else (another dtype or axis, nothing to take the median of) goes to ``np.median``
    (tests/core/test_numeric.py pins the two together)."""
    a = np.asarray(a)
    if a.dtype != np.float64 or axis not in (None, 0) or a.size == 0 or (axis == 0 and a.ndim == 0):
        return np.median(a, axis=axis)
    s = np.sort(a.ravel() if axis is None else a, axis=0)
    n = s.shape[0]
    h = n // 2
    m = s[h] if n % 2 else (s[h - 1] + s[h]) / 2.0
    nan = np.isnan(s[-1])  # sorting puts NaN last
    if np.ndim(m) == 0:
        return np.float64(np.nan) if nan else np.float64(m)
    return np.where(nan, np.nan, m) if nan.any() else m


def norms2(d: np.ndarray) -> np.ndarray:
    """``np.linalg.norm(d, axis=1)`` of float64 (N, 2) ``d``, to the bit, without its per-call overhead: numpy
    computes it as ``sqrt(add.reduce(d * d, axis=1))``, and an add.reduce over an axis of two is the one
    addition ``x*x + y*y`` (tests/core/test_numeric.py pins the two together)."""
    x, y = d[:, 0], d[:, 1]
    return np.sqrt(x * x + y * y)


def median_floats(values) -> float:
    """:func:`median` of a few (at least one) numbers, on Python floats: the middle of the sorted numbers, or
    ``(lo + hi) / 2`` of the middle two, NaN when any is NaN; the same IEEE operations, without building an
    array (the floor anchoring's per-person factor and the lifter's image motion, every frame). Signed zeros,
    where neither is numpy's to the bit: when ``-0.0`` and ``0.0`` tie in the middle, which of the two comes
    out follows Python's stable sort here and numpy's sort in :func:`median`; and ``np.median`` itself sums
    from ``+0.0`` (a median of ``-0.0`` alone is ``0.0`` there, ``-0.0`` here and in :func:`median`). All equal
    under ``==``; tests/core/test_numeric_small.py pins the rest to the bit."""
    s = sorted(values)
    if any(v != v for v in s):
        return math.nan
    h = len(s) // 2
    return float(s[h]) if len(s) % 2 else (s[h - 1] + s[h]) / 2.0


def median_columns(a: np.ndarray) -> np.ndarray:
    """``median(a, axis=0)`` of a float64 (n, k) array with n >= 1 (:func:`median_floats` per column): the
    lifter's image-motion step, from a handful of joints' two coordinates."""
    return np.array([median_floats(column) for column in a.T.tolist()])
