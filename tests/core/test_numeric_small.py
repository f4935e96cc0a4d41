"""edge_runtime.core.numeric's Python-float medians (session 16) against the medians they replace
(:func:`edge_runtime.core.numeric.median`, numpy's sort) and numpy's own, to the bit."""
import math
import warnings
from collections import deque

import numpy as np

from edge_runtime.core.numeric import median, median_columns, median_floats


def bits(x) -> bytes:
    return np.asarray(x, np.float64).tobytes()


def _sample(rng, shape):
    a = rng.normal(0.0, 1.0, shape) * np.exp(rng.uniform(-30, 30, shape))
    r = rng.random()
    if r < 0.3:  # ties
        a = np.round(a, 1)
    elif r < 0.45:
        a.flat[rng.integers(a.size, size=2)] = rng.choice([np.nan, np.inf, -np.inf, 1e308, -1e308, 5e-324, -5e-324])
    elif r < 0.55:  # zeros, of one sign per array (both signs tied in the middle: the test below)
        a.flat[rng.integers(a.size, size=3)] = rng.choice([0.0, -0.0])
    return a


def _both_zeros(a) -> bool:
    z = np.signbit(a[a == 0])
    return bool(z.any() and not z.all())


def test_median_floats_is_the_old_median_to_the_bit():
    rng = np.random.default_rng(1620)
    for _ in range(6000):
        a = _sample(rng, int(rng.integers(1, 32)))
        if _both_zeros(a):
            continue
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # inf - inf in a mean of two
            old, ref = median(a), np.median(a)
        for values in (a.tolist(), deque(a.tolist())):
            got = median_floats(values)
            assert type(got) is float and bits(got) == bits(old), (a, got, old)
            assert bits(got) == bits(ref) or got == ref == 0.0, (a, got, ref)  # numpy's own: up to a zero's sign


def test_a_tie_of_both_zeros_differs_in_sign_at_most():
    for values in ([0.0, -0.0, 1.0], [-0.0, 0.0, 0.0], [-1.0, 0.0, -0.0], [-0.0, 0.0], [-0.0]):
        assert median_floats(values) == median(np.array(values)) == np.median(values) == 0.0


def test_median_columns_is_the_old_median_to_the_bit():
    rng = np.random.default_rng(1621)
    for _ in range(3000):
        a = _sample(rng, (int(rng.integers(1, 18)), int(rng.integers(1, 4))))
        if _both_zeros(a):
            a[a == 0] = 0.0
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)
            old = median(a, axis=0)
        got = median_columns(a)
        assert got.dtype == old.dtype and got.shape == old.shape and got.tobytes() == old.tobytes(), a
    assert math.isnan(median_floats([1.0, math.nan, 2.0])) and math.isnan(median_floats([math.nan]))
