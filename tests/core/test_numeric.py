"""edge_runtime.core.numeric: the per-frame path's fast helpers give numpy's results to the bit."""
import warnings

import numpy as np

from edge_runtime.core.numeric import median


def same(got, want) -> bool:
    got, want = np.asarray(got), np.asarray(want)
    return got.shape == want.shape and got.dtype == want.dtype and np.array_equal(got, want, equal_nan=True)


def test_median_is_numpys_to_the_bit():
    rng = np.random.default_rng(11)
    for _ in range(3000):
        n = int(rng.integers(1, 40))
        shape = (n,) if rng.random() < 0.6 else (n, int(rng.integers(1, 4)))
        a = rng.normal(0.0, 1.0, shape) * np.exp(rng.uniform(-30, 30, shape))
        if rng.random() < 0.3:  # ties
            a = np.round(a, 1)
        if rng.random() < 0.1:
            a.flat[rng.integers(a.size)] = np.nan
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", RuntimeWarning)  # numpy's median of NaN may warn
            for axis in ((None, 0) if a.ndim == 2 else (None, 0)):
                assert same(median(a, axis=axis), np.median(a, axis=axis)), (a, axis)
        assert same(median(list(a.ravel())), np.median(list(a.ravel())))  # a deque or list of floats too


def test_median_hands_anything_else_to_numpy():
    a = np.arange(12, dtype=np.float32).reshape(3, 4)
    assert same(median(a), np.median(a))
    b = np.arange(12.0).reshape(3, 4)
    assert same(median(b, axis=1), np.median(b, axis=1))
    assert same(median([3, 1, 2]), np.median([3, 1, 2]))


def test_norms2_is_numpys_row_norm():
    from edge_runtime.core.numeric import norms2
    rng = np.random.default_rng(1507)
    for case in range(2000):
        d = rng.normal(0, 1, (int(rng.integers(0, 20)), 2)) * 10.0 ** rng.uniform(-200, 200)
        for value in (np.nan, np.inf, -np.inf, -0.0, 0.0, 1e-320):
            d[rng.random(d.shape) < 0.03] = value
        with np.errstate(all="ignore"):
            want = np.linalg.norm(d, axis=1)
            got = norms2(d)
        assert got.dtype == want.dtype and got.shape == want.shape and got.tobytes() == want.tobytes(), case
