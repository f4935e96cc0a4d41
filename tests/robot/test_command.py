"""``python -m edge_runtime robot``: config, calibration from a recording, a replay against a
link, and one-line errors for bad input."""
import json
import subprocess
import sys
import tomllib

import numpy as np
import pytest
from support.robot import FakeLink

from edge_runtime.__main__ import main
from edge_runtime.robot import command as robot_cli
from firmware_sim.devices.camera import Camera
from firmware_sim.people import human

BODY = human.Body.from_height(1.8)
CAM = Camera.look_at((1.0, 1.5, 6.5), target_m=(0.0, 0.0, 1.0))
MARKERS = ((0.0, 1.0), (1.0, 1.0), (0.0, 2.0))


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "edge_runtime", "robot", *args], capture_output=True, text=True,
                          timeout=120)


def write_jsonl(path, rows):
    path.write_text("".join(json.dumps(r) + "\n" for r in rows))
    return path


def calibration_recording(path, rng):
    rows, t = [], 0.0
    for x, z in MARKERS:
        for _ in range(45):
            j = CAM.to_camera(human.joints(BODY, human.Posture(), pelvis_xz_m=(x, z))) + rng.normal(0, 0.02, (17, 3))
            rows.append({"t": round(t, 4), "joints_cam_m": j.round(4).tolist()})
            t += 1 / 30
        t += 1.0  # walking to the next marker (not recorded)
    return write_jsonl(path, rows)


def approach(path, frame="robot", seconds=1.6, start_z=3.0, speed=1.4):
    """A worker walking at the effector from +z, in robot- or camera-frame joints."""
    rows = []
    for i in range(int(seconds * 30)):
        z = start_z - speed * i / 30
        j = human.joints(BODY, human.Posture(), pelvis_xz_m=(0.0, z), heading_rad=np.pi)
        if frame == "camera":
            rows.append({"t": i / 30, "joints_cam_m": CAM.to_camera(j).round(4).tolist()})
        else:
            rows.append({"t": i / 30, "joints_robot_m": j.round(4).tolist()})
    return write_jsonl(path, rows)


@pytest.fixture
def fake_link(monkeypatch):
    link = FakeLink()
    monkeypatch.setattr(robot_cli, "_open_link", lambda cfg: link)
    return link


@pytest.mark.slow
def test_print_config_shows_the_robot_sections_with_flags_applied(tmp_path):
    p = tmp_path / "box.toml"
    p.write_text('[zones]\nmargin1_m = 1.5\n[robot_loop]\ntask_waypoints_m = [[0.3, 0.1, 0.6]]\n')
    r = _cli("--config", str(p), "--print-config", "--link", "mavlink", "--sizing", "iso15066")
    assert r.returncode == 0, r.stderr
    eff = tomllib.loads(r.stdout)
    assert eff["zones"]["margin1_m"] == 1.5 and eff["zones"]["sizing"] == "iso15066"
    assert eff["robot_link"]["kind"] == "mavlink" and eff["robot_loop"]["task_waypoints_m"] == [[0.3, 0.1, 0.6]]
    # the command prints (and checks) its own sections; the wearable's are the wearable command's
    assert "can" not in eff and "detector" not in eff and "lifter" in eff


@pytest.mark.slow
@pytest.mark.parametrize("toml, key", [
    ("[zones]\nmargin_1 = 2\n", "margin_1"),
    ("[zones]\nsizing = \"huge\"\n", "sizing"),
    ("[robot_loop]\nheartbeat_period_s = 0.5\n", "heartbeat_period_s"),
    ("[robot_loop]\ntask_waypoints_m = [[0.1, 0.2]]\n", "task_waypoints_m"),
    ("[calibration]\nmethod = \"svd\"\n", "method"),
    ("[robot_link]\nkind = \"udp\"\n", "kind"),
])
def test_a_bad_config_key_is_one_line_naming_the_key(tmp_path, toml, key):
    p = tmp_path / "box.toml"
    p.write_text(toml)
    r = _cli("--config", str(p), "--print-config")
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1 and key in lines[0] and "box.toml" in lines[0], r.stderr


def test_calibrate_then_replay_camera_frame_joints_against_the_link(tmp_path, fake_link, capsys):
    rng = np.random.default_rng(0)
    rec = calibration_recording(tmp_path / "calib.jsonl", rng)
    cal = tmp_path / "cal.json"
    assert main(["robot", "--joints", str(rec), "--calibrate", str(cal)]) == 0
    data = json.loads(cal.read_text())
    assert data["inputs"]["frames_per_marker"][0] >= 30 and max(data["residuals_m"]["head"]) < 0.1
    out = capsys.readouterr().out
    assert "residuals" in out and str(cal) in out

    # starts 5.5 m out: the start-up hold runs on the wall clock, and under load it lasted until a walker
    # starting at 5 m was inside R1 with the (default) pnp calibration
    walk = approach(tmp_path / "walk.jsonl", frame="camera", seconds=3.1, start_z=5.5)
    log = tmp_path / "log.jsonl"
    box = tmp_path / "box.toml"
    # a shorter start-up hold and the dissertation's head zones, smaller (R1 3 m) keep the test short
    box.write_text("[zones]\ndwell_s = 0.3\nretract_time_s = 1.0\nseparation = \"head\"\n")
    assert main(["robot", "--config", str(box), "--joints", str(walk), "--calibration", str(cal), "--log", str(log),
                 "--quiet"]) == 0
    lines = [json.loads(x) for x in log.read_text().splitlines()]
    frames, summary = lines[:-1], lines[-1]["summary"]
    assert len(frames) == 93 and summary["frames"] == 93
    # a worker 5.5 m out walking in at 1.4 m/s: the arm works, is stopped, then retracted
    states = [f["state"] for f in frames]
    assert states.index("NORMAL") < states.index("LEVEL1") < states.index("LEVEL2") and summary["retracts"] == 1
    assert [f["command"] for f in frames if f["command"] in ("stop", "retract")] == ["stop", "retract"]
    assert fake_link.calls[-1] == ("stop",)  # the CLI stops the arm when the input ends
    assert summary["reaction_ms"]["n"] >= 2 and summary["reaction_ms"]["median"] >= 0


def test_robot_frame_joints_need_no_calibration(tmp_path, fake_link):
    walk = approach(tmp_path / "walk.jsonl", frame="robot", seconds=0.5, start_z=8.0)
    assert main(["robot", "--joints", str(walk), "--duration", "0.3", "--quiet"]) == 0
    assert ("stop",) in fake_link.calls and any(c[0] == "heartbeat" for c in fake_link.calls)


@pytest.mark.slow
@pytest.mark.parametrize("line, match", [
    ('{"t": 0.0, "joints_robot_m": [[0, 0, 0]]}', r"walk.jsonl:2: joints_robot_m: expected a list of 17"),
    ('{"t": 0.0}', r"walk.jsonl:2: no joints_cam_m, joints_robot_m or people"),
    ('{"t": "soon", "joints_robot_m": null, "valid": false}', r"walk.jsonl:2: t: expected a finite number"),
    ('[1, 2]', r"walk.jsonl:2: expected a JSON object"),
    ('{"t": -1.0, "joints_robot_m": null, "valid": false}', r"walk.jsonl:2: t -1.0 does not increase"),
    (json.dumps({"t": 1.0, "joints_cam_m": [[0, 0, 1]] * 17}), r"walk.jsonl:2: mixes camera- and robot-frame"),
    ('{"t": 1.0, "people": [{"id": 1}]}', r"walk.jsonl:2: every person needs joints_cam_m or joints_robot_m"),
])
def test_bad_joints_files_are_one_line_naming_the_line(tmp_path, line, match):
    p = tmp_path / "walk.jsonl"
    good = {"t": 0.0, "joints_robot_m": np.zeros((17, 3)).tolist()}
    p.write_text(json.dumps(good) + "\n" + line + "\n")
    r = _cli("--joints", str(p))
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and "Traceback" not in r.stderr
    import re

    assert re.search(match, r.stderr), r.stderr


@pytest.mark.parametrize("line, match", [
    ('{"t": 1.7e308, "joints_robot_m": null, "valid": false}', r"walk.jsonl:2: t: expected a finite number in"),
    ('{"t": 1.0, "joints_robot_m": [[1e400, 0, 0]' + ', [0, 0, 0]' * 16 + ']}',
     r"walk.jsonl:2: joints_robot_m\[0\]\[0\]: expected a finite number in \[-100, 100\]"),
    ('{"t": 1.0, "joints_robot_m": [[NaN, 0, 0]' + ', [0, 0, 0]' * 16 + ']}', r"walk.jsonl:2: NaN is not JSON"),
    ('{"t": 1.0, "marker": true, "joints_robot_m": null, "valid": false}', r"walk.jsonl:2: marker: expected an integer"),
    (json.dumps({"t": 1.0, "people": [{"id": [1], "joints_robot_m": [[0, 0, 0]] * 17}]}), r"walk.jsonl:2: people\[0\].id"),
    ('{"t": ' + "9" * 400 + ', "joints_robot_m": null, "valid": false}', r"walk.jsonl:2: t: expected a finite number"),
    ('{"t": 1.0, "x": ' + "[" * 3000 + "]" * 3000 + '}', r"walk.jsonl:2: nested more than 64 levels"),
])
def test_joints_lines_are_checked_field_by_field(tmp_path, line, match):
    from edge_runtime.robot.command import JointsInputError, read_joints_jsonl

    p = tmp_path / "walk.jsonl"
    p.write_text(json.dumps({"t": 0.0, "joints_robot_m": np.zeros((17, 3)).tolist()}) + "\n" + line + "\n")
    with pytest.raises(JointsInputError, match=match):
        read_joints_jsonl(str(p))


def test_non_utf8_joints_line_is_named(tmp_path):
    from edge_runtime.robot.command import JointsInputError, read_joints_jsonl

    p = tmp_path / "walk.jsonl"
    p.write_bytes(json.dumps({"t": 0.0, "joints_robot_m": None, "valid": False}).encode() + b"\n\xff\n")
    with pytest.raises(JointsInputError, match=r"walk.jsonl:2: not UTF-8 text"):
        read_joints_jsonl(str(p))


@pytest.mark.slow
def test_camera_frame_joints_without_a_calibration_and_bad_calibration_files(tmp_path):
    walk = approach(tmp_path / "walk.jsonl", frame="camera", seconds=0.2)
    r = _cli("--joints", str(walk))
    assert r.returncode == 2 and "--calibration" in r.stderr
    bad = tmp_path / "cal.json"
    bad.write_text("{}")
    r = _cli("--joints", str(walk), "--calibration", str(bad))
    assert r.returncode == 2 and "cal.json" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    # calibrating from a recording in which the worker never moves
    still = write_jsonl(tmp_path / "still.jsonl", [
        {"t": i / 30, "joints_cam_m": CAM.to_camera(human.joints(BODY, human.Posture(), pelvis_xz_m=(0, 1))).tolist()}
        for i in range(90)])
    r = _cli("--joints", str(still), "--calibrate", str(tmp_path / "out.json"))
    assert r.returncode == 2 and "standing period" in r.stderr and len(r.stderr.strip().splitlines()) == 1


@pytest.mark.slow
def test_against_the_simulated_sawyer_process_over_signed_mavlink(tmp_path):
    """The real thing: the controller as its own process on a pseudo-terminal, the runtime
    as another, a recording of a worker walking in; the controller ends retracted."""
    from firmware_sim.robot.controller import SawyerProcess

    key = bytes(range(32))
    walk = approach(tmp_path / "walk.jsonl", frame="robot", seconds=3.2, start_z=5.5)
    box = tmp_path / "box.toml"
    box.write_text("[zones]\ndwell_s = 0.3\nretract_time_s = 1.0\nseparation = \"head\"\n")  # the dissertation's zones
    log = tmp_path / "log.jsonl"
    with SawyerProcess("mavlink", signing_key=key, json_path=tmp_path / "sawyer.json") as proc:
        r = _cli("--config", str(box), "--link", "mavlink", "--serial", f"serial:{proc.endpoint}?key={key.hex()}",
                 "--joints", str(walk), "--log", str(log), "--quiet")
    assert r.returncode == 0, r.stderr
    summary = json.loads(log.read_text().splitlines()[-1])["summary"]
    assert summary["retracts"] == 1 and summary["states"].get("LEVEL2", 0) > 0
    assert summary["robot_link"]["integrity_errors"] == 0 and summary["robot_link"]["states"] > 100
    assert summary["reaction_ms"]["n"] >= 3 and "reaction" in r.stdout
    sawyer = proc.result
    assert sawyer["mode"] == "stopped" and sawyer["counters"]["refused"] == 0  # the final stop; nothing refused


def test_a_stalled_live_camera_is_caught_by_the_staleness_check():
    """--camera: frames come from a reader thread; while the camera stalls the loop keeps
    ticking, so the arm is stopped for a stale pose (not left to the arm's watchdog)."""
    import time

    from edge_runtime.robot.loop import RobotLoop

    link = FakeLink()
    loop = RobotLoop(link)
    j = human.joints(BODY, human.Posture(), pelvis_xz_m=(0.0, 6.0))

    def camera():
        for _ in range(40):  # 30 Hz for 1.3 s, then the camera stalls for 0.6 s
            time.sleep(1 / 30)
            yield 0.0, (lambda lp: lp.feed_joints(j))
        time.sleep(0.6)

    seen = [feed(loop).state for _, feed in robot_cli._live_frames(loop, camera(), time.monotonic(), None)]
    s = loop.status()
    assert "NORMAL" in seen and s["state"] == "FAULT" and s["reason"] == "pose_stale" and s["stale"] == 1
    assert [c for c in link.calls if c[0] != "heartbeat"][-1] == ("stop",)


class _Timeline:
    """A fake monotonic clock whose sleep() moves it on, and a loop stand-in whose tick() writes
    ("tick", now) on the same timeline as the frames ("frame", now)."""

    def __init__(self):
        self.now_s, self.events = 0.0, []

    def clock(self) -> float:
        return self.now_s

    def sleep(self, s: float) -> None:
        self.now_s += s

    def tick(self) -> None:
        self.events.append(("tick", self.now_s))

    def replay(self, times_s, frame_cpu_s: float):
        """Replays frames at ``times_s`` as ``run_loop`` does, each taking ``frame_cpu_s``."""
        frames = ((t, None) for t in times_s)
        for _ in robot_cli._replayed_frames(self, frames, 0.0, None, self.clock, self.sleep):
            self.events.append(("frame", self.now_s))
            self.now_s += frame_cpu_s


def test_a_replayed_frame_goes_first_and_its_tick_right_after():
    """The real-time replay ticks the loop after each frame and every TICK_S in between, but not at a
    frame's due time in front of it (a tick there would count in the frame's reaction)."""
    times = [k / 30 for k in range(10)]
    tl = _Timeline()
    tl.replay(times, frame_cpu_s=0.004)
    frames = [i for i, (what, _) in enumerate(tl.events) if what == "frame"]
    assert [tl.events[i][1] for i in frames] == pytest.approx(times)  # each frame at its due time, not later
    for i in frames[1:]:
        assert tl.events[i - 1][0] == "tick" and tl.events[i - 1][1] < tl.events[i][1] - 1e-9
    for i in frames:  # its tick right after it
        assert tl.events[i + 1] == ("tick", pytest.approx(tl.events[i][1] + 0.004))


def test_a_replay_still_has_a_control_cycle_every_tick_period():
    """Between frames (here up to 0.25 s apart) the loop is ticked every TICK_S; with the frames, a
    tick or a frame comes at least every TICK_S, and the replay ends with ticks after the last frame."""
    tl = _Timeline()
    tl.replay([0.0, 1 / 30, 0.1, 0.35, 0.36], frame_cpu_s=0.003)
    starts = [t for _, t in tl.events]
    assert max(b - a for a, b in zip(starts, starts[1:])) <= robot_cli.TICK_S + 1e-9
    last_frame = max(t for what, t in tl.events if what == "frame")
    assert [w for w, t in tl.events if t > last_frame] == ["tick", "tick"]
    assert tl.events[-1][1] >= last_frame + robot_cli.TICK_S


# ------------------------------------------------------------------ --link none: an offline replay


def test_link_none_fast_logs_each_persons_head_as_given_and_says_no_arm(tmp_path, capsys):
    rows = []
    for i in range(150):                                  # two workers, 5 s; one walks at the arm
        a = human.joints(BODY, human.Posture(), pelvis_xz_m=(0.0, 9.0 - 1.2 * i / 30), heading_rad=np.pi)
        b = human.joints(BODY, human.Posture(), pelvis_xz_m=(6.0, 6.0), heading_rad=np.pi)
        rows.append({"t": i / 30, "people": [{"id": 4, "joints_robot_m": a.round(4).tolist()},
                                             {"id": 9, "joints_robot_m": b.round(4).tolist()}]})
    src = write_jsonl(tmp_path / "j.jsonl", rows)
    log = tmp_path / "log.jsonl"
    assert main(["robot", "--link", "none", "--fast", "--joints", str(src), "--log", str(log), "--quiet"]) == 0
    lines = [json.loads(x) for x in log.read_text().splitlines()]
    frames, summary = lines[:-1], lines[-1]["summary"]
    assert len(frames) == 150
    for row, rec in zip(rows, frames):
        got = {p["id"]: p for p in rec["people"]}
        for person in row["people"]:
            assert np.abs(np.subtract(got[person["id"]]["head_robot_m"], person["joints_robot_m"][10])).max() <= 1e-3
    last = {p["id"]: p for p in frames[-1]["people"]}
    assert last[4]["nearest_distance_m"] < last[9]["nearest_distance_m"] and last[4]["predicted_head_m"] is not None
    states = {f["state"] for f in frames}  # the shipped whole-body monitor may go straight to level 2
    assert "NORMAL" in states and states & {"LEVEL1", "LEVEL2"} and frames[-1]["state"] != "NORMAL"
    assert any(f["command"] == "stop" for f in frames)
    assert summary["link_verdict"].startswith("none: no arm was connected") and summary["fast"] is True
    assert summary["recording_s"] == pytest.approx(149 / 30, abs=1e-3)
    assert "ok" not in summary["link_verdict"].split(";")[0]
    assert "no arm was connected" in capsys.readouterr().out


def test_fast_needs_link_none(tmp_path):
    src = approach(tmp_path / "j.jsonl")
    assert main(["robot", "--link", "can", "--fast", "--joints", str(src)]) == 2


def test_the_heap_is_settled_once_before_the_loop_runs(tmp_path, monkeypatch):
    from edge_runtime.core import heap
    calls = []
    monkeypatch.setattr(heap, "settle", lambda: calls.append(1) or 0)
    assert main(["robot", "--link", "none", "--fast", "--joints", str(approach(tmp_path / "j.jsonl")),
                 "--quiet"]) == 0
    assert calls == [1]
