"""Simulated wrist-IMU firmware: streams a recording as MAVLink 2 over a serial line.

The "sensor" samples at a real 100 Hz, paced by ``time.monotonic`` against absolute
deadlines (it sleeps until the next one, never busy-waits, and catches up without
drift when it was late). Timestamps are boot-relative: ``time_usec`` of HIGHRES_IMU
(m/s^2) or ``time_boot_ms`` of SCALED_IMU (mG, int16). A HEARTBEAT goes out at 1 Hz.
Packets may be MAVLink 2 signed. :class:`FaultConfig` injects dropped samples,
corrupted bytes (the receiver's CRC check fails), NaN bursts, saturation and a
sensor that stops streaming.

Serial lines on this machine are pseudo-terminal pairs: :func:`open_pty_pair`.
"""
from __future__ import annotations

import argparse
import errno
import os
import sys
import threading
import time
import tty
from dataclasses import dataclass, field

import numpy as np
from pymavlink.dialects.v20 import common as mavlink2

SAMPLE_RATE_HZ = 100
G_MPS2 = 9.80665
MG_TO_MPS2 = 9.80665e-3
INT16_SAT = 32767
"""SCALED_IMU full scale; -32768 is reserved as the "invalid sample" marker (NaN)."""
INT16_INVALID = -32768
SRC_SYSTEM = 1
SRC_COMPONENT = mavlink2.MAV_COMP_ID_IMU


@dataclass
class FaultConfig:
    drop_prob: float = 0.0
    """Probability per sample that a burst of ``drop_burst`` samples is not sent."""
    drop_burst: int = 1
    drop_ranges: list = field(default_factory=list)
    """Explicit (first_sample_index, count) ranges that are not sent."""
    corrupt_prob: float = 0.0
    """Probability per packet that one byte of the serialized packet is flipped."""
    nan_prob: float = 0.0
    """Probability per sample that a burst of ``nan_burst`` NaN samples starts."""
    nan_burst: int = 10
    nan_ranges: list = field(default_factory=list)
    saturate_g: float | None = None
    """Clip every axis to +-saturate_g (for SCALED_IMU also to the int16 range)."""
    stop_after_s: float | None = None
    """Stop streaming (samples and heartbeats) after this many seconds: a silent sensor."""
    seed: int = 0


@dataclass
class FirmwareStats:
    samples_sent: int = 0
    samples_dropped: int = 0
    nan_samples: int = 0
    packets_corrupted: int = 0
    heartbeats: int = 0
    tx_overflow: int = 0
    """Packets (partly) lost because nobody reads the line and its buffer is full."""
    late_max_s: float = 0.0


def open_pty_pair() -> tuple[int, str]:
    """A raw pseudo-terminal pair: (master fd the firmware writes to, slave path to connect to).

    The slave is put in raw mode (no echo, no CR/LF translation) and a descriptor of it
    is kept open by the caller's process so that writes succeed before a reader attaches.
    """
    master, slave = os.openpty()
    tty.setraw(slave)
    path = os.ttyname(slave)
    _KEEP_SLAVES[master] = slave
    os.set_blocking(master, False)
    return master, path


_KEEP_SLAVES: dict[int, int] = {}


def close_pty_pair(master_fd: int) -> None:
    slave = _KEEP_SLAVES.pop(master_fd, None)
    for fd in (master_fd, slave):
        if fd is not None:
            try:
                os.close(fd)
            except OSError:
                pass


class _FaultyWriter:
    """The ``file`` of the MAVLink object: corrupts bytes on demand and writes to the fd."""

    def __init__(self, fd: int, fw: "ImuFirmware"):
        self.fd = fd
        self.fw = fw

    def write(self, buf) -> None:
        fw = self.fw
        buf = bytearray(buf)
        if fw.faults.corrupt_prob > 0 and fw._rng.random() < fw.faults.corrupt_prob:
            i = int(fw._rng.integers(0, len(buf)))
            buf[i] ^= int(fw._rng.integers(1, 256))
            fw.stats.packets_corrupted += 1
        view = memoryview(buf)
        while view:
            try:
                n = os.write(self.fd, view)
            except BlockingIOError:
                fw.stats.tx_overflow += 1
                return
            except OSError as e:
                if e.errno in (errno.EIO, errno.EAGAIN):
                    fw.stats.tx_overflow += 1
                    return
                raise
            view = view[n:]


class ImuFirmware:
    def __init__(self, recording_or_acc, port_path_or_fd, message: str = "highres",
                 signing_key: bytes | None = None, faults: FaultConfig | None = None,
                 link_id: int = 0, speed: float = 1.0):
        acc = getattr(recording_or_acc, "acc_mps2", recording_or_acc)
        acc = np.asarray(acc, dtype=np.float64)
        if acc.ndim != 2 or acc.shape[1] != 3:
            raise ValueError(f"IMU data must be (n, 3) m/s^2, got shape {acc.shape}")
        if message not in ("highres", "scaled"):
            raise ValueError(f"message must be 'highres' or 'scaled', got {message!r}")
        if not speed > 0:
            raise ValueError(f"speed must be positive, got {speed}")
        self.acc = acc
        self.message = message
        self.speed = float(speed)
        """Time-lapse factor: samples leave every 10 ms / speed but keep their 100 Hz timestamps."""
        self.faults = faults or FaultConfig()
        self.stats = FirmwareStats()
        self._rng = np.random.default_rng(self.faults.seed)
        if isinstance(port_path_or_fd, int):
            self.fd, self._own_fd = port_path_or_fd, False
        else:
            self.fd = os.open(str(port_path_or_fd), os.O_WRONLY | os.O_NOCTTY | os.O_NONBLOCK)
            self._own_fd = True
        self.mav = mavlink2.MAVLink(_FaultyWriter(self.fd, self), srcSystem=SRC_SYSTEM,
                                    srcComponent=SRC_COMPONENT)
        if signing_key is not None:
            if len(signing_key) != 32:
                raise ValueError(f"signing key must be 32 bytes, got {len(signing_key)}")
            self.mav.signing.secret_key = bytes(signing_key)
            self.mav.signing.link_id = link_id
            # MAVLink signing time: 10 us units since 2015-01-01 00:00 UTC
            self.mav.signing.timestamp = int((time.time() - 1420070400) * 100_000)
            self.mav.signing.sign_outgoing = True
        self.boot_mono = time.monotonic()
        self.t0_boot_s: float | None = None
        """Boot-relative time (s) of sample 0, set when streaming starts."""
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._plan = self._fault_plan()

    # -- faults --------------------------------------------------------------------------
    def _fault_plan(self) -> tuple[np.ndarray, np.ndarray]:
        n = len(self.acc)
        f = self.faults
        drop = np.zeros(n, bool)
        nan = np.zeros(n, bool)
        rng = np.random.default_rng(f.seed + 1)
        if f.drop_prob > 0:
            for i in np.flatnonzero(rng.random(n) < f.drop_prob):
                drop[i:i + max(1, f.drop_burst)] = True
        for a, k in f.drop_ranges:
            drop[a:a + k] = True
        if f.nan_prob > 0:
            for i in np.flatnonzero(rng.random(n) < f.nan_prob):
                nan[i:i + max(1, f.nan_burst)] = True
        for a, k in f.nan_ranges:
            nan[a:a + k] = True
        return drop, nan

    # -- messages ------------------------------------------------------------------------
    def time_of_sample(self, k: int) -> float:
        """Boot-relative timestamp (s) that sample k carries."""
        assert self.t0_boot_s is not None
        return self.t0_boot_s + k / SAMPLE_RATE_HZ

    def _send_sample(self, k: int) -> None:
        drop, nan = self._plan
        if drop[k]:
            self.stats.samples_dropped += 1
            return
        a = self.acc[k].copy()
        if nan[k]:
            a[:] = np.nan
            self.stats.nan_samples += 1
        sat = self.faults.saturate_g
        if sat is not None:
            a = np.clip(a, -sat * G_MPS2, sat * G_MPS2)  # NaN stays NaN
        t_us = int(round(self.time_of_sample(k) * 1e6))
        if self.message == "highres":
            x, y, z = (float(v) for v in a)
            msg = mavlink2.MAVLink_highres_imu_message(t_us, x, y, z, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                                                       0.0, 0.0, 0.0, 0.0, 0b111, 0)
        else:
            mg = a / MG_TO_MPS2
            q = np.where(np.isfinite(mg), np.rint(np.clip(np.nan_to_num(mg), -INT16_SAT, INT16_SAT)),
                         INT16_INVALID).astype(int)
            msg = mavlink2.MAVLink_scaled_imu_message(t_us // 1000, int(q[0]), int(q[1]), int(q[2]),
                                                      0, 0, 0, 0, 0, 0, 0)
        self.mav.send(msg)
        self.stats.samples_sent += 1

    def _send_heartbeat(self) -> None:
        self.mav.heartbeat_send(mavlink2.MAV_TYPE_ONBOARD_CONTROLLER, mavlink2.MAV_AUTOPILOT_INVALID,
                                0, 0, mavlink2.MAV_STATE_ACTIVE)
        self.stats.heartbeats += 1

    # -- running -------------------------------------------------------------------------
    def run(self, duration_s: float | None = None, linger_s: float = 0.0) -> FirmwareStats:
        """Stream until the data ends (then idle ``linger_s``), ``duration_s`` passes, or stop()."""
        period = 1.0 / SAMPLE_RATE_HZ / self.speed
        start = time.monotonic()
        # sample 0 is stamped on the 10 ms grid of the boot clock
        self.t0_boot_s = round((start - self.boot_mono) * SAMPLE_RATE_HZ) / SAMPLE_RATE_HZ
        end = start + duration_s if duration_s is not None else None
        stop_at = start + self.faults.stop_after_s / self.speed if self.faults.stop_after_s is not None else None
        n = len(self.acc)
        k = 0
        while k < n and not self._stop.is_set():
            deadline = start + k * period
            if end is not None and deadline >= end:
                return self.stats
            if stop_at is not None and deadline >= stop_at:
                break  # silent sensor: idle until the end
            now = time.monotonic()
            if deadline > now:
                if self._stop.wait(deadline - now):
                    return self.stats
            else:
                self.stats.late_max_s = max(self.stats.late_max_s, now - deadline)
            if k % SAMPLE_RATE_HZ == 0:
                self._send_heartbeat()
            self._send_sample(k)
            k += 1
        idle_end = end if end is not None else (time.monotonic() + linger_s if k >= n else None)
        while not self._stop.is_set():
            remaining = None if idle_end is None else idle_end - time.monotonic()
            if remaining is not None and remaining <= 0:
                break
            self._stop.wait(remaining if remaining is not None else 1.0)
        return self.stats

    def start(self, duration_s: float | None = None) -> "ImuFirmware":
        self._stop.clear()
        self._thread = threading.Thread(target=self.run, args=(duration_s,), name="imu-firmware",
                                        daemon=True)
        self._thread.start()
        return self

    def stop(self, timeout: float = 2.0) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout)
            self._thread = None

    def wait(self, timeout: float | None = None) -> bool:
        """Wait for a start()ed stream to finish; True when it has."""
        if self._thread is None:
            return True
        self._thread.join(timeout)
        return not self._thread.is_alive()

    def close(self) -> None:
        self.stop()
        if self._own_fd:
            try:
                os.close(self.fd)
            except OSError:
                pass


# ----------------------------------------------------------------------------------------------
# `python -m firmware_sim imu ...` (the lead registers it with add_imu_parser)


def add_arguments(p: argparse.ArgumentParser) -> None:
    from edge_runtime.cli import hex_signing_key, positive_float, probability

    p.add_argument("--minutes", type=positive_float, default=3.0, help="length of the simulated drive (min)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--pty", action="store_true", help="create a pseudo-terminal pair and print the path to connect to")
    p.add_argument("--port", default=None, help="write to this existing serial device instead of --pty")
    p.add_argument("--message", choices=("highres", "scaled"), default="highres",
                   help="HIGHRES_IMU (m/s^2) or SCALED_IMU (mG)")
    p.add_argument("--sign-key", type=hex_signing_key("--sign-key"), default=None, help="MAVLink 2 signing key, 64 hex digits")
    p.add_argument("--drop", type=probability, default=0.0, help="probability per sample of a dropped burst")
    p.add_argument("--drop-burst", type=int, default=5, help="samples per dropped burst")
    p.add_argument("--corrupt", type=probability, default=0.0, help="probability per packet of a flipped byte")
    p.add_argument("--nan-burst", type=probability, default=0.0, help="probability per sample of a NaN burst (10 samples)")
    p.add_argument("--saturate", type=positive_float, default=None, metavar="G", help="clip every axis to +-G g")
    p.add_argument("--stop-after", type=positive_float, default=None, metavar="S", help="go silent after S seconds")
    p.add_argument("--linger", type=float, default=1.0, help="keep the line open this long after the data (s)")
    p.add_argument("--csv", default=None, metavar="FILE.csv",
                   help="stream this recording (t,ax,ay,az at 100 Hz) instead of simulating a drive")
    p.add_argument("--speed", type=positive_float, default=1.0,
                   help="time-lapse factor: send N times faster than real time (timestamps stay 100 Hz)")


def cmd(args) -> int:
    from firmware_sim.devices.wrist import simulate_drive

    if not args.pty and not args.port:
        raise ValueError("give --pty or --port PATH")
    if args.csv:
        from edge_runtime.wearable.sources import read_imu_csv

        rec = np.concatenate([b.acc_mps2 for b in read_imu_csv(args.csv)])  # InputError names the line
    else:
        rec = simulate_drive(args.minutes, args.seed)
    faults = FaultConfig(drop_prob=args.drop, drop_burst=max(1, args.drop_burst), corrupt_prob=args.corrupt,
                         nan_prob=args.nan_burst, saturate_g=args.saturate, stop_after_s=args.stop_after,
                         seed=args.seed)
    if args.pty:
        master, path = open_pty_pair()
        target: int | str = master
    else:
        master, path, target = None, args.port, args.port
    try:
        fw = ImuFirmware(rec, target, message=args.message, signing_key=args.sign_key, faults=faults,
                         speed=args.speed)
    except OSError as e:
        raise ValueError(f"cannot open {path!r}: {e.strerror or e}") from None
    print(path, flush=True)
    n = len(getattr(rec, "acc_mps2", rec))
    print(f"imu: {n} samples at 100 Hz as {args.message.upper()}_IMU"
          f"{' (signed)' if args.sign_key else ''} on {path}", file=sys.stderr, flush=True)
    try:
        st = fw.run(linger_s=args.linger)
    finally:
        fw.close()
        if master is not None:
            close_pty_pair(master)
    print(f"imu: sent {st.samples_sent} samples, dropped {st.samples_dropped}, NaN {st.nan_samples}, "
          f"corrupted {st.packets_corrupted} packets, {st.heartbeats} heartbeats, "
          f"tx overflow {st.tx_overflow}", file=sys.stderr)
    return 0


def main(argv: list[str] | None = None) -> int:
    from edge_runtime.cli import OneLineParser, run

    p = OneLineParser(prog="python -m firmware_sim imu", description="Simulated wrist IMU firmware (MAVLink).")
    add_arguments(p)
    args = p.parse_args(argv)
    return run(lambda: cmd(args), bad_input=(ValueError,))


if __name__ == "__main__":
    sys.exit(main())
