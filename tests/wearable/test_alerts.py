"""wearable/alerts.py: the vehicle DBC, cantools encoding, the heartbeat and its status, bus errors."""
from __future__ import annotations

import json
import subprocess
import sys
import threading
import time
from types import SimpleNamespace

import can
import numpy as np
import pytest

from edge_runtime.canbus.bus import CanLinkError, DeferredBus
from edge_runtime.canbus.dbc import load_dbc
from edge_runtime.canbus.e2e import E2EChecker
from edge_runtime.core.manifest import sha256_file
from edge_runtime.errors import ModelIntegrityError
from edge_runtime.wearable import alerts as alerts_module
from edge_runtime.wearable.alerts import (
    DBC_PATH,
    DBC_SCHEDULE_PATH,
    AlertEncoder,
    AlertPublisher,
    Clock,
    FrameSchedule,
    Repetition,
    WearableStatus,
    check_frame_schedule,
    load_vehicle_dbc,
)
from edge_runtime.wearable.labels import CLASSES


def decision(label="Phone", conf=0.87, alerted=True, status="alert"):
    return SimpleNamespace(t_trigger_s=10.0, t_alert_s=10.75, label=label, confidence=conf, alerted=alerted,
                           status=status, probs={}, compute_us=2500.0)


def test_dbc_loads_with_version_and_labels():
    db = load_vehicle_dbc()
    assert db.version == "1.4.0"
    alert = db.get_message_by_name("DISTRACTION_ALERT")
    status = db.get_message_by_name("WEARABLE_STATUS")
    assert (alert.frame_id, status.frame_id) == (0x3A0, 0x3A1)
    assert status.cycle_time == 100
    assert not alert.is_extended_frame and alert.length == 8
    for msg in (alert, status):
        for sig in msg.signals:
            assert sig.comment, f"{msg.name}.{sig.name} has no comment"
    choices = {str(v) for v in alert.get_signal_by_name("Class").choices.values()}
    assert set(CLASSES) <= choices
    enc = AlertEncoder(db)
    for label in CLASSES:
        assert enc.decode(enc.encode_alert(decision(label)))["Class"] == label


@pytest.mark.slow
def test_cantools_dump_cli():
    out = subprocess.run([sys.executable, "-m", "cantools", "dump", str(DBC_PATH)], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    assert "DISTRACTION_ALERT" in out.stdout and "WEARABLE_STATUS" in out.stdout


def test_alert_round_trip():
    enc = AlertEncoder()
    msg = enc.encode_alert(decision("Drink", 0.873))
    assert msg.arbitration_id == 0x3A0 and len(msg.data) == 8 and not msg.is_extended_id
    d = enc.decode(msg)
    assert d["Class"] == "Drink" and d["Status"] == "alert"
    assert d["Confidence"] == pytest.approx(0.873, abs=0.005)
    assert d["TimeSinceTrigger"] == 753  # 750 ms capture + 2.5 ms compute
    assert d["AlertSeq"] == 0 and enc.decode(enc.encode_alert(decision()))["AlertSeq"] == 1
    st = enc.decode(enc.encode_status("degraded", "nan_samples", dropped_samples=70000, model_version=3, uptime_s=12.4))
    assert (st["State"], st["SensorHealth"], st["DroppedSamples"], st["ModelVersion"], st["Uptime_s"]) == \
        ("degraded", "nan_samples", 65535, 3, 12)


class RaisingBus(can.BusABC):
    def __init__(self):
        super().__init__(channel="x")
        self.calls = 0
        self.fail = True

    def send(self, msg, timeout=None):
        self.calls += 1
        if self.fail:
            raise can.CanOperationError("bus off")

    def _recv_internal(self, timeout):
        return None, False


def test_heartbeat_rate_and_log(tmp_path):
    bus = can.Bus(interface="virtual", channel="hb", receive_own_messages=False)
    rx = can.Bus(interface="virtual", channel="hb")
    path = tmp_path / "frames.log"
    pub = AlertPublisher(bus, heartbeat_period_s=0.1, log_path=path, status=WearableStatus(model_version=2))
    pub.status.count_samples(100)  # samples arrived: the status vouches for the sensor
    pub.start()
    time.sleep(0.5)
    assert pub.on_decision(decision())
    assert not pub.on_decision(decision(alerted=False, status="uncertain"))
    pub.close()
    rx_msgs = []
    while (m := rx.recv(0.05)) is not None:
        rx_msgs.append(m)
    rx.shutdown()
    hb = [m for m in rx_msgs if m.arbitration_id == 0x3A1]
    assert 3 <= len(hb) <= 8, len(hb)
    alerts = [m for m in rx_msgs if m.arbitration_id == 0x3A0]
    assert len(alerts) == 5 and {AlertEncoder().decode(m)["AlertSeq"] for m in alerts} == {0}  # 1 + 4 copies
    assert pub.frames_sent == len(rx_msgs) and pub.send_errors == 0
    chk = E2EChecker(load_vehicle_dbc())
    assert all(chk.check(m).valid for m in hb)
    assert AlertEncoder().decode(hb[-1])["State"] == "running" and AlertEncoder().decode(hb[-1])["ModelVersion"] == 2
    logged = list(can.LogReader(str(path)))
    assert len(logged) == pub.frames_sent


class FakeClock:
    """``time.monotonic`` for the publisher: moved by the test only (its thread's waits stay real)."""

    def __init__(self, now_s: float = 1000.0):
        self.now_s = now_s

    def __call__(self) -> float:
        return self.now_s


def _heartbeats(rx: can.BusABC, n: int | None = None, timeout_s: float = 2.0) -> int:
    """Heartbeats received: ``n`` of them (or fewer when ``timeout_s`` passes first), or, with ``n`` None,
    those already waiting."""
    got, end = 0, time.monotonic() + timeout_s
    while n is None or got < n:
        m = rx.recv(0.0 if n is None else max(end - time.monotonic(), 0.0))
        if m is None:
            break
        got += m.arbitration_id == 0x3A1
    return got


def test_the_loops_thread_sends_the_heartbeats_it_is_awake_for_and_the_thread_backs_it_up(monkeypatch):
    """beat_if_due: the loop's wake-ups carry the heartbeat, a period apart at least, and the heartbeat thread
    sends only one the loop left RIDE_LATE_S overdue, so a listener still hears one every period + RIDE_LATE_S.
    Wake-ups a hair early (the 50 ms grid's float sums) still carry it: every other one does."""
    clock = FakeClock()
    monkeypatch.setattr(alerts_module.time, "monotonic", clock)
    rx = can.Bus(interface="virtual", channel="ride")
    pub = AlertPublisher(can.Bus(interface="virtual", channel="ride"), heartbeat_period_s=0.1).start()
    try:
        assert _heartbeats(rx, 1) == 1  # the thread's first, at start
        sent = pub.heartbeats_sent
        for k in range(1, 30):  # the loop wakes every 50 ms (its read period), 3 ms after the heartbeat's grid
            clock.now_s = 1000.0 + 0.05 * k + 0.003
            pub.beat_if_due()
            assert pub.heartbeats_sent == sent + k // 2, k  # every other wake-up, never two in a row
        time.sleep(0.3)  # the thread's real waits pass; on the fake clock nothing is overdue
        assert pub.heartbeats_sent == sent + 14 and _heartbeats(rx) == 14
        # the loop stalls: the thread sends it once it is RIDE_LATE_S overdue, not before
        due_s = clock.now_s + 0.05  # the last went out at k = 28, 0.05 s before the last wake-up, a period ago
        clock.now_s = due_s + alerts_module.RIDE_LATE_S - 0.01
        time.sleep(0.3)
        assert _heartbeats(rx) == 0
        clock.now_s = due_s + alerts_module.RIDE_LATE_S
        assert _heartbeats(rx, 1) == 1
    finally:
        pub.close()
        rx.shutdown()


def test_without_a_loop_to_ride_on_the_heartbeat_is_the_threads_and_a_replays_beats_go_by_data_time(monkeypatch):
    clock = FakeClock()
    monkeypatch.setattr(alerts_module.time, "monotonic", clock)
    rx = can.Bus(interface="virtual", channel="noride")
    pub = AlertPublisher(can.Bus(interface="virtual", channel="noride"), heartbeat_period_s=0.1)
    pub.beat_if_due()  # not started: nothing to ride on, nothing sent
    assert pub.heartbeats_sent == 0
    pub.start()
    try:
        assert _heartbeats(rx, 1) == 1
        clock.now_s += 0.1  # due, nobody riding: the thread sends it without waiting RIDE_LATE_S
        assert _heartbeats(rx, 1) == 1
    finally:
        pub.close()
        rx.shutdown()
    replay = AlertPublisher(None, clock=Clock.DATA)
    replay.beat_if_due()
    assert replay.heartbeats_sent == 0 and replay.send_errors == 0


def test_publisher_survives_raising_bus():
    bus = RaisingBus()
    pub = AlertPublisher(bus, heartbeat_period_s=0.02).start()
    time.sleep(0.15)
    assert pub._thread.is_alive() and pub.send_errors >= 3 and pub.frames_sent == 0
    assert not pub.on_decision(decision())
    bus.fail = False
    time.sleep(0.1)
    assert pub.frames_sent >= 2 and pub.on_decision(decision())
    pub.close()


# ---------------------------------------------------------------------------- WearableStatus


def _signals(status: WearableStatus) -> dict:
    hb = status.heartbeat()
    return {k: hb[k] for k in ("state", "sensor_health", "dropped_samples")}


def test_starting_then_running_then_each_fault_for_one_period():
    st = WearableStatus()
    assert _signals(st)["state"] == "starting"  # no sample yet: nothing to vouch for
    st.count_samples(100)
    assert _signals(st) == {"state": "running", "sensor_health": "ok", "dropped_samples": 0}
    st.set_source_counts(saturated=3, dropped=5)
    st.count_samples(100, non_finite=2)
    assert _signals(st) == {"state": "degraded", "sensor_health": "nan_samples", "dropped_samples": 7}
    st.count_samples(100)
    assert _signals(st)["state"] == "running"  # nothing new since the previous heartbeat
    st.set_source_counts(saturated=4, dropped=5)
    assert _signals(st)["sensor_health"] == "saturated"
    st.count_detector_restart()
    assert _signals(st)["sensor_health"] == "gaps"
    assert st.set_sensor("silent") and not st.set_sensor("silent")  # True on a change only
    assert _signals(st)["state"] == "sensor_silent"
    assert st.counts().sensor == "silent" and st.counts().samples == 300


def test_dropped_samples_saturate_at_the_signal_range():
    st = WearableStatus()
    st.count_samples(1, non_finite=70000)
    assert _signals(st)["dropped_samples"] == 65535


def test_heartbeat_carries_model_version_and_uptime():
    hb = WearableStatus(model_version=0xAB).heartbeat()
    assert hb["model_version"] == 0xAB and 0 <= hb["uptime_s"] < 5
    msg = AlertEncoder().decode(AlertEncoder().encode_status(**hb))
    assert msg["ModelVersion"] == 0xAB and str(msg["State"]) == "starting"


@pytest.mark.parametrize("access", [
    lambda st: st.count_samples(10, non_finite=1), lambda st: st.count_detector_restart(),
    lambda st: st.set_sensor("silent"), lambda st: st.set_source_counts(1, 2), lambda st: st.add_alert_latency(1.0),
    lambda st: st.heartbeat(), lambda st: st.counts(), lambda st: st.alert_latencies_ms(),
], ids=["count_samples", "count_detector_restart", "set_sensor", "set_source_counts", "add_alert_latency",
        "heartbeat", "counts", "alert_latencies_ms"])
def test_every_access_waits_while_another_thread_holds_the_status(access):
    """The heartbeat thread reads while the loop writes: each access goes through the one lock."""
    st = WearableStatus()
    done = threading.Event()
    with st._lock:  # another thread is in the middle of an update
        worker = threading.Thread(target=lambda: (access(st), done.set()), daemon=True)
        worker.start()
        assert not done.wait(0.05)
    assert done.wait(10)
    worker.join()


def test_alert_latencies_are_kept_in_order_and_handed_out_as_a_copy():
    st = WearableStatus()
    st.add_alert_latency(1.5)
    st.add_alert_latency(0.5)
    got = st.alert_latencies_ms()
    got.append(99.0)
    assert st.alert_latencies_ms() == [1.5, 0.5]


# ---------------------------------------------------------------------------- repetition and clocks


def test_the_dbc_says_how_alerts_are_repeated():
    rep = Repetition.of(load_vehicle_dbc().get_message_by_name("DISTRACTION_ALERT"))
    assert rep == Repetition(copies=4, period_s=0.05)
    assert rep.delays_s() == pytest.approx([0.05, 0.1, 0.15, 0.2])  # every loss recovered within 200 ms


def _frames(log_path):
    enc = AlertEncoder()
    return [(m.timestamp, m.arbitration_id, enc.decode(m)) for m in can.LogReader(str(log_path))]


def test_on_the_wall_clock_each_alert_goes_out_with_its_copies_and_the_same_alert_seq(tmp_path):
    bus = can.Bus(interface="virtual", channel="rep", receive_own_messages=False)
    rx = can.Bus(interface="virtual", channel="rep")
    pub = AlertPublisher(bus, heartbeat_period_s=0.1, log_path=tmp_path / "f.log").start()
    assert pub.publish_alert(decision("Drink")) == 0 and pub.publish_alert(decision("Phone")) == 1
    pub.close()
    got = []
    while (m := rx.recv(0.05)) is not None:
        if m.arbitration_id == 0x3A0:
            got.append(AlertEncoder().decode(m))
    rx.shutdown()
    assert sorted((d["AlertSeq"], d["Class"]) for d in got) == [(0, "Drink")] * 5 + [(1, "Phone")] * 5
    assert [d["TimeSinceTrigger"] for d in got if d["AlertSeq"] == 0] == [753, 803, 853, 903, 953]
    logged = [m for m in can.LogReader(str(tmp_path / "f.log")) if m.arbitration_id == 0x3A0]
    chk = E2EChecker(load_vehicle_dbc())
    assert all(chk.check(m).valid for m in logged)  # every copy is a new E2E frame, never a 'repeated' one
    assert [m.data[1] & 0x0F for m in logged] == list(range(10))
    assert pub.summary()["alerts_sent"] == 2 and pub.summary()["alert_copies_sent"] == 8


def test_an_alert_whose_first_frame_fails_has_no_alert_seq_and_no_copies():
    pub = AlertPublisher(RaisingBus(), heartbeat_period_s=0.05, clock=Clock.DATA)
    assert pub.publish_alert(decision()) is None
    pub.bus.fail = False
    pub.advance_to(20.0)
    assert pub.alert_copies_sent == 0 and pub.alerts_sent == 0 and pub.heartbeats_sent > 0


def test_on_the_data_clock_frames_are_stamped_with_the_recording_time(tmp_path):
    bus = can.Bus(interface="virtual", channel="data-clock", receive_own_messages=False)
    pub = AlertPublisher(bus, heartbeat_period_s=0.1, log_path=tmp_path / "f.asc", clock=Clock.DATA).start()
    assert pub._thread is None  # nothing runs between samples
    pub.status.count_samples(100)
    pub.advance_to(100.0)
    pub.publish_alert(SimpleNamespace(t_trigger_s=103.0, t_alert_s=110.0, label="Phone", confidence=0.9,
                                      status="alert", compute_us=0.0))
    pub.advance_to(110.12)
    pub.publish_alert(SimpleNamespace(t_trigger_s=123.0, t_alert_s=130.0, label="Drink", confidence=0.9,
                                      status="alert", compute_us=0.0))
    pub.advance_to(130.0)
    pub.close()  # the copies still due after the recording's end go out at their data time
    frames = _frames(tmp_path / "f.asc")
    stamps = [t for t, _, _ in frames]
    assert stamps == sorted(stamps)
    frames = [(t - stamps[0] + 100.0, i, d) for t, i, d in frames]  # .asc keeps times from the first frame
    alerts = [(round(t, 3), d["AlertSeq"]) for t, i, d in frames if i == 0x3A0]
    assert alerts == [(110.0, 0), (110.05, 0), (110.1, 0), (110.15, 0), (110.2, 0),
                      (130.0, 1), (130.05, 1), (130.1, 1), (130.15, 1), (130.2, 1)]
    beats = [(t, d["Uptime_s"]) for t, i, d in frames if i == 0x3A1]
    assert [round(t, 3) for t, _ in beats] == [round(100.0 + 0.1 * k, 3) for k in range(301)]  # 100.0 .. 130.0
    assert beats[-1][1] == 30  # uptime in data time


def test_advance_to_is_for_the_data_clock_only():
    with pytest.raises(RuntimeError):
        AlertPublisher(None).advance_to(1.0)


def test_updates_of_an_alert_go_out_under_its_alert_seq_with_their_own_status_and_copies(tmp_path):
    bus = can.Bus(interface="virtual", channel="updates", receive_own_messages=False)
    pub = AlertPublisher(bus, heartbeat_period_s=0.1, log_path=tmp_path / "f.log", clock=Clock.DATA).start()

    def verdict(t, label, status, event_seq=None):
        return SimpleNamespace(t_trigger_s=10.0, t_alert_s=t, label=label, confidence=0.9, status=status,
                               compute_us=0.0, event_seq=event_seq)

    seq = pub.publish_alert(verdict(11.62, "Phone", "preliminary"))
    assert pub.publish_alert(verdict(13.93, "Texting", "revised", seq)) == seq
    assert pub.publish_alert(verdict(15.99, "Texting", "confirmed", seq)) == seq
    assert pub.publish_alert(verdict(30.0, "Drink", "alert")) == seq + 1
    assert pub.publish_alert(verdict(31.0, "Other", "withdrawn", seq + 1)) == seq + 1
    pub.close()
    got = [(d["AlertSeq"], str(d["Status"]), str(d["Class"])) for _, i, d in _frames(tmp_path / "f.log") if i == 0x3A0]
    assert got == ([(0, "preliminary", "Phone")] * 5 + [(0, "revised", "Texting")] * 5 + [(0, "confirmed", "Texting")] * 5
                   + [(1, "alert", "Drink")] * 5 + [(1, "withdrawn", "Other")] * 5)


@pytest.mark.parametrize("channels", [("beats-heard", "beats-unheard"), ("9101", "9102")])
@pytest.mark.parametrize("deferred", [False, True])
def test_frames_nobody_can_hear_are_counted_not_encoded_and_the_next_heard_one_is_what_it_would_have_been(
        deferred, channels):
    """A data-clock publisher whose virtual bus has nobody else on its channel skips encoding the
    heartbeats and alert frames; once a listener joins, its frames equal those of a publisher that
    was heard all along. ``deferred``: the replay's bus, opened when the first frame must go out.
    A numeric channel ("9102") is one python-can opens as the number 9102: its listener must be found."""
    def publisher(channel):
        def open_virtual():
            return can.Bus(interface="virtual", channel=channel)

        pub = AlertPublisher(DeferredBus(open_virtual, channel) if deferred else open_virtual(),
                             heartbeat_period_s=0.1, clock=Clock.DATA)
        pub.status.count_samples(100)
        return pub

    heard, unheard = publisher(channels[0]), publisher(channels[1])
    rx_heard = can.Bus(interface="virtual", channel=channels[0])
    for pub in (heard, unheard):
        pub.advance_to(0.0)
        pub.status.set_alerts_undelivered(1)  # the next UNDELIVERED_HEARTBEATS heartbeats say degraded ...
        pub.advance_to(0.25)  # ... two of which nobody hears on the unheard bus
        pub.publish_alert(SimpleNamespace(t_trigger_s=0.1, t_alert_s=0.25, label="Phone", confidence=0.9,
                                          status="alert", compute_us=0.0))  # its first frame unheard, its copies heard
        pub.status.count_samples(10, non_finite=3)
    rx_unheard = can.Bus(interface="virtual", channel=channels[1])
    for pub in (heard, unheard):
        pub.advance_to(1.0)
        pub.close()
    assert unheard.frames_unheard == 4 and heard.frames_unheard == 0
    assert unheard.heartbeats_sent == heard.heartbeats_sent == 11 and unheard.alert_copies_sent == 4

    def frames(rx):
        out = []
        while (m := rx.recv(timeout=0)) is not None:
            out.append(bytes(m.data))
        rx.shutdown()
        return out

    assert frames(rx_unheard) == frames(rx_heard)[4:]


def test_the_kept_frame_schedule_is_the_shipped_dbcs():
    """The publisher schedules frames by the kept schedule until it first encodes one; it must be what parsing the
    DBC gives (after a change of the DBC: python -m export schedule)."""
    assert FrameSchedule.kept() == FrameSchedule.of(load_vehicle_dbc(), sha256_file(DBC_PATH))


def test_a_schedule_kept_for_another_dbc_is_not_used(tmp_path):
    dbc = tmp_path / "vehicle_alerts.dbc"
    dbc.write_text(DBC_PATH.read_text().replace("GenMsgNrOfRepetition\" BO_ 928 4", "GenMsgNrOfRepetition\" BO_ 928 2"))
    kept = tmp_path / "schedule.json"
    kept.write_text(DBC_SCHEDULE_PATH.read_text())
    assert FrameSchedule.kept(DBC_PATH, kept) is not None and FrameSchedule.kept(dbc, kept) is None
    assert FrameSchedule.of(load_dbc(dbc)).repetition.copies == 2
    kept.write_text("{}")
    assert FrameSchedule.kept(DBC_PATH, kept) is None  # another layout: the DBC is parsed


def _kept_schedule(tmp_path, monkeypatch, text: str):
    """The runtime's kept schedule replaced by ``text`` (the shipped DBC unchanged)."""
    kept = tmp_path / "vehicle_alerts.schedule.json"
    kept.write_text(text)
    monkeypatch.setattr(alerts_module, "DBC_SCHEDULE_PATH", kept)
    return kept


def test_a_kept_schedule_that_is_not_the_dbcs_is_refused_when_the_dbc_is_parsed(tmp_path, monkeypatch):
    """A schedule file with the shipped DBC's sha256 but other content (1 copy, the heartbeat's frame id for the
    alert's counter) was trusted: a late listener heard 2 alert frames instead of 5. The DBC is the truth: the
    replay's first encoded frame parses it and the altered schedule is a one-line integrity error."""
    good = json.loads(DBC_SCHEDULE_PATH.read_text())
    kept = _kept_schedule(tmp_path, monkeypatch, json.dumps(dict(good, repetition_copies=1, alert_frame_id=0x3A1)))
    pub = AlertPublisher(DeferredBus(lambda: can.Bus(interface="virtual", channel="tampered"), "tampered"),
                         heartbeat_period_s=0.1, clock=Clock.DATA)
    assert pub.encoder.repetition.copies == 1  # in use until the DBC is parsed ...
    pub.status.count_samples(100)
    pub.advance_to(0.0)
    pub.publish_alert(SimpleNamespace(t_trigger_s=-1.0, t_alert_s=1.0, label="Phone", confidence=0.9,
                                      status="alert", compute_us=0.0))  # nobody listens: nothing encoded
    rx = can.Bus(interface="virtual", channel="tampered")
    try:
        with pytest.raises(ModelIntegrityError, match=kept.name):  # ... which the first heard frame does
            pub.advance_to(2.0)
    finally:
        rx.shutdown()
        pub.bus.shutdown()
    with pytest.raises(ModelIntegrityError, match="differs"):
        check_frame_schedule(DBC_PATH, kept)  # what export bundle refuses


@pytest.mark.parametrize("text", ["not json", "[1, 2]", '{"dbc_sha256": null}', ""])
def test_a_malformed_kept_schedule_is_as_none_the_dbc_is_parsed_at_start(tmp_path, monkeypatch, text):
    _kept_schedule(tmp_path, monkeypatch, text)
    enc = AlertEncoder(lazy=True)
    assert enc._db is not None and enc.repetition == Repetition.of(load_vehicle_dbc().get_message_by_name("DISTRACTION_ALERT"))


def test_a_live_publisher_parses_the_dbc_at_start_a_replays_when_it_first_encodes(monkeypatch):
    """On the wall clock a DBC that cannot be parsed (or a missing cantools) is one line at start, not a heartbeat
    thread that dies after the process said it was ready."""
    assert AlertPublisher(None).encoder._db is not None
    assert AlertPublisher(None, clock=Clock.DATA).encoder._db is None

    def no_cantools():
        raise ModuleNotFoundError("No module named 'cantools'", name="cantools")

    monkeypatch.setattr(alerts_module, "load_vehicle_dbc", no_cantools)
    with pytest.raises(ModuleNotFoundError):
        AlertPublisher(None)
    AlertPublisher(None, clock=Clock.DATA)  # a replay: the kept schedule serves until a frame is heard


def test_a_heartbeat_thread_that_dies_fails_the_run(monkeypatch):
    """Whatever ends the heartbeat thread is kept and turns into a one-line CanLinkError at the loop's next turn,
    so the process stops feeding the service watchdog instead of looking healthy without heartbeats."""
    pub = AlertPublisher(None, heartbeat_period_s=0.01)

    def broken(**signals):
        raise RuntimeError("encoder\nbroke")

    monkeypatch.setattr(pub.encoder, "encode_status", broken)
    pub.check_running()
    pub.start()
    pub._thread.join(timeout=5.0)
    assert not pub._thread.is_alive() and pub.thread_error == "RuntimeError: encoder broke"
    with pytest.raises(CanLinkError, match="heartbeat thread stopped: RuntimeError: encoder broke"):
        pub.check_running()
    pub.close()


@pytest.mark.slow  # an interpreter of its own: this one has python-can loaded
def test_a_replay_nobody_hears_loads_neither_python_can_nor_cantools(tmp_path):
    """On the in-process virtual bus with nobody on its channel, nothing is encoded and nothing is sent: the
    replay needs neither python-can nor the DBC's parser (about a tenth of a day's replay to import)."""
    acc = tmp_path / "imu.csv"
    t = np.arange(3000) / 100.0
    acc.write_text("t,ax,ay,az\n" + "".join(f"{s:.2f},0.1,0.2,9.8\n" for s in t))
    code = ("import sys; from edge_runtime.__main__ import main; rc = main(['wearable', '--replay', sys.argv[1], "
            "'--quiet']); print(rc, 'can' in sys.modules, 'cantools' in sys.modules)")
    r = subprocess.run([sys.executable, "-c", code, str(acc)], capture_output=True, text=True, timeout=120)
    assert r.stdout.strip().splitlines()[-1] == "0 False False", r.stdout + r.stderr
