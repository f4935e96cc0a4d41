"""The capture -> model-input path is scipy's anti-aliased polyphase resampler, then 6 x 33."""
import numpy as np
import pytest
from scipy import signal

from edge_runtime.wearable.preprocess import preprocess, resample_capture, resample_matrix


def test_matches_scipy_resample_poly():
    rng = np.random.default_rng(0)
    x = rng.normal(0, 3, size=(4, 700, 3)) + np.array([9.8, -1.0, 2.0])
    ref = signal.resample_poly(x, 2, 7, axis=1, padtype="mean")
    np.testing.assert_allclose(resample_capture(x), ref, atol=2e-5)


def test_anti_aliasing_rejects_above_new_nyquist_and_keeps_low_band():
    t = np.arange(700) / 100.0
    low = np.sin(2 * np.pi * 2.0 * t)  # 2 Hz: kept
    high = np.sin(2 * np.pi * 20.0 * t)  # 20 Hz > 14.3 Hz Nyquist of 200/7 Hz: removed
    x = np.stack([low, high, np.zeros_like(t)], axis=1)
    y = resample_capture(x)[20:-20]  # away from the edges
    assert np.abs(y[:, 1]).max() < 0.01
    assert 0.95 < np.abs(y[:, 0]).max() < 1.05


def test_dc_gain_is_one_and_constant_gravity_survives():
    x = np.tile([0.5, -2.0, 9.81], (700, 1))
    np.testing.assert_allclose(resample_capture(x), np.tile([0.5, -2.0, 9.81], (200, 1)), atol=1e-5)
    assert np.allclose(resample_matrix().sum(axis=1)[30:-30], 1.0, atol=1e-3)  # polyphase ripple


def test_reshape_order_is_subsequence_frame_axis():
    x200 = np.arange(200 * 3, dtype=np.float32).reshape(200, 3)
    from edge_runtime.wearable.preprocess import to_subsequences

    s = to_subsequences(x200)
    assert s.shape == (6, 33, 3)
    np.testing.assert_array_equal(s[1, 0], x200[33])
    np.testing.assert_array_equal(s[5, 32], x200[197])
    assert preprocess(np.zeros((2, 700, 3))).shape == (2, 6, 33, 3)


def test_wrong_length_is_refused():
    with pytest.raises(ValueError, match="700"):
        resample_capture(np.zeros((699, 3)))


@pytest.mark.parametrize("up,down", [(1, 2), (2, 1), (4, 5), (2, 7)])
def test_stream_resampler_matches_scipy(up, down):
    from edge_runtime.wearable.preprocess import resample_poly

    x = np.random.default_rng(up * 10 + down).normal(size=(3001, 3)) + 9.0
    ref = signal.resample_poly(x, up, down, axis=0, padtype="mean")
    np.testing.assert_allclose(resample_poly(x, up, down), ref, atol=1e-9)
