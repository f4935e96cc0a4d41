"""The distraction classifier: a detector capture in, class probabilities out (numpy + onnxruntime only).

    engine = Engine.from_manifest(ASSETS_DIR, "int8", threads=1)
    probs = engine.classify_capture(x700) # (700, 3) or (N, 700, 3) m/s^2 at 100 Hz -> (K,) or (N, K)
    probs = engine.classify(x)            # model input (6, 33, 3) -> (K,), or (N, 6, 33, 3) -> (N, K)

The classifier's input contract is the detector's capture: 700 frames (7 s at
100 Hz, m/s^2, channels x, y, z). Turning it into the model's input is part of
this module, so a capture reaches the model through one module:

* the dissertation (section 2.2.2) downsamples the capture to 200 frames
  (100 Hz -> ~28.6 Hz) and reshapes the first 198 into 6 subsequences of 33
  frames (section 2.2.3): :func:`preprocess`;
* the downsampler is a proper anti-aliased polyphase resampler with ratio 2/7:
  the same Kaiser-windowed FIR (beta 5, 10 zero crossings per side of the lower
  rate) as ``scipy.signal.resample_poly(x, 2, 7, padtype="mean")``, written as
  one fixed 200 x 700 matrix so that one capture costs one small matmul
  (``tests/wearable/test_classifier.py`` pins it to scipy). :func:`resample_poly`
  is the same filter on a long stream (a recording at another rate, see
  :mod:`edge_runtime.wearable.sources`).

Training and export (``models/``, ``export/``) call :func:`preprocess` too, so the
model is trained on exactly what the box feeds it.

Loading goes through ``assets/manifest.json``: the file's sha256 is checked
against the manifest before the bytes are handed to onnxruntime (the bytes
that were hashed are the bytes that are loaded); a mismatch raises
:class:`ModelIntegrityError` naming the file. The session is set up for a
small edge box: ``threads`` intra-op threads (default 1), one inter-op
thread, sequential execution, no spin-waiting (idle threads sleep instead of
burning a core), all graph optimisations.

The model's input is ``imu`` (N, 6, 33, 3) float32 in m/s^2, the output of
:func:`preprocess`; its output ``probs`` (N, K) is a softmax in ``classes``
order. This module never imports torch.
"""
from __future__ import annotations

import json
import os
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import onnxruntime as ort

from edge_runtime import config
from edge_runtime.core.manifest import (
    ASSETS_DIR,
    CLASSIFIER_ARCHS,
    STEP_ARCH,
    ManifestError,
    ModelIntegrityError,
    load_manifest,
    load_verified,
    manifest_path,
    read_verified,
)
from edge_runtime.core.onnx import fast_run, open_session, same_arrays

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


@lru_cache(maxsize=None)
def needed_frames(steps: int) -> int:
    """Raw capture frames (from capture frame 0 = trigger - 100) the first ``steps`` sub-windows of
    :func:`preprocess` are computed from: the polyphase filter reaches 35 raw frames past resampled
    frame j (about j * 3.5 + 36), so sub-windows 1..6 need 148, 263, 379, 494, 610 and 700 frames."""
    if not 1 <= steps <= N_SUBSEQ:
        raise ValueError(f"steps must lie in 1..{N_SUBSEQ}, got {steps}")
    rows = resample_matrix()[: steps * SUBSEQ_FRAMES]
    return int(np.flatnonzero(rows.any(axis=0)).max()) + 1


MEAN_EDGE_FRAMES = 10
"""Resampled frames at the start whose value depends on the whole capture's mean: the resampler pads
with the mean (``padtype="mean"``), and these rows of its matrix do not sum to 1 (row 0: 0.64, row 9:
0.9987; from row 10 on within 4e-5 of 1). :func:`preprocess_prefix` cannot know the mean of frames
not yet captured, so only these frames of a prefix differ from the full capture's preprocessing."""


def preprocess_prefix(x_prefix: np.ndarray, steps: int) -> np.ndarray:
    """The first ``steps`` sub-windows (steps, 33, 3) float32 of a capture of which only the first
    ``needed_frames(steps)`` frames (or more) have arrived.

    The missing tail is edge-padded (the hand held where it is) and the capture preprocessed as
    :func:`preprocess` does; for ``steps`` = 6 and a whole capture this is :func:`preprocess`. Every
    frame computed from arrived samples only is the full preprocessing's, to float32 rounding,
    except the first :data:`MEAN_EDGE_FRAMES`, which depend on the mean of the unseen tail.

    The same float64 arithmetic as :func:`preprocess`, arranged for one capture at a time (the loop
    calls this about 18,000 times a day): the resampler's matrix is banded and repeats every two
    sub-windows (66 rows read the next 231 frames with the same weights), so each pair of sub-windows
    is one (66, 298) product instead of 198 rows against every frame, and the mean enters as
    ``M x + (1 - row sum) * mean`` rather than through a subtraction from every frame."""
    x = np.asarray(x_prefix, dtype=np.float32)
    if x.ndim != 2:
        raise ValueError(f"a prefix for {steps} sub-windows needs {needed_frames(steps)}..{CAPTURE_FRAMES} frames "
                         f"of (n, 3), got {x.shape}")
    return preprocess_prefixes(x[None], steps)[0]


def preprocess_prefixes(x_prefixes: np.ndarray, steps: int) -> np.ndarray:
    """:func:`preprocess_prefix` of N prefixes of one length at once, (N, n, 3) -> (N, steps, 33, 3) float32.
    Each capture goes through the same BLAS calls as alone (one (66, W) product per pair of sub-windows,
    one dot product for its sum), so its rows are :func:`preprocess_prefix`'s bit for bit, whatever N."""
    x = np.asarray(x_prefixes, dtype=np.float32)
    need = needed_frames(steps)
    if x.ndim != 3 or x.shape[2] != N_CHANNELS or not need <= x.shape[1] <= CAPTURE_FRAMES:
        raise ValueError(f"a prefix for {steps} sub-windows needs {need}..{CAPTURE_FRAMES} frames "
                         f"of (n, 3), got {x.shape[1:]}")
    return _prefix_inputs(x, ((steps, x.shape[1]),))[0]


def preprocess_prefix_steps(captures: np.ndarray, steps: Sequence[int]) -> list[np.ndarray]:
    """For N captures (N, n, 3) and each S of ``steps``, :func:`preprocess_prefixes` of their first
    ``needed_frames(S)`` frames, bit for bit (``tests/wearable/test_classifier.py``), at about the cost of
    the largest S alone: the resampler's product is computed once, on every frame. A row of it weighs
    the frames after ``needed_frames(S)`` with exact zeros, so it is the same sum, in the same order,
    as on a prefix whose buffer holds zeros there; only each prefix's mean is its own."""
    x = np.asarray(captures, dtype=np.float32)
    top = max(steps)
    if x.ndim != 3 or x.shape[2] != N_CHANNELS or not needed_frames(top) <= x.shape[1] <= CAPTURE_FRAMES:
        raise ValueError(f"captures for {top} sub-windows need {needed_frames(top)}..{CAPTURE_FRAMES} frames "
                         f"of (n, 3), got {x.shape[1:]}")
    return _prefix_inputs(x, tuple((s, needed_frames(s)) for s in steps))


def step_inputs(captures: np.ndarray, top: int) -> list[np.ndarray]:
    """For N captures (N, n, 3) with at least ``needed_frames(top)`` frames: sub-window s = 1..``top`` of each
    (N, 33, 3) as the streaming step model reads it, computed when it arrived: row s - 1 of
    :func:`preprocess_prefixes` of the first ``needed_frames(s)`` frames. A sub-window is fixed once it is
    there (the box has run its step), so sub-window 1's first :data:`MEAN_EDGE_FRAMES` frames carry the
    capture's mean as known after ``needed_frames(1)`` frames, not the whole capture's."""
    x = np.asarray(captures, dtype=np.float32)
    if x.ndim != 3 or x.shape[2] != N_CHANNELS or not needed_frames(top) <= x.shape[1] <= CAPTURE_FRAMES:
        raise ValueError(f"captures for {top} sub-windows need {needed_frames(top)}..{CAPTURE_FRAMES} frames "
                         f"of (n, 3), got {x.shape[1:]}")
    return _prefix_inputs(x, tuple((s, needed_frames(s)) for s in range(1, top + 1)), last_only=True)


def _prefix_inputs(x: np.ndarray, prefixes: tuple[tuple[int, int], ...], last_only: bool = False) -> list[np.ndarray]:
    """(N, n, 3) float32 -> for each (steps, frames) of ``prefixes``: the first ``steps`` sub-windows
    (N, steps, 33, 3) of the captures of which only the first ``frames`` frames have arrived; with
    ``last_only``, only the last of them (N, 33, 3), its values bit for bit."""
    count = len(x)
    first, block, _ = _pair_block()
    top = max(s for s, _ in prefixes)
    _, pairs, buf_frames, _ = _prefix_layout(top)
    buf = np.zeros((count, buf_frames, N_CHANNELS))  # each capture's frames from `first` on, 0 outside
    m = min(x.shape[1], buf_frames + first)
    buf[:, -first:m - first] = x[:, :m]
    # each pair's frames, a view 231 frames further on (ndarray() makes it without as_strided's Python layers)
    windows = np.ndarray((count, pairs, block.shape[1], N_CHANNELS), buf.dtype, buf, 0,
                         (buf.strides[0], PAIR_FRAMES * buf.strides[1], *buf.strides[1:]))
    product = np.matmul(block, windows).reshape(count, -1, N_CHANNELS)
    out = []
    for steps, n in prefixes:
        _, _, frames_s, edge = _prefix_layout(steps)
        m = min(n, frames_s + first)
        # the edge-padded prefix's mean: its frames' sum (their float64 copy in a buffer of the prefix's own
        # length when it holds them all: the sum of a prefix alone) and its last frame once for every missing one
        if m == n:
            if n == x.shape[1] and frames_s == buf_frames:  # the product's buffer is this prefix's
                own = buf
            else:
                own = np.zeros((count, frames_s, N_CHANNELS))
                own[:, -first:m - first] = x[:, :m]
            mean = (_ones(frames_s) @ own + (CAPTURE_FRAMES - n) * own[:, n - 1 - first]) / CAPTURE_FRAMES
        else:
            xs = x[:, :n].astype(np.float64)
            mean = (_ones(n) @ xs + (CAPTURE_FRAMES - n) * xs[:, -1]) / CAPTURE_FRAMES
        if last_only:  # the same sums for the rows of sub-window `steps` alone
            rows = slice((steps - 1) * SUBSEQ_FRAMES, steps * SUBSEQ_FRAMES)
            out.append((product[:, rows] + edge[rows] * mean[:, None, :]).astype(np.float32))
            continue
        y = product[:, :len(edge)] + edge * mean[:, None, :]
        out.append(y.astype(np.float32).reshape(count, steps, SUBSEQ_FRAMES, N_CHANNELS))
    return out


@lru_cache(maxsize=None)
def _prefix_layout(steps: int) -> tuple[int, int, int, np.ndarray]:
    """For ``steps`` sub-windows: the frames they need, the pairs of sub-windows to compute, the frames
    of the buffer those pairs read (from :func:`_pair_block`'s first frame on) and the rows' share of
    the mean padding (steps * 33, 1)."""
    first, block, edge = _pair_block()
    pairs = (steps + 1) // 2
    return needed_frames(steps), pairs, (pairs - 1) * PAIR_FRAMES + block.shape[1], edge[:steps * SUBSEQ_FRAMES]


PAIR_ROWS = 2 * SUBSEQ_FRAMES
PAIR_FRAMES = PAIR_ROWS * DOWN // UP
"""Two sub-windows (66 resampled rows) span 231 raw frames: the resampler's weights repeat with that period."""


@lru_cache(maxsize=None)
def _ones(n: int) -> np.ndarray:
    return np.ones(n)


@lru_cache(maxsize=None)
def _pair_block() -> tuple[int, np.ndarray, np.ndarray]:
    """(the first raw frame the first pair of sub-windows reads (negative: before the capture, where
    the prefix's buffer holds zeros), the (66, W) weights every pair applies to its W frames, and
    1 - each row's sum of :func:`resample_matrix` (198, 1): the share of the mean padding)."""
    mat = resample_matrix()
    rows = N_SUBSEQ * SUBSEQ_FRAMES
    band = np.flatnonzero(mat[PAIR_ROWS:2 * PAIR_ROWS].any(axis=0))  # the second pair is clear of both edges
    first = int(band[0]) - PAIR_FRAMES
    width = int(band[-1]) + 1 - int(band[0])
    block = np.ascontiguousarray(mat[PAIR_ROWS:2 * PAIR_ROWS, band[0]:band[0] + width])
    for q in range(N_SUBSEQ // 2):  # every pair's rows are this block, shifted by q * 231 frames
        cols = np.arange(width) + first + q * PAIR_FRAMES
        inside = (cols >= 0) & (cols < mat.shape[1])
        pair = mat[q * PAIR_ROWS:(q + 1) * PAIR_ROWS]
        if not np.array_equal(pair[:, cols[inside]], block[:, inside]) or np.delete(pair, cols[inside], axis=1).any():
            raise AssertionError("the resampler's matrix does not repeat every two sub-windows")
    edge = 1.0 - mat[:rows].sum(axis=1, keepdims=True)
    for a in (block, edge):
        a.setflags(write=False)
    return first, block, edge


def calibrate(probs: np.ndarray, temperature: float) -> np.ndarray:
    """Temperature scaling of probabilities: softmax(log p / T) (T = 1: unchanged)."""
    p = np.asarray(probs, dtype=np.float64)
    if temperature == 1.0:
        return p.astype(np.float32)
    # softmax(log p / T) is p ** (1 / T) normalised: one ufunc instead of log, max, subtract and exp (the
    # replay calibrates 18,000 times a day, and these calls on K numbers cost more than their arithmetic).
    # p >= 1e-12 keeps p ** (1/T) >= 1e-240 for T >= 0.05: no underflow, so no max is needed; the float32
    # results equal those of the log/exp form on 250,000 random probability vectors at the shipped temperatures
    if p.ndim == 1:  # one decision, the loop's case: the same operations on K Python floats, without numpy's calls
        q = [min(max(v, 1e-12), 1.0) ** (1.0 / temperature) for v in p.tolist()]
        total = 0.0
        for v in q:
            total += v
        return np.array([v / total for v in q], dtype=np.float32)
    q = np.power(np.minimum(np.maximum(p, 1e-12), 1.0), 1.0 / temperature)
    return (q / np.add.reduce(q, axis=-1, keepdims=True)).astype(np.float32)


@dataclass(frozen=True)
class EarlyModel:
    """What a classifier offers for decisions before its capture is complete."""

    steps: tuple[int, ...] = (N_SUBSEQ,)
    """Sub-window counts it decides at (only (6,): the model takes whole captures, a fixed S = 6)."""
    temperature_by_steps: dict[int, float] = field(default_factory=dict)
    """Calibration temperature per S (missing: 1)."""
    min_confidence_by_steps: dict[int, float] = field(default_factory=dict)
    """The manifest's confidence threshold per S (chosen on validation data), if any."""
    chosen_on: str = ""

    @classmethod
    def of(cls, input_shape: tuple, entry: dict) -> "EarlyModel":
        """From the model's input shape (N, S, 33, 3) and its manifest entry's ``"early"`` object:
        a dynamic S means early decisions at the manifest's ``steps`` (default 1..6); a fixed S
        (today's model) means full-window decisions only, whatever the manifest says."""
        dynamic = len(input_shape) == 4 and input_shape[1] is None
        early = entry.get("early") if isinstance(entry.get("early"), dict) else {}
        if not dynamic:
            return cls()
        try:
            steps = tuple(sorted({int(s) for s in early.get("steps", range(1, N_SUBSEQ + 1))} | {N_SUBSEQ}))
            temps = {int(k): float(v) for k, v in early.get("temperature_by_steps", {}).items()}
            thresholds = {int(k): float(v) for k, v in early.get("min_confidence_by_steps", {}).items()}
        except (TypeError, ValueError, AttributeError):
            raise ModelIntegrityError(f"manifest entry {entry.get('name', '?')!r}: 'early' is malformed") from None
        if not all(1 <= s <= N_SUBSEQ for s in steps) or not all(t > 0 for t in temps.values()) \
                or not all(0.0 <= p <= 1.0 for p in thresholds.values()):
            raise ModelIntegrityError(f"manifest entry {entry.get('name', '?')!r}: 'early' steps must lie in "
                                      f"1..{N_SUBSEQ}, temperatures be positive, thresholds in [0, 1]")
        return cls(steps, temps, thresholds, str(early.get("chosen_on", "")))


INPUT_NAME = "imu"
OUTPUT_NAME = "probs"


@config.section("model")
@dataclass(frozen=True)
class ModelParams:
    """Which shipped classifier the box runs, and how."""

    assets: str = ""
    """Directory with manifest.json; empty = the models shipped inside edge_runtime (both deciders' models)."""
    name: str = config.setting("int8", ("a non-empty string", bool))
    """Capture path only. Manifest entry of the ConvLSTM: a model name, or a precision (int8, fp32). The
    streaming decider ([alerts] decision = "stream", the default) runs [stream] model instead."""
    threads: int = config.setting(1, config.AT_LEAST_1)
    """onnxruntime intra-op threads (both deciders)."""
    stream: bool = True
    """Capture path only. Decide by the ConvLSTM's step model (one run per sub-window as it arrives, the LSTM
    state kept per capture) when the manifest entry names one (``step_model``); false: run the whole model on
    the capture's prefix at every decision (sessions 8-9)."""
    manifest_public_key: str = ""
    """PEM file of the Ed25519 key the manifest must be signed with (manifest.json.sig); empty =
    the sha256 hashes only. Needs the signed-models extra."""


STEP_INPUTS, STEP_OUTPUTS = ("imu", "h", "c"), ("probs", "h_out", "c_out")
"""The step graph's inputs (sub-window, LSTM state) and outputs (decision, next state); ``export.step_model``
names its graph by these."""
STEP_AGREEMENT_TOL = 1e-3
"""Largest |probability| difference allowed at load between the one-shot model and its step model after 6
sub-windows of :func:`probe_captures`: the same checkpoint gives about 7e-7 (fp32) and 5e-7 (int8 and int8,
each quantised alone; session 10), another checkpoint a difference of the order of the probabilities themselves."""


def probe_captures() -> np.ndarray:
    """Four fixed synthetic captures (4, 700, 3) m/s^2: gravity on z, a slow swing of a few m/s^2 per axis
    (frequencies and phases from a fixed seed) and some noise. Why: a probe whose every sub-window moves,
    so that two models that are not the same checkpoint disagree on it."""
    rng = np.random.default_rng(12345)
    t_s = np.arange(CAPTURE_FRAMES)[None, :, None] / 100.0
    amp = rng.uniform(1.0, 6.0, (4, 1, N_CHANNELS))
    freq_hz = rng.uniform(0.2, 2.0, (4, 1, N_CHANNELS))
    phase = rng.uniform(0.0, 2 * np.pi, (4, 1, N_CHANNELS))
    x = amp * np.sin(2 * np.pi * freq_hz * t_s + phase) + rng.normal(0.0, 0.5, (4, CAPTURE_FRAMES, N_CHANNELS))
    x[..., 2] += 9.80665
    return x.astype(np.float32)


def zero_state(n: int, hidden: int) -> tuple[np.ndarray, np.ndarray]:
    """The LSTM state (h, c) before a capture's first sub-window: zeros (n, hidden) float32."""
    return np.zeros((n, hidden), np.float32), np.zeros((n, hidden), np.float32)


def run_steps(step: Callable[[np.ndarray, np.ndarray, np.ndarray], Sequence[np.ndarray]],
              subs: Sequence[np.ndarray], hidden: int) -> list[np.ndarray]:
    """Raw probabilities (N, K) after each of the sub-windows ``subs`` (each (N, 33, 3)), from the zero state,
    by ``step`` ((x, h, c) -> (probs, h', c'): :meth:`StepModel.step`, or the export's session run)."""
    h, c = zero_state(len(subs[0]), hidden)
    out = []
    for x in subs:
        p, h, c = step(np.ascontiguousarray(x, dtype=np.float32), h, c)
        out.append(p)
    return out


def _binding(session: ort.InferenceSession, buffers: dict[str, np.ndarray]):
    """An IOBinding of the step graph's inputs and outputs named in ``buffers`` to those float32 CPU arrays."""
    binding = session.io_binding()
    for name, a in buffers.items():
        bind = binding.bind_input if name in STEP_INPUTS else binding.bind_output
        bind(name, "cpu", 0, np.float32, list(a.shape), a.ctypes.data)
    return binding


def bound_step(session: ort.InferenceSession, feed: dict[str, np.ndarray], out_shapes: Sequence[tuple[int, ...]],
               run_options: ort.RunOptions):
    """The step model's batch-1 call ``(x, h, c) -> (probs, h', c')`` through one IOBinding made here, or None
    when this onnxruntime cannot (then the caller runs the session as usual).

    Why: most of a step's fixed cost in onnxruntime is turning the feed's arrays into its values and its
    results into new arrays on every run; here :data:`STEP_INPUTS` and :data:`STEP_OUTPUTS` are bound once
    to buffers of their batch-1 shapes (``feed``'s, ``out_shapes``), and a call copies the inputs in, runs
    and copies the outputs out (about 19 instead of 21 us a step). The binding's run is taken from under the
    public ``run_with_iobinding`` (private ``_iobinding`` and ``_sess.run_with_iobinding``: 1.32's public
    wrapper costs 30 us more), so it is used only if it gives exactly what ``session.run`` gives on ``feed``.
    The buffers are the call's: one caller at a time (the wearable loop's thread)."""
    try:
        ins = [np.zeros(np.shape(feed[k]), np.float32) for k in STEP_INPUTS]
        outs = [np.zeros(shape, np.float32) for shape in out_shapes]
        binding = _binding(session, {**dict(zip(STEP_INPUTS, ins)), **dict(zip(STEP_OUTPUTS, outs))})
        run, bound, copyto = session._sess.run_with_iobinding, binding._iobinding, np.copyto
        (x_in, h_in, c_in), (p_out, h_out, c_out) = ins, outs

        def call(x: np.ndarray, h: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
            copyto(x_in, x)  # written out, not looped: a step is 19 us and a loop over the six costs 1.5
            copyto(h_in, h)
            copyto(c_in, c)
            run(bound, run_options)
            return p_out.copy(), h_out.copy(), c_out.copy()

        call.keep = binding  # with ins and outs in the closure: the buffers onnxruntime writes live as long
        if same_arrays(call(*(feed[k] for k in STEP_INPUTS)), session.run(list(STEP_OUTPUTS), feed, run_options)):
            return call
    except Exception:  # noqa: BLE001 - a private API that changed: the caller's usual run is the contract
        pass
    return None


def chained_step(session: ort.InferenceSession, hidden: int, classes: int, run_options: ort.RunOptions):
    """A capture's batch-1 step ``(x, stream) -> probs (1, K)`` whose LSTM state stays in onnxruntime's bound buffers
    from one step of the capture to the next, or None when this onnxruntime cannot (then :func:`bound_step`).

    Why: of :func:`bound_step`'s six copies per step, four move the state (in and out); here two bindings are used in
    turn, each reading the state the other wrote (buffers ``pairs[0]`` -> ``pairs[1]`` and back), so a step of the
    capture whose state is in the buffers (the *resident* stream) copies only the sub-window in and the decision out
    (about 1 us of a 19 us step). The buffers hold one capture's state: a step of another stream first gives the
    resident one its state back as its own arrays (:meth:`StepStream` reads it through :func:`release`), then copies
    its own in. The same private calls as :func:`bound_step`; the caller checks the results at load
    (:meth:`StepModel._chain_matches`). One caller at a time, like the buffers of :func:`bound_step`."""
    try:
        x_in, p_out = np.zeros((1, SUBSEQ_FRAMES, N_CHANNELS), np.float32), np.zeros((1, classes), np.float32)
        pairs = [(np.zeros((1, hidden), np.float32), np.zeros((1, hidden), np.float32)) for _ in range(2)]
        bindings = [_binding(session, dict(zip((*STEP_INPUTS, *STEP_OUTPUTS), (x_in, *pairs[k], p_out, *pairs[1 - k]))))
                    for k in range(2)]
        run, bound, copyto = session._sess.run_with_iobinding, [b._iobinding for b in bindings], np.copyto
    except Exception:  # noqa: BLE001 - a private API that changed: the caller's usual step is the contract
        return None
    reads, resident = 0, None  # the pair the next step reads, and whose state it is

    def release(stream: StepStream) -> None:
        """The resident ``stream``'s state back into its own arrays: the buffers are about to hold another's."""
        nonlocal resident
        h, c = pairs[reads]
        stream._h, stream._c, stream._held_by = h.copy(), c.copy(), None
        resident = None

    def call(x: np.ndarray, stream: StepStream) -> np.ndarray:
        nonlocal reads, resident
        k = reads
        if resident is not stream:  # another capture's state, or none, is in the buffers: this one's goes in
            if resident is not None:
                release(resident)
            copyto(pairs[k][0], stream.h)
            copyto(pairs[k][1], stream.c)
            stream._h = stream._c = None  # in the buffers from now on: StepStream.h asks for it back
            stream._held_by = release
            resident = stream
        copyto(x_in, x)
        run(bound[k], run_options)
        reads = 1 - k
        return p_out.copy()

    call.keep = bindings  # with the buffers in the closure: what onnxruntime writes lives as long as the call
    return call


class StepModel:
    """The ConvLSTM's streaming step graph (``export.step_model``): one sub-window (N, 33, 3) m/s^2 and
    the LSTM state (h, c) (N, hidden) in, the decision's probabilities (N, K) and the next state out.
    One caller at a time: a batch-1 step writes the IOBinding's shared buffers (today only the wearable
    loop's thread steps it)."""

    def __init__(self, model: bytes, threads: int, source: str, classes: Sequence[str], entry: dict | None = None):
        self.source = source
        self.entry = entry or {}
        """Its manifest entry (name, sha256, ...), when it was loaded through one."""
        self.session = open_session(model, threads, source)
        inputs = {i.name: i.shape for i in self.session.get_inputs()}
        outputs = [o.name for o in self.session.get_outputs()]
        if set(inputs) != set(STEP_INPUTS) or not set(STEP_OUTPUTS) <= set(outputs):
            raise ModelIntegrityError(f"{source}: a step model takes {list(STEP_INPUTS)} and gives "
                                      f"{list(STEP_OUTPUTS)}; this one takes {list(inputs)}, gives {outputs}")
        hidden = inputs["h"][-1]
        if not isinstance(hidden, int) or tuple(inputs["imu"][1:]) != (SUBSEQ_FRAMES, N_CHANNELS):
            raise ModelIntegrityError(f"{source}: step inputs imu {inputs['imu']}, h {inputs['h']}: expected "
                                      f"(N, {SUBSEQ_FRAMES}, {N_CHANNELS}) and (N, hidden)")
        states = {**inputs, **{o.name: o.shape for o in self.session.get_outputs()}}
        if any(isinstance(states[k][-1], int) and states[k][-1] != hidden for k in ("c", "h_out", "c_out")):
            raise ModelIntegrityError(f"{source}: step state sizes h {inputs['h']}, c {inputs['c']}, h_out "
                                      f"{states['h_out']}, c_out {states['c_out']}: expected all (N, {hidden})")
        self.hidden = hidden
        self._run_options = ort.RunOptions()
        rng = np.random.default_rng(0)  # a probe whose every value matters: a wrong binding shows
        feed = {"imu": rng.normal(0.0, 3.0, (1, SUBSEQ_FRAMES, N_CHANNELS)).astype(np.float32),
                "h": rng.normal(0.0, 0.3, (1, hidden)).astype(np.float32),
                "c": rng.normal(0.0, 0.3, (1, hidden)).astype(np.float32)}
        try:  # a graph that onnxruntime loads but cannot run (a state it does not take) is a bad model file
            self._run = fast_run(self.session, STEP_OUTPUTS, feed, self._run_options)
            self._step_one = bound_step(self.session, feed, ((1, len(classes)), (1, hidden), (1, hidden)),
                                        self._run_options)
            """The batch-1 step through its IOBinding, None on an onnxruntime that cannot."""
            self._chain = chained_step(self.session, hidden, len(classes), self._run_options)
            """A capture's step with its state kept in the bound buffers (the loop's call), None when this
            onnxruntime cannot or it does not give exactly what ``session.run`` gives (:meth:`_chain_matches`)."""
            if self._chain is not None and not self._chain_matches(feed):
                self._chain = None
            probe = self.step(np.zeros((1, SUBSEQ_FRAMES, N_CHANNELS), np.float32), *self.zero_state(1))[0]
        except Exception as e:  # noqa: BLE001 - onnxruntime's own error types differ between versions
            first = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
            raise ModelIntegrityError(f"{source}: the step model does not run on a probe: {first}") from None
        if probe.shape != (1, len(classes)):
            raise ModelIntegrityError(f"{source}: step model has {probe.shape[-1]} outputs but {len(classes)} "
                                      "classes are listed")

    def _chain_matches(self, feed: dict[str, np.ndarray]) -> bool:
        """Whether :func:`chained_step` gives exactly what ``session.run`` gives: two captures from the probe's
        state, stepped in turn and in runs (each step of one gives the other's state back and takes its own in),
        every decision and the final states compared bit for bit."""
        x, h, c = (feed[k] for k in STEP_INPUTS)
        order = (0, 0, 1, 0, 1, 1, 0)
        want = [[h, c], [np.ascontiguousarray(h[:, ::-1]), np.ascontiguousarray(c[:, ::-1])]]
        streams = [StepStream(*(a.copy() for a in state)) for state in want]
        try:
            for k in order:
                got = self._chain(x, streams[k])
                p, want[k][0], want[k][1] = self.session.run(list(STEP_OUTPUTS), {"imu": x, "h": want[k][0],
                                                                                 "c": want[k][1]}, self._run_options)
                if not np.array_equal(got, p):
                    return False
            return all(same_arrays((st.h, st.c), ref) for st, ref in zip(streams, want))
        except Exception:  # noqa: BLE001 - a private API that changed: the public run is the contract
            return False

    def zero_state(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        return zero_state(n, self.hidden)

    @property
    def bound(self) -> bool:
        """Whether a single capture's step goes through an IOBinding (:func:`chained_step` or :func:`bound_step`)."""
        return self._chain is not None or self._step_one is not None

    @property
    def call_path(self) -> str:
        """How a capture's step reaches onnxruntime here (the <= 20 us figure holds for the IOBinding paths only)."""
        if self._chain is not None:
            return "iobinding, state kept bound"
        if self._step_one is not None:
            return "iobinding"
        return "session.run" if self._run == self.session.run else "_sess.run"

    def step_stream(self, x: np.ndarray, stream: StepStream) -> np.ndarray:
        """Raw probabilities (1, K) after sub-window x (1, 33, 3) float32 C-contiguous of the capture whose state is
        ``stream``, whose state moves on: the loop's call. With :func:`chained_step` the state stays in the bound
        buffers while the same capture steps on."""
        if self._chain is not None:
            return self._chain(x, stream)
        p, stream.h, stream.c = self.step(x, stream.h, stream.c)
        return p

    def step(self, x: np.ndarray, h: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(probs (N, K), h', c') after sub-windows x (N, 33, 3) float32 C-contiguous from the state (h, c)."""
        if len(x) == 1 and self._step_one is not None:
            return self._step_one(x, h, c)
        return tuple(self._run(STEP_OUTPUTS, {"imu": x, "h": h, "c": c}, self._run_options))

    def run(self, subs: Sequence[np.ndarray]) -> list[np.ndarray]:
        """Raw probabilities (N, K) after each of the sub-windows ``subs`` (each (N, 33, 3)), from the zero state."""
        return run_steps(self.step, subs, self.hidden)


class _HeldState:
    """A :class:`StepStream`'s ``h`` or ``c``: taken back from the step model's buffers before it is read or replaced."""

    def __set_name__(self, owner: type, name: str) -> None:
        self.attr = "_" + name

    def __get__(self, stream: "StepStream | None", owner: type | None = None):
        if stream is None:
            return self
        stream._own()
        return getattr(stream, self.attr)

    def __set__(self, stream: "StepStream", value: np.ndarray) -> None:
        stream._own()
        setattr(stream, self.attr, value)


class StepStream:
    """One capture's state in the step model: the LSTM state (h, c), the sub-windows run so far and the
    probabilities after each. While the capture steps on, its state may live in the step model's bound buffers
    (:func:`chained_step`); reading ``h`` or ``c`` then takes it back into the stream's own arrays. So a read
    changes the step model's buffers' owner: one caller at a time, readers too (as for the steps). A copy (``copy``,
    ``deepcopy``, ``pickle``) takes the state back first, so the copy and the original each hold their own arrays
    (a copy that shared the buffers' claim could later read another capture's state as its own)."""

    def __init__(self, h: np.ndarray, c: np.ndarray, done: int = 0, probs: dict[int, np.ndarray] | None = None,
                 first_frame: bytes | None = None):
        self._h, self._c = h, c
        self._held_by: Callable[[StepStream], None] | None = None
        """The release of the step model whose buffers hold this state (then ``_h`` and ``_c`` are None)."""
        self.done = done
        self.probs: dict[int, np.ndarray] = {} if probs is None else probs
        self.first_frame = first_frame
        """The bytes of the capture's first frame, as :meth:`Engine.advance` first saw it: frames whose first
        frame differs are another capture's (a guard against a caller's mix-up, not a proof of identity)."""

    h = _HeldState()
    c = _HeldState()

    def _own(self) -> None:
        if self._held_by is not None:
            self._held_by(self)

    def __getstate__(self) -> dict:
        self._own()
        return self.__dict__.copy()


def _load_step_model(assets_dir: str | os.PathLike, entry: dict, threads: int,
                     public_key_file: str | os.PathLike | None) -> StepModel:
    """The step model the classifier ``entry``'s field ``step_model`` names, hash-checked, and refused in one line
    (naming that field) unless it is a :data:`STEP_ARCH` entry of the same precision, model_version and classes
    whose graph's LSTM state has the size its manifest entry declares. Whether it decides as the one-shot model
    does is checked by :meth:`Engine._check_step_model` once both are loaded."""
    mpath = manifest_path(assets_dir)
    name = entry["step_model"]
    where = f"{mpath}: field 'step_model' of {entry['name']!r}"
    if not (isinstance(name, str) and name):
        raise ManifestError(f"{where}: expected the name of a {STEP_ARCH} entry, got {name!r}")
    named = next((e for e in load_manifest(assets_dir, public_key_file)["models"] if e["name"] == name), None)
    if named is None:
        raise ManifestError(f"{where}: names {name!r}, which is not an entry of the manifest")
    if named["arch"] != STEP_ARCH:
        raise ManifestError(f"{where}: names {name!r}, a {named['arch']} entry, not a {STEP_ARCH} one")
    for key in ("precision", "model_version", "classes"):
        if named.get(key) != entry.get(key):
            raise ModelIntegrityError(f"{where}: {name!r} has {key} {named.get(key)!r}, {entry['name']!r} has "
                                      f"{entry.get(key)!r}: not the step model of this model")
    declared = next((t["shape"][-1] for t in named["inputs"] if t["name"] == STEP_INPUTS[1] and t.get("shape")), None)
    path = mpath.parent / named["file"]
    step = StepModel(read_verified(mpath.parent, named), threads, str(path), entry["classes"], named)
    if step.hidden != declared:
        raise ModelIntegrityError(f"{path}: LSTM state size {step.hidden}, but its manifest entry {name!r} "
                                  f"(field 'inputs', {STEP_INPUTS[1]!r}) declares {declared!r}")
    return step


class Engine:
    """One ONNX classifier on onnxruntime's CPU provider."""

    def __init__(self, model: bytes | str | os.PathLike, *, classes: Sequence[str] | None = None,
                 name: str = "", precision: str = "", threads: int = 1, entry: dict | None = None,
                 source: str = "", step_model: "StepModel | None" = None):
        source = source or (str(model) if not isinstance(model, bytes) else "<model bytes>")
        self.source = source
        self.threads = threads
        self.session = open_session(model, threads, source)
        self.metadata: dict[str, str] = dict(self.session.get_modelmeta().custom_metadata_map)
        inputs = self.session.get_inputs()
        outputs = [o.name for o in self.session.get_outputs()]
        self.input_name = INPUT_NAME if any(i.name == INPUT_NAME for i in inputs) else inputs[0].name
        self.output_name = OUTPUT_NAME if OUTPUT_NAME in outputs else outputs[0]
        shape = next(i.shape for i in inputs if i.name == self.input_name)
        self.input_shape = tuple(d if isinstance(d, int) else None for d in shape)
        self._item_shape = self.input_shape[1:]
        meta_classes = self._meta_json("classes")
        if classes is None:
            classes = meta_classes
        if classes is None:
            raise ModelIntegrityError(f"{source}: no class list (neither manifest nor ONNX metadata 'classes')")
        self.classes: list[str] = [str(c) for c in classes]
        if meta_classes is not None and list(meta_classes) != self.classes:
            raise ModelIntegrityError(f"{source}: manifest classes {self.classes} differ from the model's "
                                      f"metadata {meta_classes}")
        self.name = name or self.metadata.get("arch", Path(source).stem)
        self.precision = precision or self.metadata.get("precision", "")
        self.entry = entry or {}
        self._run = self.session.run
        self._outputs = [self.output_name]
        self._run_options = ort.RunOptions()
        self.early = EarlyModel.of(self.input_shape, self.entry)
        self.step_model = step_model
        """The streaming step model the decisions come from (None: the whole model on each prefix)."""
        item = tuple(N_SUBSEQ if d is None and k == 0 and len(self._item_shape) == 3 else d
                     for k, d in enumerate(self._item_shape))
        probe = self.classify(np.zeros(item, np.float32)) if None not in item else None
        if probe is not None and probe.shape != (len(self.classes),):
            raise ModelIntegrityError(f"{source}: model has {probe.shape[-1]} outputs but "
                                      f"{len(self.classes)} classes are listed")
        if step_model is not None:
            self._check_step_model()

    def _check_step_model(self) -> None:
        """Refuse a step model that does not decide as this model does: after 6 sub-windows of
        :func:`probe_captures` (the same inputs to both) their probabilities must agree within
        :data:`STEP_AGREEMENT_TOL`. Why: hashes prove the files are the manifest's, not that the step graph
        was exported from the same checkpoint as the one-shot model whose thresholds and temperatures apply."""
        x = preprocess(probe_captures())
        one_shot = self._model_probs(x, N_SUBSEQ)
        stepped = self.step_model.run([x[:, s] for s in range(N_SUBSEQ)])[-1]
        diff = float(np.abs(one_shot - stepped).max())
        if not diff <= STEP_AGREEMENT_TOL:
            raise ModelIntegrityError(f"{self.step_model.source}: its decisions after {N_SUBSEQ} sub-windows of a "
                                      f"fixed probe differ from {self.source}'s by {diff:.3g} (> {STEP_AGREEMENT_TOL:g}): "
                                      "not the step model of the same trained model")

    # ------------------------------------------------------------------ construction

    @classmethod
    def from_manifest(cls, assets_dir: str | os.PathLike = ASSETS_DIR, name_or_precision: str = "int8",
                      threads: int = 1, arch: str | tuple[str, ...] | None = CLASSIFIER_ARCHS,
                      public_key_file: str | os.PathLike | None = None, stream: bool = True) -> "Engine":
        """The manifest entry named ``name_or_precision`` (or the first of that precision)
        among the ``arch`` entries (default: the classifiers; None: any), hash-checked (and the
        manifest signature-checked with ``public_key_file``), on onnxruntime with ``threads``
        intra-op threads; with ``stream``, also the step model its ``step_model`` field names (hash-checked
        the same way), which then makes every decision after S sub-windows."""
        entry, data, path = load_verified(assets_dir, name_or_precision, arch=arch, public_key_file=public_key_file)
        step = _load_step_model(assets_dir, entry, threads, public_key_file) if stream and "step_model" in entry \
            else None
        return cls(data, classes=entry["classes"], name=entry["name"], precision=entry["precision"],
                   threads=threads, entry=entry, source=str(path), step_model=step)

    @classmethod
    def from_params(cls, params: ModelParams, name_or_precision: str | None = None) -> "Engine":
        """The engine a box's ``[model]`` section describes (assets, name, threads, signing key, stream), or
        another entry of the same assets with ``name_or_precision``: one place that reads those settings."""
        return cls.from_manifest(params.assets or ASSETS_DIR, name_or_precision or params.name, threads=params.threads,
                                 public_key_file=params.manifest_public_key or None, stream=params.stream)

    @classmethod
    def from_file(cls, path: str | os.PathLike, threads: int = 1, classes: Sequence[str] | None = None
                  ) -> "Engine":
        """An ONNX file without a manifest (no hash check); classes from its metadata."""
        p = Path(path)
        if not p.is_file():
            raise ModelIntegrityError(f"{p}: model file not found")
        return cls(p, classes=classes, threads=threads, source=str(p))

    # ------------------------------------------------------------------ inference

    def classify(self, x: np.ndarray) -> np.ndarray:
        """Class probabilities for model input(s) in m/s^2: (6, 33, 3) -> (K,), (N, 6, 33, 3) -> (N, K)."""
        a = x if type(x) is np.ndarray and x.dtype == np.float32 else np.asarray(x, dtype=np.float32)
        single = a.ndim == len(self._item_shape)
        if single:
            a = a[None]
        if a.ndim != len(self.input_shape) or (a.shape[1:] != self._item_shape and any(
                want is not None and got != want for got, want in zip(a.shape[1:], self._item_shape))):
            raise ValueError(f"{self.name}: input shape {np.shape(x)}, expected "
                             f"{tuple(d or 'N' for d in self._item_shape)} or (N, ...) of it")
        self._finite(a)
        if a.shape[0] == 0:
            return np.zeros((0, len(self.classes)), np.float32)
        if not a.flags.c_contiguous:
            a = np.ascontiguousarray(a)
        out = self._run(self._outputs, {self.input_name: a}, self._run_options)[0]
        return out[0] if single else out

    __call__ = classify

    def classify_capture(self, x700: np.ndarray) -> np.ndarray:
        """Probabilities for detector capture(s) (700, 3) or (N, 700, 3), m/s^2 at 100 Hz."""
        return self.classify(preprocess(np.asarray(x700, dtype=np.float32)))

    @property
    def early_steps(self) -> tuple[int, ...]:
        """The sub-window counts S this model decides at ((6,): full-window decisions only)."""
        return self.early.steps

    @property
    def streaming(self) -> bool:
        """Whether decisions come from the step model (one run per sub-window)."""
        return self.step_model is not None

    def new_stream(self) -> StepStream:
        """The state of a new capture for :meth:`advance` (requires a step model)."""
        return StepStream(*self.step_model.zero_state(1))

    def advance(self, stream: StepStream, data: np.ndarray, steps: int) -> np.ndarray:
        """Calibrated probabilities (K,) after ``steps`` sub-windows of one capture whose frames so far are
        ``data`` (at least ``needed_frames(steps)``): runs the step model once for each sub-window the
        capture's ``stream`` has not yet seen, sub-window s computed from the first ``needed_frames(s)``
        frames (:func:`step_inputs`), and keeps the state in ``stream``. Equal to :meth:`classify_prefix`
        of the same frames, since both read each sub-window as it arrived. Refused (ValueError, one line) before
        the state is touched: fewer than ``needed_frames(steps)`` frames, or frames whose first frame is not the
        one this stream was first advanced with (another capture's: a stream holds one capture)."""
        self._check_steps(steps)
        x = np.asarray(data, dtype=np.float32)
        need = needed_frames(steps)
        if x.ndim != 2 or x.shape[1] != N_CHANNELS or not need <= len(x) <= CAPTURE_FRAMES:
            raise ValueError(f"{self.name}: a decision after {steps} sub-windows needs {need}..{CAPTURE_FRAMES} "
                             f"frames of (n, {N_CHANNELS}), got {x.shape}")
        first = x[0].tobytes()  # bytes: NaN compares equal to itself here
        if stream.first_frame is None:
            stream.first_frame = first
        elif first != stream.first_frame:
            raise ValueError(f"{self.name}: these frames are not the capture this stream was advanced with "
                             "(its first frame differs): a stream holds one capture's state")
        for s in range(stream.done + 1, steps + 1):
            sub = _prefix_inputs(x[None, :needed_frames(s)], ((s, needed_frames(s)),), last_only=True)[0]
            self._finite(sub)
            stream.probs[s] = self.step_model.step_stream(sub, stream)[0]
            stream.done = s
        return calibrate(stream.probs[steps], self._temperature(steps))

    def classify_prefix(self, x_prefix: np.ndarray, steps: int) -> np.ndarray:
        """Calibrated probabilities (K,) after ``steps`` sub-windows, from the capture's first
        ``needed_frames(steps)`` frames or more (:func:`preprocess_prefix`); the model's decision after
        S sub-windows, temperature-scaled by the manifest's ``temperature_by_steps`` when given.
        ``steps`` = 6 on a whole capture is :meth:`classify_capture`."""
        return calibrate(self._prefix_probs(np.asarray(x_prefix)[None], steps)[0], self._temperature(steps))

    def classify_prefixes(self, x_prefixes: np.ndarray, steps: int) -> np.ndarray:
        """:meth:`classify_prefix` of N prefixes of one length (N, n, 3) at once -> (N, K), in one model run.
        Each row is what :meth:`classify_prefix` gives for its prefix alone (onnxruntime computes each
        item of a batch as it computes it alone: ``tests/wearable/test_classifier.py`` holds it to that)."""
        return calibrate(self._prefix_probs(np.asarray(x_prefixes), steps), self._temperature(steps))

    def classify_capture_groups(self, groups: Sequence[tuple[np.ndarray, Sequence[int]]]) -> list[dict[int, np.ndarray]]:
        """For each group (captures (N, n, 3), sub-window counts): {S: :meth:`classify_prefixes` of the
        captures' first ``needed_frames(S)`` frames}, with one model run per S for every group that
        asks for it and the preprocessing of each group's steps shared (:func:`preprocess_prefix_steps`).
        A replay's loop asks this for the captures a block completes. With a step model, every capture's
        sub-windows 1..max(its S) go through it, one run per sub-window for every group that reaches it."""
        if self.step_model is not None:
            return self._step_groups(groups)
        inputs = [dict(zip(steps, preprocess_prefix_steps(captures, steps))) for captures, steps in groups]
        out: list[dict[int, np.ndarray]] = [{} for _ in groups]
        for steps in sorted({s for g in inputs for s in g}):
            asking = [k for k, g in enumerate(inputs) if steps in g]
            a = inputs[asking[0]][steps] if len(asking) == 1 else np.concatenate([inputs[k][steps] for k in asking])
            probs = calibrate(self._model_probs(a, steps), self._temperature(steps))
            start = 0
            for k in asking:
                count = len(inputs[k][steps])
                out[k][steps] = probs[start:start + count]
                start += count
        return out

    def _step_groups(self, groups: Sequence[tuple[np.ndarray, Sequence[int]]]) -> list[dict[int, np.ndarray]]:
        """:meth:`classify_capture_groups` by the step model: the state of each group's captures carried
        from sub-window to sub-window, the groups that reach sub-window s run together in one step. The
        groups go in order of their last step, so those that reach s are the first rows of the state."""
        for _, steps in groups:
            for s in steps:
                self._check_steps(s)
        order = sorted(range(len(groups)), key=lambda k: -max(groups[k][1]))
        tops = [max(groups[k][1]) for k in order]
        subs = [step_inputs(groups[k][0], top) for k, top in zip(order, tops)]
        h, c = self.step_model.zero_state(sum(len(groups[k][0]) for k in order))
        out: list[dict[int, np.ndarray]] = [{} for _ in groups]
        for s in range(1, tops[0] + 1):
            reach = sum(top >= s for top in tops)
            x = subs[0][s - 1] if reach == 1 else np.concatenate([subs[j][s - 1] for j in range(reach)])
            self._finite(x)
            probs, h, c = self.step_model.step(x, h[:len(x)], c[:len(x)])
            start = 0
            for j in range(reach):
                k, count = order[j], len(subs[j][s - 1])
                if s in groups[k][1]:
                    out[k][s] = calibrate(probs[start:start + count], self._temperature(s))
                start += count
        return out

    def _check_steps(self, steps: int) -> None:
        """S = 6 (the whole capture: needed_frames(6) = 700) is every model's; others, the manifest's."""
        if steps not in self.early.steps and steps != N_SUBSEQ:
            raise ValueError(f"{self.name}: decides after {list(self.early.steps)} sub-windows, not {steps}")

    def _finite(self, a: np.ndarray) -> None:
        """ValueError unless every value of a model input is finite (onnxruntime would pass NaN through)."""
        if not np.isfinite(a).all():
            raise ValueError(f"{self.name}: input holds NaN or infinite values")

    def _temperature(self, steps: int) -> float:
        return self.early.temperature_by_steps.get(steps, 1.0)

    def _prefix_probs(self, x_prefixes: np.ndarray, steps: int) -> np.ndarray:
        """The model's raw probabilities (N, K) for prefixes (N, n, 3) after ``steps`` sub-windows: the step
        model's after running sub-windows 1..``steps``, or the whole model's on the prefix."""
        if self.step_model is not None:
            self._check_steps(steps)
            subs = step_inputs(np.asarray(x_prefixes, dtype=np.float32), steps)
            for x in subs:
                self._finite(x)
            return self.step_model.run(subs)[-1]
        return self._model_probs(preprocess_prefixes(x_prefixes, steps), steps)

    def _model_probs(self, a: np.ndarray, steps: int) -> np.ndarray:
        """The model's raw probabilities (N, K) for its inputs (N, steps, 33, 3), C-contiguous float32."""
        self._check_steps(steps)
        self._finite(a)
        # the checks of classify() hold by construction here; the loop asks this 18,000 times a day
        return self._run(self._outputs, {self.input_name: a}, self._run_options)[0]

    def predict(self, x: np.ndarray) -> list[str] | str:
        """Top class name(s) for model input(s)."""
        p = self.classify(x)
        if p.ndim == 1:
            return self.classes[int(p.argmax())]
        return [self.classes[i] for i in p.argmax(axis=1)]

    # ------------------------------------------------------------------ description

    def _meta_json(self, key: str):
        raw = self.metadata.get(key)
        if raw is None:
            return None
        try:
            return json.loads(raw)
        except json.JSONDecodeError:
            raise ModelIntegrityError(f"{self.source}: ONNX metadata {key!r} is not valid JSON") from None

    def decision_path(self) -> dict:
        """What makes the decisions, for a report's provenance: this model's manifest name and sha256, and the
        step model's when decisions come from it (None: the whole model on each prefix)."""
        step = self.step_model
        return {"model": self.name, "sha256": self.entry.get("sha256"),
                "step_model": None if step is None else step.entry.get("name", step.source),
                "step_model_sha256": None if step is None else step.entry.get("sha256")}

    def describe(self) -> dict:
        return {"name": self.name, "precision": self.precision, "source": self.source,
                "step_model": self.step_model.source if self.step_model is not None else None,
                "step_call": self.step_model.call_path if self.step_model is not None else None,
                "threads": self.threads, "classes": self.classes, "input": self.input_name,
                "input_shape": ["N" if d is None else d for d in self.input_shape],
                "output": self.output_name, "metadata": self.metadata}

    def __repr__(self) -> str:
        return f"Engine({self.name!r}, precision={self.precision!r}, threads={self.threads})"
