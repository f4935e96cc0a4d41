"""docs/examples/listen_alerts.py, the integrator's listener (python-can, cantools, autosar-e2e only):
it decodes alerts, catches every corrupted frame by its E2E CRC, recovers an alert from its copies
and counts it once, and notices a silent heartbeat."""
import json
import signal
import subprocess
import sys
import time
from types import SimpleNamespace

import can
import pytest
from support import REPO_ROOT

from edge_runtime.wearable.alerts import DBC_PATH, AlertPublisher
from firmware_sim.devices.can_hub import CanHub

pytestmark = pytest.mark.slow  # every test here starts a process

LISTENER = REPO_ROOT / "docs" / "examples" / "listen_alerts.py"


def _alert(i, label):
    return SimpleNamespace(t_trigger_s=10.0 * i, t_alert_s=10.0 * i + 6.0, label=label, confidence=0.9,
                           alerted=True, status="alert", compute_us=100.0)


def test_listener_counts_alerts_e2e_errors_and_heartbeat_loss(tmp_path):
    hub = CanHub(port=0, corrupt=0.2, seed=3).start()
    proc = subprocess.Popen([sys.executable, "-I", str(LISTENER), "--dbc", str(DBC_PATH), "--port", str(hub.port)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path)
    try:
        assert proc.stdout.readline().strip() == "listening"
        time.sleep(0.1)
        bus = can.Bus(interface="socketcand", host="127.0.0.1", port=hub.port, channel="vcan0")
        with AlertPublisher(bus, heartbeat_period_s=0.05) as pub:
            pub.status.count_samples(100)  # samples arrived: the heartbeat says running
            for i in range(20):
                pub.on_decision(_alert(i, ["Phone", "Drink", "Texting", "Marker"][i % 4]))
                time.sleep(0.02)
            time.sleep(0.3)
        time.sleep(0.6)  # the heartbeat has stopped: the listener must say so
        proc.send_signal(signal.SIGTERM)
        out, err = proc.communicate(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.communicate()
        hub.stop()
    assert proc.returncode == 0, err
    summary = json.loads(out.strip().splitlines()[-1].split(" ", 1)[1])
    corrupted = hub.stats["corrupted"]
    assert corrupted > 0
    assert summary["e2e_wrong_crc"] == corrupted  # CRC-8 catches every single-byte flip
    assert summary["alerts"] + summary["alert_copies"] + summary["heartbeats"] + corrupted == hub.stats["frames_out"]
    # a fifth of the frames is corrupted, yet each of the 20 alerts arrives (a copy stands in) and counts once
    assert summary["alerts"] == 20 and summary["alert_copies"] > 0 and summary["heartbeat_timeouts"] == 1
    alerts = [int(line.split()[1]) for line in out.splitlines() if line.startswith("ALERT")]
    assert sorted(alerts) == list(range(20))  # by AlertSeq, each once (a copy may come after the next alert)
    assert "treat the wearable as unavailable" in out


def _listener_module():
    import importlib.util

    spec = importlib.util.spec_from_file_location("listen_alerts", LISTENER)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_updates_of_an_alert_are_neither_swallowed_as_copies_nor_counted_twice():
    """In-process: the listener's AlertListener fed the frames of an early alert and its updates,
    every message in 5 copies, with the first copy of some lost."""
    import cantools

    from edge_runtime.wearable.alerts import AlertEncoder

    enc, lines = AlertEncoder(), []
    listener = _listener_module().AlertListener(cantools.database.load_file(DBC_PATH), emit=lines.append)

    def message(t, label, status, seq, lose_first=False):
        d = SimpleNamespace(t_trigger_s=10.0, t_alert_s=t, label=label, confidence=0.9, status=status, compute_us=0.0)
        for k in range(5):
            if not (lose_first and k == 0):
                listener.tick(t + 0.05 * k)
                listener.frame(enc.encode_alert(d, seq, 0.05 * k), t + 0.05 * k)

    message(11.62, "Phone", "preliminary", 7)
    message(13.93, "Texting", "revised", 7, lose_first=True)
    message(15.99, "Texting", "confirmed", 7)
    message(40.0, "Drink", "preliminary", 8, lose_first=True)
    message(42.0, "Drink", "withdrawn", 8)
    message(60.0, "Marker", "alert", 9)
    message(70.0, "Phone", "preliminary", 10)  # then nothing: the sensor stream was cut
    listener.tick(77.5)
    c = listener.summary()
    assert (c["alerts"], c["updates"], c["withdrawn"], c["expired"], c["alert_copies"]) == (4, 3, 1, 1, 4 * 4 + 4 + 2 * 3)
    kinds = [line.split()[:3] for line in lines if line.split()[0] in ("ALERT", "UPDATE", "EXPIRED")]
    assert kinds == [["ALERT", "7", "Phone"], ["UPDATE", "7", "Texting"], ["UPDATE", "7", "Texting"],
                     ["ALERT", "8", "Drink"], ["UPDATE", "8", "Drink"], ["ALERT", "9", "Marker"],
                     ["ALERT", "10", "Phone"], ["EXPIRED", "10", "preliminary"]]
    assert "stop warning: alert void" in lines[4]
