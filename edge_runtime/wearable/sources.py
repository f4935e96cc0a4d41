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
from itertools import chain
from pathlib import Path
from typing import Iterator

import numpy as np

from edge_runtime import config
from edge_runtime.errors import InputError
from edge_runtime.wearable.classifier import resample_poly

SAMPLE_RATE_HZ = 100
CSV_HEADER = ("t", "ax", "ay", "az")
MAX_GAP_PERIODS = 1.5
"""A step between timestamps longer than this many sample periods is a gap."""
MAX_TIME_S = 1e10
"""A recording's times are seconds (of a session, or since 1970: 1.7e9 now); beyond this
(about 300 years) a time is not one, and every sample after it would be dropped as going
back in time, so the line is refused."""
SILENCE_BUDGET_S = 0.15
"""``[imu] silence_timeout_s + read_period_s`` at most: with the 50 ms a silent line may wait to be
looked at, a silent sensor is reported within 200 ms of its last sample (docs/integrator.md)."""
MIN_RATE_HZ, MAX_RATE_HZ = 1.0, 10_000.0
"""Recording rates the replay resamples from; outside, the timestamps are not a sample clock."""


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
    silence_timeout_s: float = config.setting(0.1, config.within(0.02, 0.15, "s"))
    """No sample for at least this long: the sensor is silent (a shorter gap never is). WEARABLE_STATUS
    says so at once (an extra heartbeat on every change of state), within 200 ms of the last sample's
    arrival: the source reports it within ``silence_timeout_s + read_period_s`` + 50 ms (it may have
    read the last sample up to a read period after it arrived, and it looks at a silent line every
    50 ms), so the two add up to at most 0.15 s; at least two sample periods."""
    read_period_s: float = config.setting(0.05, config.within(0.0, 0.05, "s"))
    """A live source reads the serial line at most this often while samples flow and hands over
    everything that arrived meanwhile as one block (the line's buffer holds it), instead of waking for
    every sample: the wake-ups, not the loop's arithmetic, were most of its CPU (``python -m bench
    --cpus 0 --busy-cpus 1``, wearable_100hz, 2026-11-26: fed one sample every 10 ms (``--read-period
    0``) 1.27 % of a core, of which the feed calls 0.54 % (p50 54 us, on caches a 10 ms sleep leaves
    cold); in blocks of 5 every 50 ms 0.56 %). The price is latency: a sample waits up to this long
    before the loop sees it (alert latencies are measured from the start of that wait), and the
    silence timeout must leave room for it (``silence_timeout_s``). 0: read every sample as it
    arrives."""

    def __post_init__(self):
        if self.silence_timeout_s + self.read_period_s > SILENCE_BUDGET_S + 1e-9:
            raise ValueError(f"silence_timeout_s + read_period_s: {self.silence_timeout_s:g} + {self.read_period_s:g} s "
                             f"is over {SILENCE_BUDGET_S:g} s (a silent sensor must be reported within 200 ms)")


@dataclass
class ImuBlock:
    t0_s: float
    """Stream time of the first sample (s)."""
    acc_mps2: np.ndarray
    """(n, 3) float32, specific force in the sensor frame, m/s^2, 100 Hz."""
    continuous: bool = True
    """False when this block does not follow the previous one without a gap."""
    rx_monotonic_s: float | None = None
    """Host ``time.monotonic()`` no later than the block's samples arrived (live sources; None for a
    file): the read that brought them, or the previous one when they waited in the line's buffer. The
    loop carries it to the decision so alert latency is measured from arrival, the wait included."""


@dataclass
class ReplayStats:
    rows: int = 0
    dropped_non_monotonic: int = 0
    gaps: int = 0
    out_of_range: int = 0
    """Samples with an axis beyond the sensor's range: impossible readings, passed on as NaN
    (the loop counts them with the non-finite ones and restarts the detector around them)."""
    saturated: int = 0
    """Samples with an axis at the sensor's full scale (passed on: a real sensor clips there)."""
    source_rate_hz: float = SAMPLE_RATE_HZ
    notices: list[str] = field(default_factory=list)


CHUNK_ROWS = 1 << 12
"""Rows parsed at a time: a replay holds one chunk, whatever the recording's length (larger
chunks parse no faster and leave the allocator a larger high-water mark: the array parser
holds several 8-byte index arrays per byte of text: 128 KiB chunks keep a replay's peak memory
where numpy's text parser had it with 16,384 rows, 512 KiB added about 18 MB)."""
ROW_BYTES = 32
"""Bytes of a typical row (``12345.67,-1.2345,9.8765,0.1234``): chunks are read as bytes."""
SATURATION_TOLERANCE = 1e-6
"""A reading within this fraction of full scale is at full scale (saturated), beyond it: impossible."""


def screen_samples(acc: np.ndarray, range_mps2: float) -> tuple[np.ndarray, int, int]:
    """The one check of sample values, for every source: ``acc`` (n, 3) as float32 with each
    sample that has a non-finite axis or one beyond ``range_mps2`` set to NaN (so the loop
    counts it and the model never sees it), the number set to NaN for being out of range,
    and the number at full scale (saturated, passed on)."""
    if type(acc) is np.ndarray and acc.dtype == np.float32 and acc.ndim == 2 and acc.shape[1] == 3 and len(acc):
        # the common case, a block well inside the range: one maximum over the block instead of per-sample
        # checks (a NaN makes the maximum NaN and takes the full path); compared as float64, as below
        with np.errstate(invalid="ignore"):
            peak = float(np.abs(acc).max())
        if peak < range_mps2 * (1 - SATURATION_TOLERANCE):
            return acc.copy(), 0, 0
    with np.errstate(invalid="ignore", over="ignore"):  # a signalling NaN (a binary recording may hold one) warns
        a = np.asarray(acc, dtype=np.float64).reshape(-1, 3)
        mag = np.abs(a)
        beyond = (mag > range_mps2 * (1 + SATURATION_TOLERANCE)).any(axis=1)
        at_scale = (mag >= range_mps2 * (1 - SATURATION_TOLERANCE)).any(axis=1) & ~beyond
        out = a.astype(np.float32)  # finite float64 beyond float32 becomes inf here; it is beyond range too
    out[beyond] = np.nan
    return out, int(beyond.sum()), int(at_scale.sum())


def _open_csv(path: Path):
    try:
        f = path.open("rb")
    except OSError as e:
        raise InputError(f"{path}: cannot read ({e.strerror or e})") from None
    first = f.readline()
    if not first:
        f.close()
        raise InputError(f"{path}: empty file; expected the header 't,ax,ay,az'")
    header = tuple(c.strip() for c in first.decode("utf-8", "replace").split(","))
    if header != CSV_HEADER:
        f.close()
        shown = ",".join(header)[:60]
        raise InputError(f"{path}:1: header is {shown!s}; expected 't,ax,ay,az'")
    return f


def _parse_rows(path: Path, lines: list[bytes], first_no: int) -> np.ndarray:
    """Rows of ``t,ax,ay,az`` -> (n, 4) float64; a malformed line is an InputError naming it."""
    fast = _parse_plain_rows(lines)
    if fast is not None:
        return fast
    try:
        text = b"".join(lines).decode("utf-8")
        data = np.loadtxt(io.StringIO(text), delimiter=",", ndmin=2, dtype=np.float64)
        if data.shape[1:] == (4,) or data.size == 0:
            return data.reshape(-1, 4)
    except (UnicodeDecodeError, ValueError):
        pass
    for no, raw in enumerate(lines, start=first_no):  # find the offending line
        try:
            line = raw.decode("utf-8")
        except UnicodeDecodeError as e:
            raise InputError(f"{path}:{no}: not UTF-8 text (byte {e.start + 1} of the line)") from None
        cells = line.split(",")
        if not line.strip():
            raise InputError(f"{path}:{no}: empty line")
        if len(cells) != 4:
            raise InputError(f"{path}:{no}: expected 4 fields t,ax,ay,az, got {len(cells)}")
        for name, cell in zip(CSV_HEADER, cells):
            try:
                float(cell)
            except ValueError:
                raise InputError(f"{path}:{no}: field {name!r} is not a number: {cell.strip()[:40]!r}") from None
    raise InputError(f"{path}:{first_no}: unreadable CSV")


def _parse_plain_rows(lines: list[bytes]) -> np.ndarray | None:
    """Lines that :func:`_parse_plain_block` could not take but that hold four comma-separated
    numbers each (exponents, spaces, ``inf`` ...): numpy's text parser. None for anything else
    (blank lines, text, non-UTF-8 ...)."""
    if any(line.count(b",") != 3 for line in lines):
        return None
    try:
        values = np.fromstring(b"".join(lines).replace(b"\n", b","), dtype=np.float64, sep=",")
    except ValueError:
        return None
    return values.reshape(-1, 4) if values.size == 4 * len(lines) else None


MAX_PLAIN_DIGITS = 15
"""Digits of one number :func:`_parse_plain_block` takes: its digits as one integer stay below
2**53, exact in float64."""
_POW10 = 10.0 ** np.arange(MAX_PLAIN_DIGITS + 1)  # exact powers of ten
_COMMA, _NEWLINE, _DOT, _MINUS, _ZERO = map(ord, ",\n.-0")


def _parse_plain_block(buf: bytes) -> np.ndarray | None:
    """The recordings the firmware and loggers write, parsed with array operations (no
    per-number Python or text parser): whole lines of four plain decimals (``-12.3456``),
    ``buf`` ending with a newline -> (lines, 4) float64. None for anything else (exponents,
    signs other than a leading minus, spaces, blank lines, more than 15 digits ...): the
    caller then parses line by line and names a bad line.

    Each number is its digits as one integer M (exact: < 2**53) divided by 10**k for its k
    digits after the point; IEEE division of two exact values rounds correctly, so the result
    is the float64 nearest the decimal, as ``float()`` gives it."""
    b = np.frombuffer(buf, dtype=np.uint8)
    digit = b - np.uint8(_ZERO)  # wraps: every non-digit byte is >= 10
    is_digit = digit < 10
    sep = (b == _COMMA) | (b == _NEWLINE)
    dot, minus = b == _DOT, b == _MINUS
    n_dot, n_minus = int(np.count_nonzero(dot)), int(np.count_nonzero(minus))
    if int(np.count_nonzero(is_digit)) + int(np.count_nonzero(sep)) + n_dot + n_minus != len(b):
        return None  # a byte that is none of 0-9 , \n . -
    ends = np.flatnonzero(sep)
    n_lines = int(np.count_nonzero(b[ends] == _NEWLINE))
    if not n_lines or len(ends) != 4 * n_lines or not (b[ends[3::4]] == _NEWLINE).all():
        return None  # every line: exactly three commas, then the newline
    at = np.flatnonzero(is_digit)  # where the digits are, in order
    end_count = np.searchsorted(at, ends)  # digits before each number's end
    n_digits = np.diff(end_count, prepend=0)
    if n_digits.min() < 1 or n_digits.max() > MAX_PLAIN_DIGITS:
        return None
    negative = minus[np.r_[0, ends[:-1] + 1]]
    if int(np.count_nonzero(negative)) != n_minus:
        return None  # a minus that is not a number's first byte
    dots = np.flatnonzero(dot)
    dot_field = np.searchsorted(ends, dots)  # the number each point belongs to
    if dots.size > 1 and not (np.diff(dot_field) > 0).all():
        return None  # two points in one number
    frac_digits = np.zeros(len(ends), dtype=np.int64)
    frac_digits[dot_field] = end_count[dot_field] - np.searchsorted(at, dots)
    # each digit times 10 ** (digits after it in its number), summed per number: exact integers
    power = np.repeat(end_count, n_digits) - np.arange(1, len(at) + 1)
    mantissa = np.add.reduceat(digit[at] * _POW10[power], end_count - n_digits)
    values = mantissa / _POW10[frac_digits]
    np.negative(values, out=values, where=negative)
    return values.reshape(-1, 4)


def _line_blocks(f, block_bytes: int) -> Iterator[bytes]:
    """The rest of ``f`` in blocks of whole lines of about ``block_bytes`` (a line longer than
    that is one block); the last line gets its newline if the file lacks one."""
    rest = b""
    while buf := f.read(block_bytes):
        buf = rest + buf
        cut = buf.rfind(b"\n") + 1
        if not cut:
            rest = buf
            continue
        rest = buf[cut:]
        yield buf[:cut]
    if rest:
        yield rest + b"\n"


def _chunks(path: Path, f, chunk_rows: int) -> Iterator[tuple[int, np.ndarray]]:
    """(line number of the first row, rows) of about ``chunk_rows`` rows each (read as bytes:
    ``chunk_rows`` x ``ROW_BYTES``); checks 't' is finite."""
    no = 2
    for buf in _line_blocks(f, chunk_rows * ROW_BYTES):
        data = _parse_plain_block(buf)
        if data is None:
            lines = io.BytesIO(buf).readlines()
            data = _parse_rows(path, lines, no)
            n_lines = len(lines)
        else:
            n_lines = len(data)
        with np.errstate(invalid="ignore"):
            bad_t = np.flatnonzero(~(np.abs(data[:, 0]) <= MAX_TIME_S))  # NaN fails the comparison too
        if bad_t.size:
            raise InputError(f"{path}:{no + bad_t[0]}: field 't' is not a time in seconds "
                             f"(finite, at most {MAX_TIME_S:g}): {data[bad_t[0], 0]!r}")
        yield no, data
        no += n_lines


def _rate_ratio(rate_hz: float) -> Fraction:
    return Fraction(SAMPLE_RATE_HZ / rate_hz).limit_denominator(50)


def read_imu_csv(path: str | Path, stats: ReplayStats | None = None, range_mps2: float = ImuParams.range_mps2,
                 chunk_rows: int = CHUNK_ROWS) -> Iterator[ImuBlock]:
    """A recording ``t,ax,ay,az`` (s, m/s^2) as continuous 100 Hz blocks, streamed: the file is
    read ``chunk_rows`` at a time, so memory does not grow with the recording's length.

    The header, the first chunk and the sample rate are checked at once (bad input is
    reported before anything runs); a malformed line further on ends the replay there
    with an InputError naming it. Out-of-order or duplicate timestamps are dropped and
    counted; a step of more than 1.5 periods (the period: the median step of the first
    chunk) starts a new block; a recording at another constant rate is resampled to 100 Hz
    with a notice (chunk by chunk). Sample values go through :func:`screen_samples`:
    non-finite and out-of-range samples reach the loop as NaN and are counted, never fatal.
    """
    path = Path(path)
    stats = stats if stats is not None else ReplayStats()
    f = _open_csv(path)
    try:
        chunks = _chunks(path, f, chunk_rows)
        first = next(chunks, None)
        if first is None or not len(first[1]):
            raise InputError(f"{path}: no samples after the header")
        period, ratio = _replay_rate(path, first[1], stats)
    except BaseException:
        f.close()
        raise
    return _replay_blocks(f, first, chunks, period, ratio, range_mps2, stats, path)


def _replay_rate(path: Path, data: np.ndarray, stats: ReplayStats) -> tuple[float, Fraction]:
    t = data[:, 0]
    t = t[np.r_[True, t[1:] > np.maximum.accumulate(t)[:-1]]]
    if len(t) < 2:
        return 1.0 / SAMPLE_RATE_HZ, Fraction(1)
    period = float(np.median(np.diff(t)))
    rate = 1.0 / period
    if not MIN_RATE_HZ <= rate <= MAX_RATE_HZ:
        raise InputError(f"{path}: the timestamps give a sample rate of {rate:.3g} Hz (median step {period:.3g} s); "
                         f"expected {MIN_RATE_HZ:g} to {MAX_RATE_HZ:g} Hz")
    ratio = Fraction(1)
    if abs(rate - SAMPLE_RATE_HZ) > 0.01 * SAMPLE_RATE_HZ:
        ratio = _rate_ratio(rate)
        if ratio.numerator > 50 or math.isclose(float(ratio), 0.0):
            raise InputError(f"{path}: sample rate {rate:.3g} Hz cannot be resampled to {SAMPLE_RATE_HZ} Hz")
        stats.notices.append(f"{path}: recorded at {rate:.4g} Hz; resampled to {SAMPLE_RATE_HZ} Hz "
                             f"(polyphase {ratio.numerator}/{ratio.denominator})")
    stats.source_rate_hz = rate
    return period, ratio


def _replay_blocks(f, first, chunks, period: float, ratio: Fraction, range_mps2: float,
                   stats: ReplayStats, path: Path) -> Iterator[ImuBlock]:
    last_t: float | None = None
    with f:
        for _, data in chain([first], chunks):
            stats.rows += len(data)
            t = data[:, 0]
            prev = -math.inf if last_t is None else last_t
            keep = t > np.maximum.accumulate(np.r_[prev, t])[:-1]  # drop samples that do not advance time
            dropped = int((~keep).sum())
            if dropped and not stats.dropped_non_monotonic:
                stats.notices.append(f"{path}: samples whose time did not advance are dropped (counted)")
            stats.dropped_non_monotonic += dropped
            t, acc = t[keep], data[keep, 1:]
            if not len(t):
                continue
            steps = np.diff(np.r_[prev, t])
            breaks = np.flatnonzero(steps > MAX_GAP_PERIODS * period)
            if last_t is None:
                breaks = breaks[1:]  # the very first sample starts the first block
            n_gaps = int(breaks.size)
            if n_gaps and not stats.gaps:
                stats.notices.append(f"{path}: gap(s) in time; the detector restarts after each (counted)")
            stats.gaps += n_gaps
            acc, out_of_range, saturated = screen_samples(acc, range_mps2)
            stats.out_of_range += out_of_range
            stats.saturated += saturated
            starts = set(breaks.tolist())
            bounds = [0, *sorted(starts), len(t)]
            for a, b in zip(bounds[:-1], bounds[1:]):
                if b <= a:
                    continue
                seg = acc[a:b]
                if ratio != 1:
                    seg = np.clip(_resample_segment(seg, ratio), -range_mps2, range_mps2).astype(np.float32)
                yield ImuBlock(float(t[a]), seg, continuous=a not in starts)
            last_t = float(t[-1])


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
