"""firmware_sim record: a newcomer's recording, then lift, score-lift and robot --link none on it."""
import json

import numpy as np
import pytest

from edge_runtime.__main__ import main as runtime
from firmware_sim.__main__ import main as sim
from firmware_sim.scenarios.recording import MOTIONS, episode, random_body


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    d = tmp_path_factory.mktemp("rec")
    assert sim(["record", "--out", str(d), "--seconds", "6", "--people", "2", "--seed", "3"]) == 0
    return d


def test_the_recording_holds_keypoints_camera_calibration_walk_and_truth(recording):
    names = {p.name for p in recording.iterdir()}
    assert {"keypoints.jsonl", "camera.json", "calibration.jsonl", "truth.jsonl", "recording.json"} <= names
    frames = [json.loads(x) for x in (recording / "keypoints.jsonl").read_text().splitlines()]
    truth = [json.loads(x) for x in (recording / "truth.jsonl").read_text().splitlines()]
    assert len(frames) == len(truth) and max(len(f["people"]) for f in frames) == 2
    assert all(f["format"] == "coco" for f in frames)
    assert {p["motion"] for row in truth for p in row["people"]} <= set(MOTIONS)
    cam = json.loads((recording / "camera.json").read_text())
    assert cam["dist"][0] < 0  # a wide-angle lens: barrel distortion
    assert json.loads((recording / "recording.json").read_text())["next"]


def test_lifted_joints_project_onto_their_keypoints_and_are_scored_per_motion(recording, tmp_path):
    lifted = tmp_path / "lifted.jsonl"
    assert runtime(["lift", "--keypoints", str(recording / "keypoints.jsonl"), "--camera",
                    str(recording / "camera.json"), "--person", "all", "--out", str(lifted), "--quiet"]) == 0
    out = tmp_path / "score.json"
    assert sim(["score-lift", "--recording", str(recording), "--lifted", str(lifted), "--json", str(out)]) == 0
    res = json.loads(out.read_text())
    assert res["scored_person_frames"] > 100
    assert res["all"]["reprojection_px"]["median"] <= 2 and res["all"]["reprojection_px"]["p95"] <= 5
    assert set(res["by_motion"]) <= set(MOTIONS) and res["all"]["p_mpjpe_mm"] > 0
    # the same rays at the true depth: only the 2D errors are left, less than with the network's depth
    assert 0 < res["all"]["true_depth_on_rays"]["p_mpjpe_mm"] < res["all"]["p_mpjpe_mm"]


def test_calibrate_then_replay_every_person_with_no_arm(recording, tmp_path, capsys):
    cal, log = tmp_path / "cal.json", tmp_path / "replay.jsonl"
    assert runtime(["robot", "--keypoints", str(recording / "calibration.jsonl"), "--intrinsics",
                    str(recording / "camera.json"), "--calibrate", str(cal), "--calibration-method", "pnp"]) == 0
    assert json.loads(cal.read_text())["method"] == "pnp"
    assert runtime(["robot", "--link", "none", "--fast", "--keypoints", str(recording / "keypoints.jsonl"),
                    "--intrinsics", str(recording / "camera.json"), "--calibration", str(cal), "--log", str(log),
                    "--quiet"]) == 0
    lines = [json.loads(x) for x in log.read_text().splitlines()]
    summary = lines[-1]["summary"]
    assert summary["link_verdict"].startswith("none: no arm was connected")
    ids = {p["id"] for rec in lines[:-1] for p in rec["people"]}
    assert len(ids) >= 2  # both people reached the hazard monitor, each with his own id
    assert all(np.isfinite(p["head_robot_m"]).all() for rec in lines[:-1] for p in rec["people"])


@pytest.mark.parametrize("kind", MOTIONS)
def test_every_motion_type_makes_an_episode(kind):
    rng = np.random.default_rng(0)
    m = episode(kind, random_body(rng), (0.0, 3.0), 0.0, (2.0, 4.0), rng)
    assert len(m) > 30 and set(m.labels) == {kind} and np.isfinite(m.joints_m).all()


def test_the_truth_replays_through_the_decision_chain_with_heads_as_given(recording, tmp_path):
    log = tmp_path / "truth_replay.jsonl"
    assert runtime(["robot", "--link", "none", "--fast", "--joints", str(recording / "truth.jsonl"), "--log",
                    str(log), "--quiet"]) == 0
    truth = [json.loads(x) for x in (recording / "truth.jsonl").read_text().splitlines()]
    frames = [json.loads(x) for x in log.read_text().splitlines()][:-1]
    assert len(frames) == len(truth)
    for row, rec in zip(truth, frames):
        got = {p["id"]: p["head_robot_m"] for p in rec["people"]}
        for p in row["people"]:
            assert np.abs(np.subtract(got[p["id"]], p["joints_robot_m"][10])).max() <= 1e-3
