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
