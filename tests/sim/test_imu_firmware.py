"""The simulated IMU firmware: pacing, heartbeats, timestamps, faults, command line."""
from __future__ import annotations

import os
import select
import threading
import time

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink2

from firmware_sim.devices import imu_firmware
from firmware_sim.devices.imu_firmware import FaultConfig, ImuFirmware, close_pty_pair, open_pty_pair


def read_messages(path: str, stop: threading.Event, out: list) -> None:
    """Raw reader of the slave side (no project code): parse every message with pymavlink."""
    fd = os.open(path, os.O_RDONLY | os.O_NOCTTY | os.O_NONBLOCK)
    mav = mavlink2.MAVLink(None)
    mav.robust_parsing = True
    try:
        while not stop.is_set():
            r, _, _ = select.select([fd], [], [], 0.05)
            if r:
                try:
                    data = os.read(fd, 4096)
                except BlockingIOError:
                    continue
                for m in mav.parse_buffer(data) or ():
                    out.append((time.monotonic(), m))
    finally:
        os.close(fd)


@pytest.fixture
def pty():
    master, path = open_pty_pair()
    yield master, path
    close_pty_pair(master)


def run_and_read(pty, acc, duration_s, **kw):
    master, path = pty
    stop, msgs = threading.Event(), []
    reader = threading.Thread(target=read_messages, args=(path, stop, msgs), daemon=True)
    reader.start()
    fw = ImuFirmware(acc, master, **kw)
    t0 = time.monotonic()
    fw.run(duration_s=duration_s)
    elapsed = time.monotonic() - t0
    time.sleep(0.1)
    stop.set()
    reader.join(2)
    return fw, msgs, elapsed


def test_paced_at_100_hz_with_1_hz_heartbeat(pty):
    acc = np.zeros((1000, 3), np.float32)
    fw, msgs, elapsed = run_and_read(pty, acc, 1.0)
    imu = [m for _, m in msgs if m.get_type() == "HIGHRES_IMU"]
    hb = [m for _, m in msgs if m.get_type() == "HEARTBEAT"]
    assert 80 <= len(imu) <= 120 and fw.stats.samples_sent == len(imu)
    assert 0.9 <= elapsed < 1.5  # it waited for real time and did not run ahead
    assert len(hb) == 1 and hb[0].type == mavlink2.MAV_TYPE_ONBOARD_CONTROLLER
    t = np.array([m.time_usec for m in imu])
    assert np.all(np.diff(t) == 10_000)  # boot-relative sample clock, no drift
    assert t[0] % 10_000 == 0 and t[0] < 10_000_000
    assert all(m.get_srcComponent() == mavlink2.MAV_COMP_ID_IMU for m in imu)


def test_two_seconds_two_heartbeats_scaled_timestamps(pty):
    acc = np.full((1000, 3), 9.80665, np.float32)
    fw, msgs, _ = run_and_read(pty, acc, 2.0, message="scaled")
    imu = [m for _, m in msgs if m.get_type() == "SCALED_IMU"]
    assert sum(m.get_type() == "HEARTBEAT" for _, m in msgs) == 2
    assert 160 <= len(imu) <= 240
    assert all(m.xacc == 1000 and m.zacc == 1000 for m in imu)  # 1 g = 1000 mG
    assert np.all(np.diff([m.time_boot_ms for m in imu]) == 10)


def test_signed_packets_carry_a_signature(pty):
    acc = np.zeros((20, 3), np.float32)
    _, msgs, _ = run_and_read(pty, acc, 0.3, signing_key=bytes(range(32)))
    assert msgs and all(m.get_header().incompat_flags & mavlink2.MAVLINK_IFLAG_SIGNED for _, m in msgs)


def test_catches_up_without_drift():
    """A late start sends the overdue samples at once, then keeps the original grid."""
    master, path = open_pty_pair()
    try:
        fw = ImuFirmware(np.zeros((30, 3)), master)
        sleep = time.sleep
        calls = []
        orig = fw._send_sample

        def slow_first(k):
            calls.append((k, time.monotonic()))
            if k == 0:
                sleep(0.1)  # a hiccup of 10 periods
            orig(k)

        fw._send_sample = slow_first
        t0 = time.monotonic()
        fw.run()
        total = time.monotonic() - t0
    finally:
        close_pty_pair(master)
    assert [k for k, _ in calls] == list(range(30))
    assert fw.stats.late_max_s >= 0.05
    assert 0.28 <= total < 0.6  # 30 samples still end at ~0.3 s: no accumulated drift


def test_fault_plan_deterministic_and_ranges():
    master, _ = open_pty_pair()
    try:
        f = FaultConfig(drop_prob=0.02, drop_burst=3, nan_prob=0.01, nan_burst=4, seed=7,
                        drop_ranges=[(0, 2)], nan_ranges=[(500, 1)])
        a = ImuFirmware(np.zeros((1000, 3)), master, faults=f)._plan
        b = ImuFirmware(np.zeros((1000, 3)), master, faults=f)._plan
    finally:
        close_pty_pair(master)
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert a[0][:2].all() and a[1][500]
    assert 20 < a[0].sum() < 120 and 10 < a[1].sum() < 100


def test_bad_arguments_rejected():
    master, _ = open_pty_pair()
    try:
        with pytest.raises(ValueError):
            ImuFirmware(np.zeros((10, 2)), master)
        with pytest.raises(ValueError):
            ImuFirmware(np.zeros((10, 3)), master, message="raw")
        with pytest.raises(ValueError):
            ImuFirmware(np.zeros((10, 3)), master, signing_key=b"short")
    finally:
        close_pty_pair(master)


def test_unread_line_never_blocks_the_firmware():
    master, _ = open_pty_pair()
    try:
        fw = ImuFirmware(np.zeros((10, 3)), master)
        t0 = time.monotonic()
        for _ in range(5000):  # ~250 kB, far more than the pty buffer
            fw.mav.heartbeat_send(0, 0, 0, 0, 0)
        assert time.monotonic() - t0 < 5
        assert fw.stats.tx_overflow > 0
    finally:
        close_pty_pair(master)


def test_cli_prints_the_path_and_streams(capsys):
    rc = imu_firmware.main(["--minutes", "0.005", "--seed", "1", "--pty", "--linger", "0",
                            "--message", "scaled", "--drop", "0.1", "--corrupt", "0.1", "--nan-burst", "0.05",
                            "--saturate", "2", "--sign-key", "00" * 32])
    out, err = capsys.readouterr()
    assert rc == 0
    assert out.strip().startswith("/dev/pts/")
    assert "samples" in err


@pytest.mark.parametrize("argv", [["--pty", "--sign-key", "zz"], ["--pty", "--drop", "2"], ["--minutes", "0.01"]])
def test_cli_bad_input_one_line(argv, capsys):
    try:
        rc = imu_firmware.main(argv)
    except SystemExit as e:  # argparse errors
        rc = e.code
    assert rc == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "Traceback" not in err
