"""Capture window -> classifier input (numpy only).

The detector hands over 700 frames (7 s at 100 Hz, m/s^2, channels x, y, z).
The dissertation (section 2.2.2) downsamples them to 200 frames (100 Hz -> ~28.6 Hz)
and reshapes the first 198 into 6 subsequences of 33 frames (section 2.2.3).

The downsampler is a proper anti-aliased polyphase resampler with ratio 2/7:
the same Kaiser-windowed FIR (beta 5, 10 zero crossings per side of the lower
rate) as ``scipy.signal.resample_poly(x, 2, 7, padtype="mean")``, written as
one fixed 200 x 700 matrix so that one capture costs one small matmul.
``tests/test_preprocess.py`` pins it to scipy.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np

CAPTURE_FRAMES = 700
RESAMPLED_FRAMES = 200
UP, DOWN = 2, 7
N_SUBSEQ = 6
SUBSEQ_FRAMES = 33
N_CHANNELS = 3
MODEL_INPUT_SHAPE = (N_SUBSEQ, SUBSEQ_FRAMES, N_CHANNELS)


def _kaiser_lowpass(num_taps: int, cutoff: float, beta: float) -> np.ndarray:
    """Windowed-sinc low-pass, cutoff as a fraction of Nyquist, unit DC gain
    (what ``scipy.signal.firwin(num_taps, cutoff, window=("kaiser", beta))`` gives)."""
    m = np.arange(num_taps) - (num_taps - 1) / 2.0
    h = cutoff * np.sinc(cutoff * m) * np.kaiser(num_taps, beta)
    return h / h.sum()


def polyphase_filter(up: int, down: int) -> tuple[np.ndarray, int]:
    """scipy.signal.resample_poly's FIR for up/down, pre-padded, and the number
    of leading output samples to drop (its group delay in output samples)."""
    max_rate = max(up, down)
    half_len = 10 * max_rate
    h = _kaiser_lowpass(2 * half_len + 1, 1.0 / max_rate, 5.0) * up
    n_pre_pad = down - half_len % down
    return np.concatenate([np.zeros(n_pre_pad), h]), (half_len + n_pre_pad) // down


@lru_cache(maxsize=8)
def resample_matrix(n_in: int = CAPTURE_FRAMES, up: int = UP, down: int = DOWN) -> np.ndarray:
    """The (n_out, n_in) float64 matrix of the polyphase resampler up/down."""
    h, n_pre_remove = polyphase_filter(up, down)
    n_out = -(-n_in * up // down)
    k = np.arange(n_out)[:, None] + n_pre_remove
    j = np.arange(n_in)[None, :]
    idx = k * down - j * up  # upfirdn: y[i] = sum_j x[j] h[i*down - j*up]
    valid = (idx >= 0) & (idx < h.size)
    mat = np.where(valid, h[np.clip(idx, 0, h.size - 1)], 0.0)
    mat.setflags(write=False)
    return mat


def resample_poly(x: np.ndarray, up: int, down: int) -> np.ndarray:
    """Resample a long (n, C) stream by up/down along axis 0, mean-padded;
    equal to ``scipy.signal.resample_poly(x, up, down, axis=0, padtype="mean")``."""
    x = np.asarray(x, dtype=np.float64)
    if up == down:
        return x.copy()
    h, n_pre_remove = polyphase_filter(up, down)
    n_out = -(-len(x) * up // down)
    mean = x.mean(axis=0, keepdims=True)
    stuffed = np.zeros((len(x) * up, x.shape[1]))
    stuffed[::up] = x - mean
    y = np.stack([np.convolve(stuffed[:, c], h)[::down] for c in range(x.shape[1])], axis=1)
    y = y[n_pre_remove : n_pre_remove + n_out]
    if len(y) < n_out:  # the filter tail ran out: scipy pads with zeros after the mean
        y = np.concatenate([y, np.zeros((n_out - len(y), x.shape[1]))])
    return y + mean


def resample_capture(x: np.ndarray) -> np.ndarray:
    """(..., 700, C) at 100 Hz -> (..., 200, C) at 200/7 Hz, float32.

    Edges are padded with each window's mean (``padtype="mean"``) so that
    gravity's offset does not ring at the window ends.
    """
    x = np.asarray(x, dtype=np.float64)
    if x.shape[-2] != CAPTURE_FRAMES:
        raise ValueError(f"capture must have {CAPTURE_FRAMES} frames, got {x.shape[-2]}")
    mean = x.mean(axis=-2, keepdims=True)
    y = np.matmul(resample_matrix(), x - mean) + mean  # (200, 700) @ (..., 700, C); einsum is ~50x slower here
    return y.astype(np.float32)


def to_subsequences(x200: np.ndarray) -> np.ndarray:
    """(..., 200, 3) -> (..., 6, 33, 3): drop the last 2 frames, split in 6."""
    lead = x200.shape[:-2]
    return np.ascontiguousarray(
        x200[..., : N_SUBSEQ * SUBSEQ_FRAMES, :].reshape(*lead, N_SUBSEQ, SUBSEQ_FRAMES, x200.shape[-1])
    )


def preprocess(x700: np.ndarray) -> np.ndarray:
    """Capture window(s) (..., 700, 3) m/s^2 -> model input (..., 6, 33, 3) float32 m/s^2."""
    return to_subsequences(resample_capture(x700))
