"""Live wrist-IMU source: MAVLink 2 HIGHRES_IMU / SCALED_IMU over a serial line.

``MavlinkImuSource(path).blocks()`` yields :class:`ImuBlock` objects -- whatever
arrived in one read of the serial line (at most ``block_samples``) -- and :class:`SourceStatus`
events (the sensor went silent / came back). With ``read_period_s`` (the box's ``[imu]
read_period_s``, 0.05 s) it reads at most that often while samples flow, so a read brings the
samples that arrived meanwhile (5 at 100 Hz) and the process wakes 20 times a second instead of
100. Without it (0, the class's default) a read usually brings one sample.

Two clocks, each a bound on the right side:

* a block's ``rx_monotonic_s`` is never later than its samples arrived: the time the previous
  read returned when its bytes were already waiting as this read began (they came after it), else
  this read's own time (it waited for them). Alert latencies measured from it count the buffer's
  wait, so they are never flattering;
* silence is measured from the time of the read that brought the last sample, never earlier than
  its arrival: "silent" means no sample for at least ``silence_timeout_s``, never a shorter gap.

A silent line is looked at at least every read timeout (50 ms): after the period's sleep only
what is already waiting is read, and a read that waits for the line waits at most that long. So
silence is reported within ``silence_timeout_s + read_period_s + 50 ms`` of the last sample's
arrival (the box's limits keep that within 200 ms, :class:`~edge_runtime.wearable.sources.ImuParams`),
and the "silent" status is repeated every read timeout while it lasts (the caller keeps control for
its heartbeat).

Bad input is counted in :attr:`MavlinkImuSource.stats` and handled:

* corrupted bytes: pymavlink's CRC check rejects the packet (robust parsing; the
  packet and bytes are counted, nothing of it is delivered);
* a gap in the timestamps (> 1.5 periods): the next block has ``continuous=False``
  and the missing samples are counted as ``dropped``;
* duplicate or out-of-order timestamps: the sample is dropped and counted (a jump
  back of more than 1 s is taken as a sensor reboot: the stream restarts,
  ``continuous=False``);
* NaN samples are passed on (the loop counts them and resets its detector);
  SCALED_IMU's -32768 is the "invalid" marker and becomes NaN;
* values: :func:`~edge_runtime.wearable.sources.screen_samples`, the one check every source
  uses: an axis at the configured full scale ``range_mps2`` (or SCALED_IMU's int16 limit)
  is counted as saturated and passed on; beyond it (or inf, or a float32 overflow) the
  sample is counted and passed on as NaN, so the model never sees it;
* with a signing key, unsigned or wrongly signed packets are rejected and counted; the
  signature is checked before the stream's timestamp moves (``core.serial_line.SignedMAVLink``),
  so a forged packet stamped far in the future cannot make later genuine packets look replayed;
* a stray start byte (0xFD) costs only itself: the parser rescans the bytes behind it.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable, Iterator, Union

import numpy as np
import serial

from edge_runtime.core.mavlink import make_mavlink, signature_failure
from edge_runtime.wearable.sources import (
    MAX_GAP_PERIODS,
    SAMPLE_RATE_HZ,
    SATURATION_TOLERANCE,
    ImuBlock,
    ImuParams,
    screen_samples,
)

MG_TO_MPS2 = 9.80665e-3
G_MPS2 = 9.80665
INT16_INVALID = -32768
INT16_SAT = 32767
BLOCK_SAMPLES = 10
READ_TIMEOUT_S = 0.05
REBOOT_BACKJUMP_S = 1.0


@dataclass
class SourceStatus:
    state: str
    """"silent" (no sample for silence_timeout_s), "ok" (samples again), "disconnected"."""
    since_s: float
    """Seconds since the read that brought the last sample (monotonic clock) when the event was raised:
    the sensor has been silent at least this long."""
    last_t_s: float | None = None
    """Stream time of the last sample received, if any."""


@dataclass
class SourceStats:
    samples: int = 0
    blocks: int = 0
    packets: int = 0
    heartbeats: int = 0
    crc_errors: int = 0
    """Packets rejected by the parser (bad CRC, bad length/flags, junk bytes)."""
    bad_bytes: int = 0
    """Bytes thrown away with those packets."""
    dropped: int = 0
    """Samples missing from the stream (timestamp gaps)."""
    gaps: int = 0
    out_of_order: int = 0
    """Duplicate or backwards timestamps (dropped)."""
    reboots: int = 0
    saturated: int = 0
    """Samples with an axis at full scale (the configured range, or SCALED_IMU's int16 limit)."""
    out_of_range: int = 0
    """Samples with an axis beyond the configured range: passed on as NaN (never to the model)."""
    nan_samples: int = 0
    signature_failures: int = 0
    silent_events: int = 0
    read_errors: int = 0


Event = Union[ImuBlock, SourceStatus]


class ImuPacketDecoder:
    """Bytes of the serial line -> ImuBlocks (and "ok" SourceStatus events): the MAVLink
    parser, the signature check and the timestamp bookkeeping, with no line and no clock
    of its own (``feed`` is given the arrival time), so it can be driven with any bytes."""

    def __init__(self, signing_key: bytes | None = None, range_mps2: float = ImuParams.range_mps2,
                 block_samples: int = BLOCK_SAMPLES, stats: SourceStats | None = None):
        self.range_mps2 = float(range_mps2)
        self._inside_mps2 = self.range_mps2 * (1 - SATURATION_TOLERANCE)  # below it, an axis is neither clipped nor saturated
        self.block_samples = int(block_samples)
        self.stats = stats if stats is not None else SourceStats()
        # The robot link's endpoint: it checks a signature before any timestamp state changes
        # (a forged far-future packet cannot starve the line) and resynchronises after a stray
        # start byte. With a key, unsigned packets are refused.
        self.mav = make_mavlink(None, 0, 0, signing_key, link_id=0)
        self._period = 1.0 / SAMPLE_RATE_HZ
        self._last_t: float | None = None
        self._pending: list[tuple[float, float, float]] = []
        self._pending_t0: float | None = None
        self._pending_continuous = False  # the first block of a stream is not continuous
        self._next_continuous = False
        self._rx: float | None = None
        self.silent = False
        """Set by the owner when the sensor went silent; the next sample reports "ok"."""

    @property
    def last_t_s(self) -> float | None:
        return self._last_t

    def feed(self, data: bytes, rx_monotonic_s: float, out: list) -> None:
        """The events in ``data`` (arrived at ``rx_monotonic_s``) appended to ``out``; a block
        that is not full yet is held back until :meth:`flush`."""
        self._rx = rx_monotonic_s
        for m in self.mav.parse_buffer(data) or ():
            self._handle(m, out)

    def _handle(self, m, out: list) -> None:
        mtype = m.get_type()
        if mtype == "BAD_DATA":
            if signature_failure(self.mav, m) is not None:
                self.stats.signature_failures += 1
            else:
                self.stats.crc_errors += 1
                self.stats.bad_bytes += len(getattr(m, "data", b""))
            return
        self.stats.packets += 1
        if mtype == "HEARTBEAT":
            self.stats.heartbeats += 1
            return
        if mtype == "HIGHRES_IMU":
            t = m.time_usec * 1e-6
            acc = (float(m.xacc), float(m.yacc), float(m.zacc))
            int16_sat = False
        elif mtype == "SCALED_IMU":
            t = m.time_boot_ms * 1e-3
            raw = (m.xacc, m.yacc, m.zacc)
            acc = tuple(float("nan") if r == INT16_INVALID else r * MG_TO_MPS2 for r in raw)
            int16_sat = any(abs(r) >= INT16_SAT for r in raw if r != INT16_INVALID)
        else:
            return
        nan = any(v != v for v in acc)
        if not nan and max(map(abs, acc)) < self._inside_mps2:
            # well inside the range, the common case: what screen_samples returns for it (the values
            # as they are, nothing counted), without its numpy calls for every sample
            self._sample(t, acc, int16_sat, False, out)
            return
        screened, out_of_range, at_scale = screen_samples(np.asarray(acc), self.range_mps2)
        self.stats.out_of_range += out_of_range
        self._sample(t, tuple(screened[0]), int16_sat or at_scale > 0, nan, out)

    def _sample(self, t: float, acc, sat: bool, nan: bool, out: list) -> None:
        if self._last_t is not None:
            dt = t - self._last_t
            if dt < -REBOOT_BACKJUMP_S:  # sensor rebooted: a new stream
                self.stats.reboots += 1
                self.flush(out)
                self._next_continuous = False
            elif dt <= 0.5 * self._period:
                self.stats.out_of_order += 1
                return
            elif dt > MAX_GAP_PERIODS * self._period:
                self.stats.gaps += 1
                self.stats.dropped += max(0, int(round(dt / self._period)) - 1)
                self.flush(out)
                self._next_continuous = False
        if self.silent:
            self.silent = False
            out.append(SourceStatus("ok", 0.0, self._last_t))
        self._last_t = t
        self.stats.samples += 1
        if sat:
            self.stats.saturated += 1
        if nan:
            self.stats.nan_samples += 1
        if not self._pending:
            self._pending_t0 = t
            self._pending_continuous = self._next_continuous
            self._next_continuous = True
        self._pending.append(acc)
        if len(self._pending) >= self.block_samples:
            self.flush(out)

    def flush(self, out: list) -> None:
        """The samples held back, as a block appended to ``out``."""
        if not self._pending:
            return
        out.append(ImuBlock(self._pending_t0, np.asarray(self._pending, dtype=np.float32),
                            self._pending_continuous, rx_monotonic_s=self._rx))
        self.stats.blocks += 1
        self._pending = []
        self._pending_t0 = None


class MavlinkImuSource:
    """A :class:`ImuPacketDecoder` on a serial line, with the silence watch."""

    def __init__(self, path: str, baud: int = 921600, signing_key: bytes | None = None,
                 silence_timeout_s: float = 0.2, range_mps2: float = ImuParams.range_mps2,
                 on_status: Callable[[SourceStatus], None] | None = None,
                 block_samples: int = BLOCK_SAMPLES, read_timeout_s: float = READ_TIMEOUT_S,
                 read_period_s: float = 0.0):
        self.path = path
        self.silence_timeout_s = float(silence_timeout_s)
        self.on_status = on_status
        self.read_timeout_s = min(float(read_timeout_s), READ_TIMEOUT_S)
        self.read_period_s = float(read_period_s)
        if not 0.0 <= self.read_period_s <= self.read_timeout_s:
            # longer, and a line that just fell silent would go unlooked-at for longer than a read timeout
            raise ValueError(f"read_period_s: {read_period_s!r} is outside [0, {self.read_timeout_s:g}] s")
        self.decoder = ImuPacketDecoder(signing_key, range_mps2, block_samples)
        self.stats = self.decoder.stats
        try:
            self.ser = serial.Serial(path, baudrate=baud, timeout=self.read_timeout_s)
        except (serial.SerialException, OSError) as e:
            raise ValueError(f"cannot open IMU serial line {path!r}: {e}") from None
        self._closed = False
        self._opened_s = time.monotonic()

    # -- public --------------------------------------------------------------------------
    def close(self) -> None:
        self._closed = True
        try:
            self.ser.close()
        except Exception:
            pass

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def blocks(self, duration_s: float | None = None) -> Iterator[Event]:
        """ImuBlocks and SourceStatus events until close() (or ``duration_s`` of wall time)."""
        end = None if duration_s is None else time.monotonic() + duration_s
        out: list[Event] = []
        last_read_s = time.monotonic()  # when the previous read returned ...
        flowing = False  # ... with bytes
        seen_s = self._opened_s  # when the read that brought the last sample returned
        while not self._closed:
            if end is not None and time.monotonic() >= end:
                break
            # ``read_period_s``: while bytes flow, let the line's buffer gather them until the period is
            # over, then take only what is waiting (a second, blocking read after the sleep would leave a
            # line that just fell silent unlooked-at for two read timeouts); after an empty read the next
            # one waits for the line itself, at most a read timeout
            wait_s = last_read_s + self.read_period_s - time.monotonic() if flowing else 0.0
            if wait_s > 0:
                time.sleep(wait_s)
            waiting = self._waiting()
            got = self._read(waiting) if waiting or wait_s <= 0 else b""
            now = time.monotonic()
            if got:
                # bytes already waiting came after the previous read returned: stamped then, never later
                # than they arrived; bytes this read waited for arrived as it returned
                samples = self.stats.samples
                self.decoder.feed(got, last_read_s if waiting else now, out)
                if self.stats.samples != samples:
                    seen_s = now
            last_read_s, flowing = now, bool(got)
            # hand over at once what this read brought: a capture's last sample waits for nothing more
            self.decoder.flush(out)
            if now - seen_s >= self.silence_timeout_s and not out:
                # repeated every read timeout while silent, so that the caller keeps control
                # (heartbeats); silent_events counts the transitions only
                if not self.decoder.silent:
                    self.decoder.silent = True
                    self.stats.silent_events += 1
                out.append(SourceStatus("silent", now - seen_s, self.decoder.last_t_s))
            while out:
                event = out.pop(0)
                if self.on_status is not None and isinstance(event, SourceStatus):
                    self.on_status(event)
                yield event
        self.decoder.flush(out)
        yield from out

    # -- internals -----------------------------------------------------------------------
    def _waiting(self) -> int:
        """Bytes in the line's buffer now (0 when the line cannot say: the read finds out)."""
        try:
            return self.ser.in_waiting
        except (serial.SerialException, OSError):
            return 0

    def _read(self, waiting: int) -> bytes:
        """What is waiting, or (nothing waiting) the first byte to come within the read timeout."""
        try:
            return self.ser.read(max(1, waiting))
        except (serial.SerialException, OSError):
            # e.g. the writer closed the pty: wait a read timeout, never spin
            self.stats.read_errors += 1
            time.sleep(self.read_timeout_s)
            return b""
