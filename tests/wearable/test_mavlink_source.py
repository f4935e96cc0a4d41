"""MavlinkImuSource against the simulated IMU firmware over a real pseudo-terminal pair."""
from __future__ import annotations

import os
import time

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink2

from edge_runtime.wearable.mavlink_source import MG_TO_MPS2, MavlinkImuSource, SourceStatus
from edge_runtime.wearable.sources import ImuBlock
from firmware_sim.devices.imu_firmware import FaultConfig, ImuFirmware, close_pty_pair, open_pty_pair

G = 9.80665
KEY = bytes(range(32))


def ramp(n: int = 60) -> np.ndarray:
    """Distinct, in-range (< 2 g) samples whose values identify their index."""
    k = np.arange(n)
    return np.stack([k * 0.05 - 3.0, 4 * np.sin(k * 0.3), 9.0 + np.cos(k * 0.7)], 1).astype(np.float32)


@pytest.fixture
def pty():
    master, path = open_pty_pair()
    yield master, path
    close_pty_pair(master)


def stream(acc, pty, *, message="highres", key=None, src_key=None, faults=None, max_s=None, **src_kw):
    """Run the firmware to the end of ``acc``; collect events until the sensor goes silent."""
    master, path = pty
    src = MavlinkImuSource(path, signing_key=src_key, **src_kw)
    fw = ImuFirmware(acc, master, message=message, signing_key=key, faults=faults)
    events, arrival = [], []
    state = None
    stop_after = faults is not None and faults.stop_after_s is not None
    max_s = max_s if max_s is not None else len(acc) / 100 + 0.6
    fw.start()
    try:
        for ev in src.blocks(duration_s=max_s):
            events.append(ev)
            arrival.append(time.monotonic())
            if isinstance(ev, SourceStatus):
                state = ev.state
            if state == "silent" and (stop_after or fw.wait(0)):
                break
    finally:
        fw.stop()
        src.close()
    return fw, src, events, arrival


def samples(events):
    blocks = [e for e in events if isinstance(e, ImuBlock)]
    t = np.concatenate([b.t0_s + np.arange(len(b.acc_mps2)) / 100.0 for b in blocks]) if blocks else np.zeros(0)
    a = np.concatenate([b.acc_mps2 for b in blocks]) if blocks else np.zeros((0, 3), np.float32)
    return blocks, t, a


def index_of(fw, t):
    return np.rint((t - fw.t0_boot_s) * 100).astype(int)


def test_highres_roundtrip_exact_in_order(pty):
    acc = ramp()
    fw, src, events, arrival = stream(acc, pty)
    blocks, t, a = samples(events)
    assert src.stats.samples == len(acc) and len(a) == len(acc)
    assert a.dtype == np.float32 and np.array_equal(a, acc)  # exact to float32
    assert np.all(np.diff(t) > 0)
    assert np.allclose(np.diff(t), 0.01)
    assert t[0] == pytest.approx(fw.t0_boot_s)  # boot-relative, not wall clock
    assert t[0] < 60.0
    assert blocks[0].continuous is False and all(b.continuous for b in blocks[1:])
    # each read is handed over at once (a capture's last sample must not wait for a full block),
    # stamped with its host arrival time, which precedes the moment the caller gets it
    assert max(len(b.acc_mps2) for b in blocks) <= 10
    got = [when for e, when in zip(events, arrival) if isinstance(e, ImuBlock)]
    assert all(b.rx_monotonic_s is not None and b.rx_monotonic_s <= when for b, when in zip(blocks, got))
    assert all(b2.rx_monotonic_s >= b1.rx_monotonic_s for b1, b2 in zip(blocks, blocks[1:]))
    assert src.stats.crc_errors == src.stats.dropped == src.stats.out_of_order == 0
    assert src.stats.heartbeats >= 1


def test_a_read_period_hands_over_what_arrived_meanwhile(pty):
    """[imu] read_period_s: the line is read at most every period, the samples that arrived meanwhile
    go out as one block (the same samples, in order), each stamped no later than it arrived: with the
    previous read's time, before the wait began."""
    acc = ramp(100)
    fw, src, events, arrival = stream(acc, pty, read_period_s=0.05)
    blocks, t, a = samples(events)
    assert np.array_equal(a, acc) and np.allclose(np.diff(t), 0.01)
    assert len(blocks) <= 40 and np.median([len(b.acc_mps2) for b in blocks]) >= 3  # about 5 per read at 100 Hz
    got = [when for e, when in zip(events, arrival) if isinstance(e, ImuBlock)]
    waited = [when - b.rx_monotonic_s for b, when in zip(blocks, got)]
    assert min(waited) >= 0 and np.median(waited) >= 0.04  # stamped before the wait (a late loop waits less)
    # the line fell silent at the end: reported as promised, from the stamp of the last samples
    silent = next(e for e in events if isinstance(e, SourceStatus) and e.state == "silent")
    assert src.silence_timeout_s <= silent.since_s < src.silence_timeout_s + 0.06  # + a read timeout


def test_scaled_roundtrip_within_quantisation(pty):
    acc = ramp()
    fw, src, events, _ = stream(acc, pty, message="scaled")
    _, t, a = samples(events)
    assert len(a) == len(acc)
    assert np.max(np.abs(a - acc)) <= 0.5 * MG_TO_MPS2 + 1e-5
    assert np.allclose(np.diff(t), 0.01)
    assert src.stats.saturated == 0


def test_corrupted_bytes_fail_crc_and_never_deliver_wrong_samples(pty):
    acc = ramp(80)
    fw, src, events, _ = stream(acc, pty, faults=FaultConfig(corrupt_prob=0.25, seed=3))
    blocks, t, a = samples(events)
    assert fw.stats.packets_corrupted > 0
    assert src.stats.crc_errors > 0 and src.stats.bad_bytes > 0
    assert 0 < len(a) < len(acc)
    k = index_of(fw, t)
    assert np.array_equal(a, acc[k])  # every delivered sample is the right one
    assert src.stats.dropped == len(acc) - len(a) - (len(acc) - 1 - k[-1]) - k[0]
    assert any(not b.continuous for b in blocks[1:])


def test_dropped_samples_break_continuity(pty):
    acc = ramp()
    fw, src, events, _ = stream(acc, pty, faults=FaultConfig(drop_ranges=[(30, 5)]))
    blocks, t, a = samples(events)
    assert src.stats.dropped == 5 and src.stats.gaps == 1
    assert len(a) == len(acc) - 5
    after = [b for b in blocks if b.t0_s == pytest.approx(fw.time_of_sample(35))]
    assert len(after) == 1 and after[0].continuous is False
    assert sum(not b.continuous for b in blocks) == 2  # stream start + the gap
    assert np.array_equal(a, acc[index_of(fw, t)])


@pytest.mark.parametrize("message", ["highres", "scaled"])
def test_nan_burst_passed_through(pty, message):
    acc = ramp()
    fw, src, events, _ = stream(acc, pty, message=message, faults=FaultConfig(nan_ranges=[(30, 4)]))
    _, t, a = samples(events)
    k = index_of(fw, t)
    bad = np.isnan(a).any(1)
    assert list(k[bad]) == [30, 31, 32, 33]
    assert np.isnan(a[bad]).all()
    assert src.stats.nan_samples == 4 and len(a) == len(acc)


def test_saturation_clipped_and_counted(pty):
    acc = ramp()
    acc[20:25, 0] = 3.5 * G
    acc[40, 2] = -2.5 * G
    fw, src, events, _ = stream(acc, pty, faults=FaultConfig(saturate_g=2.0), range_mps2=2 * G)
    _, _, a = samples(events)
    assert np.max(np.abs(a)) == pytest.approx(2 * G, rel=1e-6)
    assert src.stats.saturated == 6 and src.stats.out_of_range == 0


def test_the_configured_range_decides_saturated_and_out_of_range(pty):
    acc = ramp()
    acc[20, 0] = 2.5 * G  # inside the default 16 g: an ordinary sample
    acc[30, 1] = 156.9  # at full scale (16 g as configured): saturated, passed on
    acc[40:42, 2] = 3.4e38  # finite in float64, inf in float32, far beyond the range: NaN, counted
    acc[50, 0] = 200.0  # beyond 16 g (156.9 m/s^2): impossible for this sensor
    fw, src, events, _ = stream(acc, pty)
    _, t, a = samples(events)
    k = index_of(fw, t)
    assert src.stats.saturated == 1 and src.stats.out_of_range == 3
    assert list(k[np.isnan(a).any(1)]) == [40, 41, 50]
    assert np.nanmax(np.abs(a)) == pytest.approx(156.9, rel=1e-6)


def test_scaled_int16_limit_counted(pty):
    acc = ramp()
    acc[10:13, 1] = 40 * G  # beyond int16 mG: the firmware clips to +-32767 mG
    _, src, events, _ = stream(acc, pty, message="scaled", range_mps2=50 * G)
    _, _, a = samples(events)
    assert src.stats.saturated == 3
    assert np.allclose(a[10:13, 1], 32767 * MG_TO_MPS2)


def test_silent_sensor_reported_quickly(pty):
    acc = ramp(300)
    fw, src, events, arrival = stream(acc, pty, faults=FaultConfig(stop_after_s=0.3))
    idx = [i for i, e in enumerate(events) if isinstance(e, SourceStatus) and e.state == "silent"]
    assert idx, "no silent status"
    last_block = max(i for i, e in enumerate(events[: idx[0]]) if isinstance(e, ImuBlock))
    assert arrival[idx[0]] - arrival[last_block] < 0.5
    assert events[idx[0]].since_s >= 0.2
    assert src.stats.silent_events >= 1
    assert 10 <= src.stats.samples < 300


def test_no_sensor_at_all_does_not_block(pty):
    _, path = pty
    src = MavlinkImuSource(path, silence_timeout_s=0.1)
    t0 = time.monotonic()
    try:
        gen = src.blocks(duration_s=3.0)
        ev = next(gen)
        t1 = time.monotonic()
        again = next(gen)  # the caller keeps getting control while the sensor is silent
        t2 = time.monotonic()
    finally:
        src.close()
    assert isinstance(ev, SourceStatus) and ev.state == "silent"
    assert t1 - t0 < 1.0 and t2 - t1 < 0.5
    assert isinstance(again, SourceStatus) and again.state == "silent" and again.since_s > ev.since_s
    assert src.stats.silent_events == 1


def test_signed_stream_accepted(pty):
    acc = ramp(60)
    _, src, events, _ = stream(acc, pty, key=KEY, src_key=KEY)
    _, _, a = samples(events)
    assert np.array_equal(a, acc)
    assert src.stats.signature_failures == 0


@pytest.mark.parametrize("fw_key", [None, bytes(32)], ids=["unsigned", "wrong-key"])
def test_unsigned_or_wrongly_signed_rejected(pty, fw_key):
    acc = ramp(60)
    _, src, events, _ = stream(acc, pty, key=fw_key, src_key=KEY)
    assert src.stats.samples == 0 and not any(isinstance(e, ImuBlock) for e in events)
    assert src.stats.signature_failures >= 60


def test_duplicate_and_out_of_order_timestamps_dropped(pty):
    master, path = pty
    src = MavlinkImuSource(path, silence_timeout_s=0.1)
    tx = mavlink2.MAVLink(None, 1, 200)
    times_ms = [1000, 1010, 1020, 1020, 1015, 1030, 1040, 10, 20]  # dup, backwards, then a reboot
    buf = b"".join(bytes(mavlink2.MAVLink_scaled_imu_message(t, t, 0, 1000, 0, 0, 0, 0, 0, 0).pack(tx))
                   for t in times_ms)
    os.write(master, buf)
    events = []
    try:
        for ev in src.blocks(duration_s=3.0):
            events.append(ev)
            if isinstance(ev, SourceStatus):
                break
    finally:
        src.close()
    blocks, t, a = samples(events)
    assert src.stats.out_of_order == 2 and src.stats.reboots == 1
    assert np.allclose(t, [1.0, 1.01, 1.02, 1.03, 1.04, 0.01, 0.02])
    assert np.allclose(a[:, 0] / MG_TO_MPS2, [1000, 1010, 1020, 1030, 1040, 10, 20], atol=1e-3)
    assert [b.continuous for b in blocks] == [False, False]


def _decoder_and_firmware_bytes(key):
    from edge_runtime.wearable.mavlink_source import ImuPacketDecoder
    from fuzz.seeds import firmware_bytes

    t_sign = 36_000_000_000_000
    dec = ImuPacketDecoder(signing_key=key)
    dec.mav.signing.timestamp = t_sign
    return dec, lambda acc, t0_s, signing_t=t_sign: firmware_bytes(acc, "highres", key, t0_s, signing_t)


def test_a_forged_far_future_packet_does_not_starve_a_signed_line():
    key = bytes(range(32))
    dec, packets = _decoder_and_firmware_bytes(key)
    acc = ramp(100)
    forged = packets(acc[:1], 1.0, signing_t=2**47)  # a heartbeat and a sample stamped far in the future ...
    forged = forged[forged.index(b"\xfd", 1):-6] + bytes(6)  # ... the sample alone, its signature forged
    events: list = []
    dec.feed(forged + packets(acc, 2.0), 0.0, events)
    dec.flush(events)
    assert dec.stats.samples == 100 and dec.stats.signature_failures == 1


def test_a_stray_start_byte_loses_no_good_packet():
    dec, packets = _decoder_and_firmware_bytes(bytes(range(32)))
    stream = packets(ramp(100), 2.0)
    cut = len(stream) // 2
    cut = stream.index(b"\xfd", cut)  # a packet boundary
    events: list = []
    dec.feed(stream[:cut] + b"\xfd" + stream[cut:], 0.0, events)
    dec.flush(events)
    assert dec.stats.samples == 100



def test_samples_inside_the_range_pass_as_screen_samples_would_pass_them():
    """The decoder skips screen_samples for a sample well inside the range: around the range's limit
    (just inside, at it, within the tolerance, beyond), with NaN and infinities among them, every
    value and count is what screen_samples makes of the whole stream."""
    from edge_runtime.wearable.mavlink_source import ImuPacketDecoder
    from edge_runtime.wearable.sources import screen_samples
    from fuzz.seeds import firmware_bytes

    range_mps2 = 100.0
    acc = np.random.default_rng(3).uniform(-99.0, 99.0, (60, 3)).astype(np.float32)
    acc[5:19, 1] = [99.9999, 99.99995, 100.0, 100.00005, 100.1, -100.0, -99.99995, 150.0, np.nan, np.inf,
                    -np.inf, 99.9, -99.9, 0.0]
    dec = ImuPacketDecoder(range_mps2=range_mps2)
    events: list = []
    dec.feed(firmware_bytes(acc, "highres", None, 2.0, 0), 0.0, events)
    dec.flush(events)
    got = np.concatenate([e.acc_mps2 for e in events if isinstance(e, ImuBlock)])
    want, out_of_range, saturated = screen_samples(acc, range_mps2)
    assert np.array_equal(got, want, equal_nan=True)
    assert (dec.stats.samples, dec.stats.out_of_range, dec.stats.saturated) == (len(acc), out_of_range, saturated)
    assert out_of_range == 4 and saturated == 6  # beyond: 100.1, 150, +-inf; at scale: 99.9999 .. 100.00005, -100, -99.99995


# ---------------------------------------------------------------- the read schedule on a virtual clock
class _Clock:
    """``time`` for the source: reads and sleeps move a virtual clock, so the schedule is exact."""

    def __init__(self, now_s: float = 100.0):
        self.now = now_s

    def monotonic(self) -> float:
        return self.now

    def sleep(self, dt_s: float) -> None:
        self.now += max(dt_s, 0.0) + 0.0002  # a real sleep overshoots a little


class _Line:
    """A serial line whose bytes arrive at given virtual times (pyserial's read: up to n bytes, waiting
    at most the timeout for the first)."""

    def __init__(self, clock: _Clock, arrivals, timeout_s: float):
        self.clock, self.arrivals, self.timeout_s = clock, sorted(arrivals, key=lambda a: a[0]), timeout_s
        self.buf, self.i = bytearray(), 0

    def _deliver(self) -> None:
        while self.i < len(self.arrivals) and self.arrivals[self.i][0] <= self.clock.now:
            self.buf += self.arrivals[self.i][1]
            self.i += 1

    @property
    def in_waiting(self) -> int:
        self._deliver()
        return len(self.buf)

    def read(self, n: int = 1) -> bytes:
        self._deliver()
        if not self.buf:
            deadline = self.clock.now + self.timeout_s
            if self.i < len(self.arrivals) and self.arrivals[self.i][0] <= deadline:
                self.clock.now = self.arrivals[self.i][0]
            else:
                self.clock.now = deadline
            self._deliver()
        out = bytes(self.buf[:n])
        del self.buf[:n]
        return out

    def close(self) -> None:
        pass


def _packets(n: int) -> list[bytes]:
    """The firmware's HIGHRES_IMU packets of ``ramp(n)``, one per sample, stream times 2.00, 2.01, ..."""
    r, w = os.pipe()
    fw = ImuFirmware(ramp(n), w, message="highres", signing_key=None)
    fw.t0_boot_s = 2.0
    out = []
    for k in range(n):
        fw._send_sample(k)
        out.append(os.read(r, 65536))
    os.close(r)
    os.close(w)
    return out


def _run(monkeypatch, arrivals, until_s, stall_s=None, **src_kw):
    """(virtual time, event) for each event of a source on ``arrivals`` until ``until_s``; the consumer
    takes 0.2 ms per event, ``stall_s`` {block index: seconds} longer for some blocks."""
    import edge_runtime.wearable.mavlink_source as ms

    clock = _Clock()
    monkeypatch.setattr(ms, "time", clock)
    monkeypatch.setattr(ms.serial, "Serial", lambda path, baudrate, timeout: _Line(clock, arrivals, timeout))
    src = MavlinkImuSource("virtual", **src_kw)
    got, n_blocks = [], 0
    for event in src.blocks():
        got.append((clock.now, event))
        clock.now += 0.0002 + ((stall_s or {}).get(n_blocks, 0.0) if isinstance(event, ImuBlock) else 0.0)
        n_blocks += isinstance(event, ImuBlock)
        if clock.now >= until_s:
            break
    return got


BOX = {"silence_timeout_s": 0.1, "read_period_s": 0.05}  # the box's [imu] defaults


def test_a_stray_byte_after_the_last_sample_does_not_delay_the_silence_report(monkeypatch):
    """docs/integrator.md: sensor_silent within 200 ms of the last sample. A byte of line noise just
    after it (a cable pulled, a sensor resetting) must not make the source sleep a read period and then
    block a read timeout on top of it."""
    for stray_after_s in (0.0, 0.01, 0.03, 0.045, 0.07, 0.095, 0.142):
        arr = [(100.0 + k * 0.01 * 1.0013, p) for k, p in enumerate(_packets(77))]  # a sensor clock 1300 ppm fast
        last_s = arr[-1][0]
        got = _run(monkeypatch, arr + [(last_s + stray_after_s, b"\x00")], last_s + 0.5, **BOX)
        t, ev = next((t, e) for t, e in got if isinstance(e, SourceStatus) and e.state == "silent")
        assert BOX["silence_timeout_s"] <= t - last_s <= 0.2, (stray_after_s, t - last_s)
        assert BOX["silence_timeout_s"] <= ev.since_s <= t - last_s + 1e-9


@pytest.mark.parametrize("period_s", [0.0, 0.05])
def test_a_gap_shorter_than_the_silence_timeout_is_never_silence(monkeypatch, period_s):
    """The stream pauses and catches up (nothing lost): a gap between two samples' arrivals shorter than
    silence_timeout_s is no silence, wherever it falls between the reads."""
    pk = _packets(120)
    for m in range(40, 46):
        for hold_s in (0.05, 0.07, 0.085):  # arrivals m -> m + 1: 10 ms + hold
            arr = [(100.0 + k * 0.01 + (hold_s if k > m else 0.0), p) for k, p in enumerate(pk)]
            got = _run(monkeypatch, arr, arr[-1][0] + 0.05, silence_timeout_s=0.1, read_period_s=period_s)
            # (the stream's real end is silence: only what came before it counts)
            assert not any(isinstance(e, SourceStatus) for t, e in got if t < arr[-1][0] + 0.1), (m, hold_s)
            assert sum(len(e.acc_mps2) for _, e in got if isinstance(e, ImuBlock)) == len(pk)


@pytest.mark.parametrize("period_s", [0.0, 0.05])
def test_a_block_is_never_stamped_after_its_samples_arrived(monkeypatch, period_s):
    """rx_monotonic_s is the latency's start: never later than the block's first sample arrived, even
    when the loop once takes longer than the read period (a capture's classification, a GC pause), and
    never going back."""
    pk = _packets(150)
    arr = [(100.0 + k * 0.01 * 1.0013, p) for k, p in enumerate(pk)]
    for stall_s in (0.0, 0.045, 0.055, 0.08, 0.2):
        got = _run(monkeypatch, arr, arr[-1][0] + 0.2, stall_s={10: stall_s}, silence_timeout_s=0.1,
                   read_period_s=period_s)
        blocks = [e for _, e in got if isinstance(e, ImuBlock)]
        assert sum(len(b.acc_mps2) for b in blocks) == len(pk)
        for b in blocks:
            first = int(round((b.t0_s - blocks[0].t0_s) * 100))
            assert b.rx_monotonic_s <= arr[first][0] + 1e-9, (stall_s, first)
        assert all(b2.rx_monotonic_s >= b1.rx_monotonic_s for b1, b2 in zip(blocks, blocks[1:]))
        if period_s and stall_s == 0.0:  # the line is read about every period: about 5 samples a block
            assert np.median([len(b.acc_mps2) for b in blocks]) >= 4


def test_a_read_period_longer_than_the_read_timeout_is_refused(pty):
    with pytest.raises(ValueError, match="read_period_s"):
        MavlinkImuSource(pty[1], read_period_s=0.2)
