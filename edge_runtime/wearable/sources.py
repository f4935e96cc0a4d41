"""IMU data providers: where samples come from before the detector sees them.

A provider yields :class:`ImuBlock` objects: consecutive 100 Hz samples (m/s^2)
with the stream time of the first one. A break in continuity (a gap, samples
that were dropped) starts a new block with ``continuous=False`` so that the
loop resets the detector there.

This module has the recording provider (``--replay FILE.csv``); live sources
(MAVLink over a serial line, the in-process simulator) plug in beside it.
"""
from __future__ import annotations

import io
import math
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path

import numpy as np

from edge_runtime import config
from edge_runtime.errors import InputError
from edge_runtime.wearable.classifier import resample_poly

SAMPLE_RATE_HZ = 100
CSV_HEADER = ("t", "ax", "ay", "az")
MAX_GAP_PERIODS = 1.5
"""A step between timestamps longer than this many sample periods is a gap."""


@config.section("imu")
@dataclass(frozen=True)
class ImuParams:
    """The wrist IMU the box reads."""

    sample_rate_hz: int = config.setting(SAMPLE_RATE_HZ, ("100 (the rate the shipped classifier was trained at)",
                                                          lambda v: v == SAMPLE_RATE_HZ))
    """Rate the detector and model expect; recordings at other rates are resampled to it."""
    range_mps2: float = config.setting(156.9, config.within(19.6, 1000, "m/s^2"))
    """Accelerometer full scale (m/s^2, 16 g); readings at or beyond it count as saturated and
    are clipped to it before the model sees them."""
    silence_timeout_s: float = config.setting(0.15, config.within(0.02, 0.15, "s"))
    """No sample for this long: the sensor is silent. WEARABLE_STATUS says so at once (an
    extra heartbeat on every change of state), so within 200 ms of the last sample: the
    source looks every 50 ms, hence at most 0.15 s (and at least two sample periods)."""


@dataclass
class ImuBlock:
    t0_s: float
    """Stream time of the first sample (s)."""
    acc_mps2: np.ndarray
    """(n, 3) float32, specific force in the sensor frame, m/s^2, 100 Hz."""
    continuous: bool = True
    """False when this block does not follow the previous one without a gap."""
    rx_monotonic_s: float | None = None
    """Host ``time.monotonic()`` when the block's last sample arrived (live sources; None for a
    file). The loop carries it to the decision so alert latency is measured from arrival."""


@dataclass
class ReplayStats:
    rows: int = 0
    dropped_non_monotonic: int = 0
    gaps: int = 0
    source_rate_hz: float = SAMPLE_RATE_HZ
    notices: list[str] = field(default_factory=list)


def _load_csv(path: Path) -> np.ndarray:
    try:
        text = path.read_text()
    except OSError as e:
        raise InputError(f"{path}: cannot read ({e.strerror or e})") from None
    lines = text.splitlines()
    if not lines:
        raise InputError(f"{path}: empty file; expected the header 't,ax,ay,az'")
    header = tuple(c.strip() for c in lines[0].split(","))
    if header != CSV_HEADER:
        raise InputError(f"{path}:1: header is {','.join(header)!s}; expected 't,ax,ay,az'")
    try:
        data = np.loadtxt(io.StringIO(text), delimiter=",", skiprows=1, ndmin=2, dtype=np.float64)
    except ValueError:
        data = None
    if data is None or data.shape[1:] != (4,):
        for no, line in enumerate(lines[1:], start=2):  # find the offending line
            cells = line.split(",")
            if not line.strip():
                raise InputError(f"{path}:{no}: empty line")
            if len(cells) != 4:
                raise InputError(f"{path}:{no}: expected 4 fields t,ax,ay,az, got {len(cells)}")
            for name, cell in zip(CSV_HEADER, cells):
                try:
                    float(cell)
                except ValueError:
                    raise InputError(f"{path}:{no}: field {name!r} is not a number: {cell.strip()!r}") from None
        raise InputError(f"{path}: unreadable CSV")
    if len(data) == 0:
        raise InputError(f"{path}: no samples after the header")
    bad_t = np.flatnonzero(~np.isfinite(data[:, 0]))
    if bad_t.size:
        raise InputError(f"{path}:{bad_t[0] + 2}: field 't' is not a finite time")
    return data


def _rate_ratio(rate_hz: float) -> Fraction:
    return Fraction(SAMPLE_RATE_HZ / rate_hz).limit_denominator(50)


def read_imu_csv(path: str | Path, stats: ReplayStats | None = None) -> list[ImuBlock]:
    """A recording ``t,ax,ay,az`` (s, m/s^2) as continuous 100 Hz blocks.

    Out-of-order or duplicate timestamps are dropped and counted; a step of more
    than 1.5 periods starts a new block; a recording at another constant rate is
    resampled to 100 Hz with a notice. NaN/inf samples are passed on: the loop
    counts them and resets the detector around them.
    """
    path = Path(path)
    stats = stats if stats is not None else ReplayStats()
    data = _load_csv(path)
    stats.rows = len(data)
    t = data[:, 0]
    keep = np.ones(len(t), bool)
    if len(t) > 1:  # drop samples that do not advance time
        running_max = np.maximum.accumulate(t)
        keep[1:] = t[1:] > running_max[:-1]
    stats.dropped_non_monotonic = int((~keep).sum())
    if stats.dropped_non_monotonic:
        stats.notices.append(f"{path}: dropped {stats.dropped_non_monotonic} samples whose time did not advance")
    t, acc = t[keep], data[keep, 1:]
    if len(t) < 2:
        return [ImuBlock(float(t[0]), acc.astype(np.float32), True)]
    dt = np.diff(t)
    period = float(np.median(dt))
    rate = 1.0 / period
    ratio = Fraction(1)
    if abs(rate - SAMPLE_RATE_HZ) > 0.01 * SAMPLE_RATE_HZ:
        ratio = _rate_ratio(rate)
        if ratio.numerator > 50 or math.isclose(float(ratio), 0.0):
            raise InputError(f"{path}: sample rate {rate:.3g} Hz cannot be resampled to {SAMPLE_RATE_HZ} Hz")
        stats.notices.append(f"{path}: recorded at {rate:.4g} Hz; resampled to {SAMPLE_RATE_HZ} Hz (polyphase {ratio.numerator}/{ratio.denominator})")
    stats.source_rate_hz = rate
    breaks = np.flatnonzero(dt > MAX_GAP_PERIODS * period) + 1
    stats.gaps = int(breaks.size)
    if breaks.size:
        stats.notices.append(f"{path}: {breaks.size} gap(s) in time; the detector restarts after each")
    blocks = []
    for k, (a, b) in enumerate(zip([0, *breaks], [*breaks, len(t)])):
        seg = acc[a:b]
        if ratio != 1:
            seg = _resample_segment(seg, ratio)
        blocks.append(ImuBlock(float(t[a]), seg.astype(np.float32), continuous=(k == 0)))
    return blocks


def _resample_segment(seg: np.ndarray, ratio: Fraction) -> np.ndarray:
    finite = np.isfinite(seg).all(axis=1)
    if finite.all():
        return resample_poly(seg, ratio.numerator, ratio.denominator)
    # Resampling would smear a NaN across the filter length: fill for the filter,
    # then mark the output samples that came from non-finite input as NaN again.
    filled = np.where(np.isfinite(seg), seg, np.nanmean(np.where(np.isfinite(seg), seg, np.nan), axis=0))
    out = resample_poly(np.nan_to_num(filled), ratio.numerator, ratio.denominator)
    src = np.minimum((np.arange(len(out)) * ratio.denominator) // ratio.numerator, len(seg) - 1)
    out[~finite[src]] = np.nan
    return out
