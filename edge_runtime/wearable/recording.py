"""The box's own IMU recording format (``.imu``): what the loop was fed, written by ``--record`` and
read by ``--replay`` beside CSV.

A CSV recording costs more to parse than everything the loop does with it (a day of 100 Hz
samples is 275 MB of text); this format is the samples as the IMU sends them in HIGHRES_IMU
(float32 m/s^2 per axis, little-endian), 12 bytes a sample, read with one copy per record.
Values are exactly the float32 the loop is fed, so a CSV replayed directly and through a
recording made from it decide the same.

Layout (little-endian):

* header, 16 bytes: magic ``b"EDGEIMU\\n"``, version u16 (1), reserved u16 (0), sample rate u32 (Hz);
* records, each: start time float64 (s, the stream time of its first sample), sample count
  u32 (1 .. MAX_RECORD_ROWS), reserved u32 (0), then count x 3 float32 (ax, ay, az).

A record that starts where the previous one ended (within half a period) continues it; one that
starts later follows a gap (the loop restarts its detector, counted as in CSV); one that starts
earlier is refused. NaN is a bad sample (the loop counts it), as from any source; values pass
:func:`~edge_runtime.wearable.sources.screen_samples` like every source's. A malformed header or
record is an InputError naming the file and the byte offset; memory is one record, whatever the
recording's length.
"""
from __future__ import annotations

import math
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO, Iterator

import numpy as np

from edge_runtime.errors import InputError
from edge_runtime.wearable.sources import (
    MAX_TIME_S,
    SAMPLE_RATE_HZ,
    ImuBlock,
    ImuParams,
    ReplayStats,
    read_imu_csv,
    screen_samples,
)

MAGIC = b"EDGEIMU\n"
VERSION = 1
HEADER = struct.Struct("<8sHHI")
RECORD = struct.Struct("<dII")
SAMPLE_BYTES = 12
MAX_RECORD_ROWS = 1 << 16
"""Samples of one record at most: a reader holds one record (786 KB), whatever a file claims."""
RECORD_ROWS = 1 << 12
"""Samples per record the writer writes (41 s at 100 Hz): large enough that a record's overhead is nothing."""


def is_recording(path: str | Path) -> bool:
    """Whether ``path`` starts with this format's magic (else it is read as CSV)."""
    try:
        with open(path, "rb") as f:
            return f.read(len(MAGIC)) == MAGIC
    except OSError:
        return False  # the CSV reader names the file and the reason


REPLAY_BLOCK_ROWS = MAX_RECORD_ROWS
"""Samples ``--replay`` hands the loop at most in one block: records that continue one another are
joined up to this many (11 min at 100 Hz, 786 KB), so that the loop classifies the captures a block
completes together (``WearableLoop``: one model run per step for all of them, instead of one per
capture) while a reader still holds a bounded amount, whatever the recording's length."""


def open_replay(path: str | Path, stats: ReplayStats | None = None, range_mps2: float = ImuParams.range_mps2
                ) -> Iterator[ImuBlock]:
    """``--replay FILE``: a recording of this format (records joined up to :data:`REPLAY_BLOCK_ROWS`)
    or a CSV ``t,ax,ay,az``, as 100 Hz blocks, streamed."""
    if is_recording(path):
        return read_recording(path, stats, range_mps2, join_rows=REPLAY_BLOCK_ROWS)
    return read_imu_csv(path, stats, range_mps2=range_mps2)


def read_recording(path: str | Path, stats: ReplayStats | None = None, range_mps2: float = ImuParams.range_mps2,
                   join_rows: int = 0) -> Iterator[ImuBlock]:
    """The records of ``path`` as ImuBlocks; the header is checked at once (bad input is reported
    before anything runs), a bad record further on ends the replay there with an InputError.
    ``join_rows`` > 0: records that continue one another, with every sample inside the sensor's range,
    go out as one block of up to that many samples (a record with a finding goes alone, and what
    ``stats`` counts of a block is counted when it goes out, so that everything downstream reads the
    counts it read with one block per record); 0: one block per record."""
    path = Path(path)
    stats = stats if stats is not None else ReplayStats()
    try:
        f = path.open("rb")
    except OSError as e:
        raise InputError(f"{path}: cannot read ({e.strerror or e})") from None
    try:
        head = f.read(HEADER.size)
        if len(head) < HEADER.size:
            raise InputError(f"{path}: {len(head)} bytes; an IMU recording's header is {HEADER.size}")
        magic, version, reserved, rate_hz = HEADER.unpack(head)
        if magic != MAGIC:
            raise InputError(f"{path}: not an IMU recording (no {MAGIC!r} at byte 0)")
        if version != VERSION or reserved:
            raise InputError(f"{path}: IMU recording version {version}.{reserved}; this box reads {VERSION}.0")
        if rate_hz != SAMPLE_RATE_HZ:
            raise InputError(f"{path}: recorded at {rate_hz} Hz; the recording format holds {SAMPLE_RATE_HZ} Hz "
                             f"samples (replay a CSV to resample)")
    except BaseException:
        f.close()
        raise
    return _joined(_records(f, path, range_mps2), path, stats, join_rows)


def _records(f: BinaryIO, path: Path, range_mps2: float) -> Iterator[_Record]:
    period_s = 1.0 / SAMPLE_RATE_HZ
    end_s: float | None = None  # when the next sample of the stream would be due
    offset = HEADER.size
    with f:
        while head := f.read(RECORD.size):
            if len(head) < RECORD.size:
                raise InputError(f"{path}: byte {offset}: truncated record header ({len(head)} of {RECORD.size} bytes)")
            t0_s, n, reserved = RECORD.unpack(head)
            if not (math.isfinite(t0_s) and abs(t0_s) <= MAX_TIME_S):
                raise InputError(f"{path}: byte {offset}: start time {t0_s!r} is not a time in seconds "
                                 f"(finite, at most {MAX_TIME_S:g})")
            if not 1 <= n <= MAX_RECORD_ROWS or reserved:
                raise InputError(f"{path}: byte {offset}: record of {n} samples (1..{MAX_RECORD_ROWS}), "
                                 f"reserved field {reserved} (0)")
            if end_s is not None and t0_s < end_s - period_s / 2:
                raise InputError(f"{path}: byte {offset}: record starts at {t0_s:.3f} s, before the previous "
                                 f"one ended ({end_s:.3f} s)")
            body = f.read(n * SAMPLE_BYTES)
            if len(body) < n * SAMPLE_BYTES:
                raise InputError(f"{path}: byte {offset + RECORD.size}: truncated record ({len(body)} of "
                                 f"{n * SAMPLE_BYTES} bytes of samples)")
            acc, out_of_range, saturated = screen_samples(np.frombuffer(body, "<f4").reshape(n, 3), range_mps2)
            continuous = end_s is None or t0_s <= end_s + period_s / 2
            yield _Record(t0_s, acc, continuous, out_of_range, saturated)
            end_s = t0_s + n * period_s
            offset += RECORD.size + n * SAMPLE_BYTES


@dataclass
class _Record:
    t0_s: float
    acc: np.ndarray
    continuous: bool
    out_of_range: int
    saturated: int


def _joined(records: Iterator[_Record], path: Path, stats: ReplayStats, join_rows: int) -> Iterator[ImuBlock]:
    """The records as blocks (see :func:`read_recording`), each counted in ``stats`` as it goes out;
    at a bad record the blocks before it go out first, then its InputError."""
    held: list[_Record] = []
    rows = 0
    while True:
        try:
            rec = next(records, None)
        except InputError:
            if held:
                yield _block(held, path, stats)
            raise
        if held and (rec is None or not rec.continuous or rec.out_of_range or rec.saturated
                     or rows + len(rec.acc) > join_rows):
            yield _block(held, path, stats)
            held, rows = [], 0
        if rec is None:
            return
        held.append(rec)
        rows += len(rec.acc)
        if rec.out_of_range or rec.saturated or rows >= join_rows:
            yield _block(held, path, stats)
            held, rows = [], 0


def _block(held: list[_Record], path: Path, stats: ReplayStats) -> ImuBlock:
    first = held[0]
    for rec in held:
        stats.rows += len(rec.acc)
        stats.out_of_range += rec.out_of_range
        stats.saturated += rec.saturated
    if not first.continuous:
        if not stats.gaps:
            stats.notices.append(f"{path}: gap(s) in time; the detector restarts after each (counted)")
        stats.gaps += 1
    acc = first.acc if len(held) == 1 else np.concatenate([rec.acc for rec in held])
    return ImuBlock(first.t0_s, acc, continuous=first.continuous)


class RecordingWriter:
    """``--record OUT.imu``: every block the loop is fed, in records of up to RECORD_ROWS samples.

    Blocks that continue one another are gathered into one record (a live source hands over one
    sample at a time: a record each would triple the file); a record is written when it is full,
    at a gap, and on :meth:`close`."""

    def __init__(self, path: str | Path, rate_hz: int = SAMPLE_RATE_HZ, record_rows: int = RECORD_ROWS):
        if not 1 <= record_rows <= MAX_RECORD_ROWS:
            raise ValueError(f"record_rows must lie in 1..{MAX_RECORD_ROWS}")
        self.path = Path(path)
        try:
            self._f = self.path.open("wb")
        except OSError as e:
            raise InputError(f"--record {self.path}: cannot write ({e.strerror or e})") from None
        self._f.write(HEADER.pack(MAGIC, VERSION, 0, rate_hz))
        self.rate_hz = rate_hz
        self._rows = np.empty((record_rows, 3), "<f4")  # the record being gathered ...
        self._n = 0  # ... its samples so far ...
        self._t0_s = 0.0  # ... and its start time

    def write(self, block: ImuBlock) -> None:
        acc = np.asarray(block.acc_mps2, dtype="<f4").reshape(-1, 3)
        t0_s = block.t0_s
        if self._n and (not block.continuous or abs(t0_s - (self._t0_s + self._n / self.rate_hz)) > 0.5 / self.rate_hz):
            self._flush()
        while len(acc):
            if not self._n:
                self._t0_s = t0_s
            take = min(len(acc), len(self._rows) - self._n)
            self._rows[self._n : self._n + take] = acc[:take]
            self._n += take
            if self._n == len(self._rows):
                self._flush()
            acc, t0_s = acc[take:], t0_s + take / self.rate_hz

    def _flush(self) -> None:
        self._f.write(RECORD.pack(self._t0_s, self._n, 0))
        self._f.write(self._rows[: self._n].tobytes())
        self._n = 0

    def close(self) -> None:
        if self._f.closed:
            return
        if self._n:
            self._flush()
        self._f.close()
