"""The whole wearable chain across processes: simulated drive -> `python -m edge_runtime wearable`
-> socketcand hub -> a listener that knows only python-can, cantools and our DBC."""
import json
import subprocess
import sys
import time

import pytest
from support.can import LISTENER  # the stock-tools listener script

from edge_runtime.wearable.alerts import DBC_PATH, AlertEncoder

pytestmark = pytest.mark.slow  # every test here starts a process


def _wearable(csv, tmp_path, name, decision, extra=()):
    alerts = tmp_path / f"{name}.jsonl"
    # one message per alert (the shipped stream's, or the full-window decision), so alerts pair up one to one with
    # the listener's lines; early decisions' updates across processes: tests/e2e/test_integrator_listener.py
    r = subprocess.run([sys.executable, "-m", "edge_runtime", "wearable", "--replay", str(csv), "--alerts", str(alerts),
                        "--quiet", "--decision", decision, *extra], capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    return [json.loads(x) for x in alerts.read_text().splitlines()], r.stdout


@pytest.mark.parametrize("decision", ["stream", "full_window"])
def test_alerts_of_a_simulated_drive_reach_an_integrator_process(hub, tmp_path, decision):
    sim = subprocess.run([sys.executable, "-m", "firmware_sim", "drive", "--minutes", "3", "--seed", "11", "--out",
                          str(tmp_path)], capture_output=True, text=True, timeout=60)
    assert sim.returncode == 0, sim.stderr
    csv = tmp_path / "imu.csv"
    # how many alerts to expect: the same replay on python-can's in-process virtual bus
    offline, _ = _wearable(csv, tmp_path, "offline", decision)
    expected = [d["label"] for d in offline if d["alerted"]]
    assert len(expected) >= 3

    box = tmp_path / "box.toml"
    box.write_text(f'[can]\ninterface = "socketcand"\nchannel = "vcan0"\nport = {hub.port}\n')
    script = tmp_path / "listener.py"
    script.write_text(LISTENER)
    listener = subprocess.Popen([sys.executable, "-I", str(script), str(DBC_PATH), str(hub.port), str(len(expected))],
                                cwd=tmp_path, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert listener.stdout.readline().strip() == "ready"
        time.sleep(0.1)
        decisions, summary = _wearable(csv, tmp_path, "live", decision,
                                       ["--config", str(box), "--can-log", str(tmp_path / "sent.log")])
        out, err = listener.communicate(timeout=20)
    finally:
        if listener.poll() is None:
            listener.kill()
            listener.communicate()
    assert listener.returncode == 0, err
    received = [json.loads(x) for x in out.splitlines()[:-1]]
    assert [a["Class"] for a in received] == expected == [d["label"] for d in decisions if d["alerted"]]
    assert "send errors 0" in summary
    log = (tmp_path / "sent.log").read_text()
    frames_per_alert = 1 + AlertEncoder().repetition.copies
    assert log.count("3A0#") == frames_per_alert * len(expected) and "3A1#" in log  # every frame sent is logged
    seqs = [d["alert_seq"] for d in decisions if d["alerted"]]
    assert [a["AlertSeq"] for a in received] == seqs == list(range(len(expected)))
