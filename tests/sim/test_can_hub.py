"""The socketcand-protocol CAN hub, reached with python-can's stock socketcand interface."""
from __future__ import annotations

import json
import subprocess
import sys
import time
from types import SimpleNamespace

import can
import pytest
from support.can import LISTENER

from edge_runtime.canbus.e2e import E2EChecker
from edge_runtime.wearable.alerts import DBC_PATH, AlertEncoder, AlertPublisher, load_vehicle_dbc
from edge_runtime.wearable.labels import DISTRACTIONS


def client(hub):
    bus = can.Bus(interface="socketcand", host="127.0.0.1", port=hub.port, channel="vcan0")
    time.sleep(0.08)  # the hub holds frames back briefly after the handshake
    return bus


def recv_all(bus, timeout=0.3):
    out = []
    while (m := bus.recv(timeout)) is not None:
        out.append(m)
    return out


def test_relay_between_two_clients(hub):
    a, b, c = client(hub), client(hub), client(hub)
    try:
        a.send(can.Message(arbitration_id=0x3A0, data=[1, 2, 3, 0xFF, 0, 0, 0, 9], is_extended_id=False))
        a.send(can.Message(arbitration_id=0x1ABCDEF, data=[7], is_extended_id=True))
        for rx in (b, c):
            got = recv_all(rx)
            assert [(m.arbitration_id, m.is_extended_id, bytes(m.data)) for m in got] == [
                (0x3A0, False, bytes([1, 2, 3, 0xFF, 0, 0, 0, 9])), (0x1ABCDEF, True, bytes([7]))]
        assert recv_all(a, 0.1) == []  # no echo to the sender
    finally:
        for bus in (a, b, c):
            bus.shutdown()


def test_drop_all(hub):
    hub.drop = 1.0
    a, b = client(hub), client(hub)
    try:
        for i in range(5):
            a.send(can.Message(arbitration_id=0x100, data=[i], is_extended_id=False))
        assert recv_all(b, 0.2) == []
        assert hub.stats["dropped"] == 5
    finally:
        a.shutdown()
        b.shutdown()


def test_corrupt_is_caught_by_e2e(hub):
    hub.corrupt = 1.0
    a, b = client(hub), client(hub)
    enc, chk = AlertEncoder(), E2EChecker(load_vehicle_dbc())
    try:
        d = SimpleNamespace(t_trigger_s=0.0, t_alert_s=0.7, label="Phone", confidence=0.9, alerted=True,
                            status="alert", compute_us=0.0)
        sent = [enc.encode_alert(d) for _ in range(5)]
        for m in sent:
            a.send(m)
        got = recv_all(b)
        assert len(got) == 5
        assert all(bytes(g.data) != bytes(s.data) for g, s in zip(got, sent))
        assert [chk.check(g).status for g in got] == ["wrong_crc"] * 5
    finally:
        a.shutdown()
        b.shutdown()


def test_disconnect_and_reconnect(hub):
    a = client(hub)
    assert hub.n_clients == 1
    hub.disconnect_all()
    time.sleep(0.05)
    with pytest.raises((OSError, can.CanError)):
        for _ in range(20):  # the first writes may still be buffered by the kernel
            a.send(can.Message(arbitration_id=0x100, data=[1], is_extended_id=False))
            time.sleep(0.01)
    a.shutdown()
    a, b = client(hub), client(hub)
    try:
        a.send(can.Message(arbitration_id=0x101, data=[2], is_extended_id=False))
        assert [m.arbitration_id for m in recv_all(b)] == [0x101]
    finally:
        a.shutdown()
        b.shutdown()


def test_publisher_reconnects_after_hub_disconnect(hub):
    listener = client(hub)
    factory = lambda: can.Bus(interface="socketcand", host="127.0.0.1", port=hub.port, channel="vcan0")  # noqa: E731
    pub = AlertPublisher(factory(), heartbeat_period_s=0.02, bus_factory=factory).start()
    try:
        time.sleep(0.2)
        hub.disconnect_all()  # drops the listener too
        listener.shutdown()
        listener = client(hub)
        deadline = time.monotonic() + 3.0
        while pub.reconnects == 0 and time.monotonic() < deadline:
            time.sleep(0.02)
        assert pub.send_errors >= 1 and pub.reconnects >= 1
        time.sleep(0.15)
        m = listener.recv(1.0)  # heartbeats keep coming: take one, don't drain
        assert m is not None and m.arbitration_id == 0x3A1
    finally:
        pub.close()
        listener.shutdown()




@pytest.mark.slow
def test_stock_tools_listener_process_decodes_alerts(hub, tmp_path):
    script = tmp_path / "listener.py"
    script.write_text(LISTENER)
    labels = list(DISTRACTIONS)
    proc = subprocess.Popen([sys.executable, "-I", str(script), str(DBC_PATH), str(hub.port), str(len(labels))],
                            cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "ready"
        time.sleep(0.1)
        bus = can.Bus(interface="socketcand", host="127.0.0.1", port=hub.port, channel="vcan0")
        with AlertPublisher(bus, heartbeat_period_s=0.05) as pub:
            time.sleep(0.1)
            for i, label in enumerate(labels):  # a drive: one alert per distraction
                pub.on_decision(SimpleNamespace(t_trigger_s=30.0 * i, t_alert_s=30.0 * i + 0.7, label=label,
                                                confidence=0.8 + 0.02 * i, alerted=True, status="alert",
                                                compute_us=1000.0))
                time.sleep(0.02)
        out, err = proc.communicate(timeout=15)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
    assert proc.returncode == 0, err
    lines = [json.loads(x) for x in out.splitlines()]
    alerts, tail = lines[:-1], lines[-1]
    assert [a["Class"] for a in alerts] == labels
    assert [a["AlertSeq"] for a in alerts] == list(range(len(labels)))
    assert [a["TimeSinceTrigger"] for a in alerts] == [701] * len(labels)
    assert alerts[2]["Confidence"] == pytest.approx(0.84, abs=0.005)
    assert tail == {"project_modules": []}


@pytest.mark.slow
def test_cli_prints_port_and_stops():
    proc = subprocess.Popen([sys.executable, "-m", "firmware_sim.devices.can_hub", "--port", "0", "--duration", "0.5"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    out, err = proc.communicate(timeout=10)
    assert proc.returncode == 0, err
    assert "listening on 127.0.0.1:" in out and "can-hub stopped" in out
    bad = subprocess.run([sys.executable, "-m", "firmware_sim.devices.can_hub", "--drop", "2"], capture_output=True, text=True)
    assert bad.returncode == 2 and "drop" in bad.stderr and "Traceback" not in bad.stderr
