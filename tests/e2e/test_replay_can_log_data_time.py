"""A replay's ``--can-log`` in the recording's time (issue 12 item 7): each frame is stamped when it
would have been sent, so ``python -m can.player`` replays the log at the data's pace. Read back with
python-can's own LogReader."""
import json
import subprocess
import sys

import can
import pytest

from edge_runtime.wearable.alerts import AlertEncoder

pytestmark = pytest.mark.slow  # starts the simulator and the runtime


@pytest.fixture(scope="module")
def drive(tmp_path_factory):
    out = tmp_path_factory.mktemp("drive")
    r = subprocess.run([sys.executable, "-m", "firmware_sim", "drive", "--minutes", "3", "--seed", "11", "--out",
                        str(out)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    return out / "imu.csv"


@pytest.mark.parametrize("suffix", [".asc", ".log", ".blf"])
def test_replayed_frames_follow_the_data_not_the_wall_clock(drive, tmp_path, suffix):
    log, alerts = tmp_path / f"frames{suffix}", tmp_path / "alerts.jsonl"
    r = subprocess.run([sys.executable, "-m", "edge_runtime", "wearable", "--replay", str(drive), "--alerts",
                        str(alerts), "--can-log", str(log), "--quiet"], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0, r.stderr
    sent = [d for d in map(json.loads, alerts.read_text().splitlines()) if d["alerted"]]
    assert len(sent) >= 5
    enc = AlertEncoder()
    frames = list(can.LogReader(str(log)))
    t0 = frames[0].timestamp  # .asc keeps times from its first frame; .log and .blf keep them absolute
    times = [m.timestamp - t0 for m in frames]
    assert times == sorted(times)
    assert times[-1] == pytest.approx(179.9, abs=0.01)  # 180 s of data, not the replay's second

    beats = [t for m, t in zip(frames, times) if m.arbitration_id == 0x3A1]
    assert len(beats) == 1800 and all(b - a == pytest.approx(0.1, abs=1e-3) for a, b in zip(beats, beats[1:]))

    alert_frames = [(t, enc.decode(m)["AlertSeq"]) for m, t in zip(frames, times) if m.arbitration_id == 0x3A0]
    copies = [k * enc.repetition.period_s for k in range(enc.repetition.copies + 1)]
    expected = [(d["t_alert_s"] + dt, d["alert_seq"]) for d in sent for dt in copies]
    assert [s for _, s in alert_frames] == [s for _, s in expected]
    assert [t for t, _ in alert_frames] == pytest.approx([t for t, _ in expected], abs=1e-3)  # t_alert_s, then copies
