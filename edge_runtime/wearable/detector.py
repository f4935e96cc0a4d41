"""The dissertation's hand-motion detector (section 2.2.2), numpy only.

At every frame T the detector compares the newest and the oldest frame of a
200-frame (2 s) window on the wrist's x axis:

    P3[T] = |ax[T] - ax[T - 199]|

and triggers when P3 exceeds the threshold (5 m/s^2). A trigger at T captures
frames T-100 ... T+599 (700 frames: 1 s before, 6 s after) for the classifier
and pauses the detector until the capture ends: the next trigger can come at
T+600 at the earliest.

Two implementations with one meaning:

* :func:`detect_triggers` scans a whole recording at once (the reference);
* :class:`StreamingDetector` is fed samples one by one or in blocks of any
  size, as a firmware loop would, and gives exactly the same triggers and
  captures (``tests/wearable/test_detector.py`` checks this over random block splits).

Sample indices are absolute: frame 0 is the first sample since the stream
started. :meth:`StreamingDetector.reset` marks a loss of continuity (a gap,
NaNs): the window must fill again before the next trigger.
"""
from __future__ import annotations

from array import array
from dataclasses import dataclass

import numpy as np

from edge_runtime import config


@config.section("detector")
@dataclass(frozen=True)
class DetectorConfig:
    """The capture path's hand-motion detector (dissertation 2.3.1) and capture; decision "stream" reads none of it.

    [alerts] decision = "early" or "full_window" reads this section; "stream" (the default) has no detector (a gap or
    bad samples restart its stream, which the status counts as detector restarts)."""

    threshold_mps2: float = config.setting(5.0, config.POSITIVE)
    """Trigger when |ax[T] - ax[T - window + 1]| exceeds this (m/s^2)."""
    window_frames: int = config.setting(200, ("an integer of at least 2", lambda v: v >= 2))
    """Length of the sliding window; P3 spans window_frames - 1 samples."""
    # A box's captures are the ConvLSTM's input (700 frames, sub-windows timed from the trigger), so
    # its file may not move them; other lengths are for studying the detector alone (this class).
    pre_frames: int = config.setting(100, ("100 (the model's capture starts 1 s before the trigger)",
                                           lambda v: v == 100))
    """Frames captured before the trigger frame."""
    post_frames: int = config.setting(600, ("600 (the model's capture runs 6 s from the trigger)",
                                            lambda v: v == 600))
    """Frames captured from the trigger frame on (T ... T+599)."""
    axis: int = config.setting(0, ("0, 1 or 2", lambda v: v in (0, 1, 2)))
    """Accelerometer axis watched (0 = x, roughly perpendicular to the wheel axis)."""

    @property
    def capture_frames(self) -> int:
        return self.pre_frames + self.post_frames

    @property
    def lag(self) -> int:
        return self.window_frames - 1

    def __post_init__(self) -> None:
        if self.window_frames < 2:
            raise ValueError("window_frames must be at least 2")
        if not self.threshold_mps2 > 0:
            raise ValueError("threshold_mps2 must be positive")
        if not 0 <= self.pre_frames <= self.window_frames - 1:
            raise ValueError(f"[detector] pre_frames: must be below window_frames ({self.window_frames})")
        if self.post_frames < 1:
            raise ValueError("post_frames must be at least 1")


@dataclass(frozen=True)
class Capture:
    """One detector capture: frames ``start_index ... start_index + 699``."""

    trigger_index: int
    start_index: int
    data: np.ndarray  # (capture_frames, 3) float32, m/s^2


def p3_series(ax: np.ndarray, cfg: DetectorConfig = DetectorConfig()) -> np.ndarray:
    """P3[T] for every frame (NaN for the first window_frames-1 frames)."""
    ax = np.asarray(ax, dtype=np.float64)
    out = np.full(ax.shape, np.nan)
    if ax.size > cfg.lag:
        out[cfg.lag :] = np.abs(ax[cfg.lag :] - ax[: ax.size - cfg.lag])
    return out


def _greedy_triggers(candidates: np.ndarray, first_allowed: int, post: int) -> list[int]:
    """Take candidates in order, each pausing the detector for ``post`` frames."""
    out: list[int] = []
    allowed = first_allowed
    pos = int(np.searchsorted(candidates, allowed))
    while pos < candidates.size:
        t = int(candidates[pos])
        out.append(t)
        allowed = t + post
        pos = int(np.searchsorted(candidates, allowed, side="left"))
    return out


def detect_triggers(x: np.ndarray, cfg: DetectorConfig = DetectorConfig()) -> np.ndarray:
    """Trigger frames of a whole recording. ``x`` is (n, 3) or the watched axis (n,)."""
    x = np.asarray(x)
    ax = x[:, cfg.axis] if x.ndim == 2 else x
    with np.errstate(invalid="ignore"):
        candidates = np.flatnonzero(p3_series(ax, cfg) > cfg.threshold_mps2)
    return np.asarray(_greedy_triggers(candidates, cfg.lag, cfg.post_frames), dtype=np.int64)


def extract_captures(x: np.ndarray, triggers: np.ndarray, cfg: DetectorConfig = DetectorConfig()) -> list[Capture]:
    """The complete capture windows of ``triggers`` in recording ``x`` (n, 3)."""
    x = np.asarray(x, dtype=np.float32)
    caps = []
    for t in np.asarray(triggers, dtype=np.int64):
        lo, hi = int(t) - cfg.pre_frames, int(t) + cfg.post_frames
        if lo >= 0 and hi <= len(x):
            caps.append(Capture(int(t), lo, x[lo:hi].copy()))
    return caps


_ROOM_FRAMES = 4096
"""Free rows of the detector's buffer before it is compacted (one copy of the window per this many samples)."""


class StreamingDetector:
    """Sample-by-sample (or block) version of :func:`detect_triggers`.

    ``push(block)`` takes an (n, 3) block of m/s^2 samples and returns the
    captures that completed inside it; ``triggers`` lists every trigger so
    far, including one whose capture is still filling (:attr:`filling`).

    Per sample it costs a copy into a preallocated buffer and, while the detector
    is not paused by a capture, one subtraction: the 100 Hz loop feeds one sample
    at a time, so nothing proportional to the window may happen per call (the buffer
    is compacted once every ``_ROOM_FRAMES`` samples, and a capture fills its own
    preallocated array).
    """

    def __init__(self, cfg: DetectorConfig = DetectorConfig()):
        self.cfg = cfg
        self.n_seen = 0
        self.triggers: list[int] = []
        self._keep = max(cfg.lag, cfg.pre_frames)  # history a new sample may need
        self._lag, self._thr, self._axis = cfg.lag, cfg.threshold_mps2, cfg.axis  # read per sample
        self._alloc(self._keep + _ROOM_FRAMES)
        self._len = 0  # rows of _buf in use: frames n_seen - _len ... n_seen - 1, none before _valid_from
        self._valid_from = 0  # first sample of the current continuous stretch
        self._allowed_from = cfg.lag  # earliest frame that may trigger
        self._cap_a = array("f", bytes(4 * 3 * cfg.capture_frames))
        self._cap = np.frombuffer(self._cap_a, np.float32).reshape(-1, 3)
        self._cap_trigger: int | None = None  # the capture filling, if any ...
        self._cap_have = 0  # ... and its frames so far

    def _alloc(self, rows: int) -> None:
        """The history buffers for ``rows`` frames: Python arrays that :meth:`push_sample` writes one
        float at a time (no numpy call per sample: in a 100 Hz loop each costs microseconds on cold
        caches), and numpy views of the same memory for blocks."""
        self._rows = rows  # len(self._buf), without a numpy call per sample
        self._buf_a = array("f", bytes(4 * 3 * rows))
        self._ax_a = array("d", bytes(8 * rows))
        self._buf = np.frombuffer(self._buf_a, np.float32).reshape(rows, 3)
        self._ax = np.frombuffer(self._ax_a, np.float64)  # the watched axis, as detect_triggers compares it

    @property
    def capturing(self) -> bool:
        return self._cap_trigger is not None

    @property
    def filled(self) -> int:
        """Frames of the capture being filled so far (0: none)."""
        return self._cap_have if self._cap_trigger is not None else 0

    @property
    def filling(self) -> tuple[int, np.ndarray] | None:
        """The capture being filled: (trigger frame, its frames so far, a read-only view valid until
        the next :meth:`push`), or None."""
        if self._cap_trigger is None:
            return None
        view = self._cap[: self._cap_have]
        view.flags.writeable = False
        return self._cap_trigger, view

    def reset(self) -> None:
        """Continuity lost: drop the window and any capture in progress."""
        self._len = 0
        self._cap_trigger = None
        self._valid_from = self.n_seen
        self._allowed_from = self.n_seen + self.cfg.lag

    def skip(self, n: int) -> None:
        """``n`` unusable samples (NaN, inf): count them in the stream index and reset."""
        self.n_seen += int(n)
        self.reset()

    def _append(self, block: np.ndarray) -> None:
        n = len(block)
        if self._len + n > len(self._buf):  # compact: keep the window's history, make room
            keep = min(self._len, self._keep)
            rows, ax = self._buf[self._len - keep : self._len], self._ax[self._len - keep : self._len]
            rows, ax = rows.copy(), ax.copy()  # the slices may overlap the target, or go with the old buffer
            if keep + n > len(self._buf):  # a block longer than the room: a buffer that holds it
                self._alloc(self._keep + max(n, _ROOM_FRAMES))
            self._buf[:keep], self._ax[:keep] = rows, ax
            self._len = keep
        if n == 1:  # the live 100 Hz loop: item assignments, no slicing
            self._buf[self._len] = block[0]
            self._ax[self._len] = block[0, self._axis]
        else:
            self._buf[self._len : self._len + n] = block
            self._ax[self._len : self._len + n] = block[:, self._axis]
        self._len += n

    def push_sample(self, x: float, y: float, z: float) -> Capture | None:
        """:meth:`push` of one finite sample given as three floats, the 100 Hz loop's call: the same
        triggers and captures, written into the buffers element by element (the capture it
        completes, if any)."""
        if self._len == self._rows:
            self._append(np.array([[x, y, z]], np.float32))  # compaction: rare, the block path does it
        else:
            i = self._len
            buf = self._buf_a
            buf[3 * i], buf[3 * i + 1], buf[3 * i + 2] = x, y, z
            self._ax_a[i] = buf[3 * i + self._axis]  # the float32 value, as push compares it
            self._len = i + 1
        t = self.n_seen
        end = self.n_seen = t + 1
        s0 = end - self._len
        if self._cap_trigger is not None:  # one more frame of the capture filling (it cannot trigger)
            return self._fill_one(s0)
        lag = self._lag
        if t >= self._valid_from + lag and t >= self._allowed_from:
            j = t - s0
            if abs(self._ax_a[j] - self._ax_a[j - lag]) > self._thr:
                self.triggers.append(t)
                self._allowed_from = t + self.cfg.post_frames
                self._cap_trigger, self._cap_have = t, 0
                done = self._fill(s0, end)
                return done[0] if done else None
        return None

    def _fill_one(self, s0: int) -> Capture | None:
        have = self._cap_have
        r = 3 * (self._cap_trigger - self.cfg.pre_frames + have - s0)
        self._cap_a[3 * have : 3 * have + 3] = self._buf_a[r : r + 3]
        self._cap_have = have = have + 1
        if have < self.cfg.capture_frames:
            return None
        t, self._cap_trigger = self._cap_trigger, None
        return Capture(t, t - self.cfg.pre_frames, self._cap.copy())

    def push(self, block: np.ndarray) -> list[Capture]:
        if type(block) is not np.ndarray or block.dtype != np.float32 or block.ndim != 2:
            block = np.asarray(block, dtype=np.float32).reshape(-1, 3)
        n = len(block)
        if n == 0:
            return []
        self._append(block)
        end = self.n_seen + n
        s0 = end - self._len  # absolute index of _buf[0]
        done: list[Capture] = []
        if self._cap_trigger is not None:  # finish a capture that was already filling
            done += self._fill(s0, end)
        # Candidates T in this block with a full window behind them, not inside a capture's pause.
        lag = self._lag
        t_first = max(self.n_seen, self._valid_from + lag, self._allowed_from)
        if t_first < end:
            if end - t_first == 1:  # the 100 Hz loop: one sample, no array temporaries
                j = t_first - s0
                hit = abs(float(self._ax[j]) - float(self._ax[j - lag])) > self._thr
                candidates = [t_first] if hit else []
            else:
                a = self._ax[t_first - s0 : self._len]
                b = self._ax[t_first - s0 - lag : self._len - lag]
                with np.errstate(invalid="ignore"):
                    candidates = np.flatnonzero(np.abs(a - b) > self._thr) + t_first
            post = self.cfg.post_frames
            for t in _greedy_triggers(np.asarray(candidates, dtype=np.int64), self._allowed_from, post
                                      ) if len(candidates) else ():
                self.triggers.append(t)
                self._allowed_from = t + post
                self._cap_trigger, self._cap_have = t, 0
                done += self._fill(s0, end)
        self.n_seen = end
        return done

    def _fill(self, s0: int, end: int) -> list[Capture]:
        t, have = self._cap_trigger, self._cap_have
        start = t - self.cfg.pre_frames + have  # next absolute frame the capture needs
        stop = min(t + self.cfg.post_frames, end)
        if stop - start == 1:  # the 100 Hz loop: one more frame
            self._cap[have] = self._buf[start - s0]
            self._cap_have = have = have + 1
        elif stop > start:
            self._cap[have : have + stop - start] = self._buf[start - s0 : stop - s0]
            self._cap_have = have = have + stop - start
        if have < self.cfg.capture_frames:
            return []
        self._cap_trigger = None
        return [Capture(t, t - self.cfg.pre_frames, self._cap.copy())]
