"""Vehicle CAN link: DBC, cantools encoding, AUTOSAR E2E, heartbeat, bus errors."""
from __future__ import annotations

import subprocess
import sys
import time
from types import SimpleNamespace

import can
import pytest

from edge_runtime.canbus.bus import CanLinkError, open_bus
from edge_runtime.canbus.e2e import E2EChecker
from edge_runtime.wearable.alerts import DBC_PATH, AlertEncoder, AlertPublisher, load_vehicle_dbc
from edge_runtime.wearable.labels import CLASSES


def decision(label="Phone", conf=0.87, alerted=True, status="alert"):
    return SimpleNamespace(t_trigger_s=10.0, t_alert_s=10.75, label=label, confidence=conf, alerted=alerted,
                           status=status, probs={}, compute_us=2500.0)


def test_dbc_loads_with_version_and_labels():
    db = load_vehicle_dbc()
    assert db.version == "1.0.0"
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


def test_e2e_counter_crc_repeat_loss():
    enc, chk = AlertEncoder(), E2EChecker(load_vehicle_dbc())
    msgs = [enc.encode_alert(decision()) for _ in range(20)]
    counters = [m.data[1] & 0x0F for m in msgs]
    assert counters[:16] == list(range(15)) + [0]  # Profile 1: 0..14 then wraps
    assert chk.check(msgs[0]).status == "initial"
    assert [chk.check(m).status for m in msgs[1:16]] == ["ok"] * 15
    assert chk.check(msgs[15]).status == "repeated"
    res = chk.check(msgs[18])
    assert (res.status, res.lost) == ("lost", 2)
    bad = can.Message(arbitration_id=0x3A0, data=bytearray(msgs[19].data), is_extended_id=False)
    bad.data[5] ^= 0x10
    assert chk.check(bad).status == "wrong_crc"
    # masquerading: a valid alert payload under the status ID fails (different data ID)
    fake = can.Message(arbitration_id=0x3A1, data=msgs[19].data, is_extended_id=False)
    assert chk.check(fake).status == "wrong_crc"
    assert chk.errors == 1 + 2 + 2


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
    pub = AlertPublisher(bus, heartbeat_period_s=0.1, log_path=path)
    pub.set_status(state="running", model_version=2)
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
    assert sum(m.arbitration_id == 0x3A0 for m in rx_msgs) == 1
    assert pub.frames_sent == len(rx_msgs) and pub.send_errors == 0
    chk = E2EChecker(load_vehicle_dbc())
    assert all(chk.check(m).valid for m in hb)
    assert AlertEncoder().decode(hb[-1])["State"] == "running"
    logged = list(can.LogReader(str(path)))
    assert len(logged) == pub.frames_sent


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


def test_open_bus_one_line_error():
    with pytest.raises(CanLinkError) as e:
        open_bus("no_such_interface", "can0")
    assert "\n" not in str(e.value) and "no_such_interface" in str(e.value)
    with pytest.raises(CanLinkError, match="not allowed"):
        open_bus("udp", "x")  # only the allow-listed bus interfaces open
