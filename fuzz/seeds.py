"""Real valid inputs the mutators start from, made once per process.

* a drive CSV: the simulated wrist (firmware_sim.devices.wrist) around real distraction events;
* MAVLink 2 packets: the simulated IMU firmware (firmware_sim.devices.imu_firmware) writing
  HIGHRES_IMU / SCALED_IMU / HEARTBEAT, signed and unsigned, into a pipe;
* CAN frames: the runtime's own AlertEncoder (DISTRACTION_ALERT, WEARABLE_STATUS).
"""
from __future__ import annotations

import functools
import os

import numpy as np

SIGNING_KEY = bytes(range(32))
"""The key the MAVLink seeds are signed with (and the fuzzed decoder checks against)."""
SIGNING_T0 = 36_000_000_000_000
"""MAVLink signing time of the seeds (10 us units since 2015: late 2026), fixed so that a run is
repeatable; the fuzzed decoder's own clock is set to it."""
TAIL_T0_S = 100_000.0
"""Boot time of the genuine packets appended after an input: later than anything in the seeds."""


@functools.lru_cache(maxsize=None)
def recording():
    """A 2-minute simulated drive (seed 5) of the wrist."""
    from firmware_sim.devices.wrist import simulate_drive

    return simulate_drive(2.0, 5)


def drive() -> tuple[np.ndarray, np.ndarray]:
    """(t_s, acc_mps2) of :func:`recording`."""
    rec = recording()
    acc = np.asarray(rec.acc_mps2, dtype=np.float64)
    return np.arange(len(acc)) / rec.sample_rate_hz, acc


def csv_bytes(t_s: np.ndarray, acc: np.ndarray) -> bytes:
    rows = [f"{t:.2f},{x:.4f},{y:.4f},{z:.4f}" for t, (x, y, z) in zip(t_s, acc)]
    return ("t,ax,ay,az\n" + "\n".join(rows) + "\n").encode()


@functools.lru_cache(maxsize=None)
def event_starts() -> list[int]:
    """First samples of stretches of the drive that each contain a detector trigger (so mutations reach the model)."""
    rec = recording()
    return [max(0, int(e["start_s"] * rec.sample_rate_hz) - 300) for e in rec.truth_json()["events"]][:4] or [0]


def drive_csvs(n_rows: int = 1200) -> tuple[bytes, ...]:
    """The stretches of :func:`event_starts` as CSV recordings."""
    t, acc = drive()
    return tuple(csv_bytes(t[s:s + n_rows], acc[s:s + n_rows]) for s in event_starts())


def firmware_bytes(acc: np.ndarray, message: str, key: bytes | None, t0_boot_s: float, signing_t: int) -> bytes:
    """What the simulated IMU firmware writes for these samples: a heartbeat, then one packet each."""
    from firmware_sim.devices.imu_firmware import ImuFirmware

    r, w = os.pipe()
    try:
        fw = ImuFirmware(acc, w, message=message, signing_key=key)
        fw.mav.signing.timestamp = signing_t
        fw.t0_boot_s = t0_boot_s
        fw._send_heartbeat()
        for k in range(len(acc)):
            fw._send_sample(k)
        os.close(w)
        w = -1
        chunks = []
        while chunk := os.read(r, 65536):
            chunks.append(chunk)
        return b"".join(chunks)
    finally:
        os.close(r)
        if w >= 0:
            os.close(w)


@functools.lru_cache(maxsize=None)
def mavlink_streams(n_samples: int = 120) -> tuple[bytes, ...]:
    """Byte streams of the simulated IMU firmware: highres signed, highres unsigned, scaled signed."""
    _, acc = drive()
    return tuple(firmware_bytes(acc[:n_samples], message, key, 10.0, SIGNING_T0)
                 for message, key in (("highres", SIGNING_KEY), ("highres", None), ("scaled", SIGNING_KEY)))


@functools.lru_cache(maxsize=None)
def signed_tail(n_samples: int) -> bytes:
    """Genuine signed HIGHRES_IMU packets stamped after every seed (boot time and signing time)."""
    _, acc = drive()
    return firmware_bytes(acc[:n_samples], "highres", SIGNING_KEY, TAIL_T0_S, SIGNING_T0 + 10**9)


@functools.lru_cache(maxsize=None)
def alert_frames() -> tuple[tuple[int, bytes], ...]:
    """(arbitration id, data) of real DISTRACTION_ALERT and WEARABLE_STATUS frames."""
    from types import SimpleNamespace

    from edge_runtime.wearable.alerts import AlertEncoder

    enc = AlertEncoder()
    frames = []
    for k, label in enumerate(["Phone", "Drink", "Other", "Radio"] * 3):
        d = SimpleNamespace(label=label, confidence=0.5 + k / 30, status="alert", t_trigger_s=1.0, t_alert_s=7.0,
                            compute_us=800.0)
        m = enc.encode_alert(d)
        frames.append((m.arbitration_id, bytes(m.data)))
    for state in ("running", "degraded", "running"):
        m = enc.encode_status(state=state, dropped_samples=3, uptime_s=12.0)
        frames.append((m.arbitration_id, bytes(m.data)))
    return tuple(frames)
