"""python -m edge_runtime lift: JSON lines or a video in, one JSON object per frame and a summary out."""
import json
import subprocess
import sys

import numpy as np
import pytest
from support import REPO_ROOT
from support.camera import make_pose_model, write_video
from support.lifter import make_lifter_assets, random_walk_keypoints

from edge_runtime.__main__ import main
from edge_runtime.robot.keypoints import CameraModel
from edge_runtime.robot.lifter import LifterParams, StreamingLifter

ROOT = REPO_ROOT
PERIOD = 1 / 30


@pytest.fixture(scope="module")
def assets(tmp_path_factory):
    return make_lifter_assets(tmp_path_factory.mktemp("lift_assets"))


def _keypoint_file(tmp_path, n=40, seed=0):
    """COCO keypoints of a 1920x1080 camera, two people (the larger one followed), with
    faults: a NaN hip for 6 frames (his trunk: not lifted without it), a frame with 15 keypoints, nobody for 2 frames."""
    rng = np.random.default_rng(seed)
    kp = random_walk_keypoints(rng, n, 1920, 1080)
    kp[10:16, 11, :2] = np.nan
    small = kp * [0.2, 0.2, 1.0]
    lines = []
    for i in range(n):
        people = [{"id": 7, "keypoints": small[i].tolist()}, {"id": 1, "keypoints": kp[i].tolist()}]
        if i == 20:
            people[1]["keypoints"] = kp[i][:15].tolist()
        if i in (30, 31):
            people = []
        lines.append(json.dumps({"t": i * PERIOD, "frame": i, "people": people, "format": "coco"},
                                allow_nan=True).replace("NaN", "null"))
    p = tmp_path / "kp.jsonl"
    p.write_text("\n".join(lines) + "\n")
    return p, kp


def _lift(assets, tmp_path, *extra):
    out = tmp_path / "out.jsonl"
    rc = main(["lift", "--assets", str(assets), "--precision", "fp32", "--out", str(out), *extra])
    return rc, out


def _read(out):
    lines = [json.loads(line) for line in out.read_text().splitlines()]
    return lines[:-1], lines[-1]["summary"]


def test_keypoint_file_to_3d(assets, tmp_path, capsys):
    kp_file, kp = _keypoint_file(tmp_path)
    rc, out = _lift(assets, tmp_path, "--keypoints", str(kp_file), "--format", "coco", "--width", "1920",
                    "--height", "1080", "--hold-frames", "3")
    assert rc == 0
    frames, summary = _read(out)
    assert len(frames) == 40 and [f["frame"] for f in frames] == list(range(40))
    assert all(f["person"] == 1 for f in frames if f["frame"] not in (30, 31))
    valid = [f["valid"] for f in frames]
    # hip NaN 10..15: held 3 frames, invalid 13..15; 15 joints at 20 and nobody at 30, 31: all held
    assert [i for i, v in enumerate(valid) if not v] == [13, 14, 15]
    assert frames[13]["reason"].startswith("missing_joints") and "left_hip" in frames[13]["reason"]
    assert frames[13]["joints_cam_m"] is None
    for i in (20, 30, 31):
        assert frames[i]["valid"] and not any(frames[i]["observed"])
    assert summary["frames"] == 40 and summary["valid"] == 37 and summary["valid_share"] == pytest.approx(0.925)
    assert summary["invalid"] == {"missing_joints": 3} and summary["mean_infer_ms"] > 0
    assert summary["wrong_joint_count"] == 1 and summary["no_person"] == 2 and summary["frames_interpolated"] == 3
    assert summary["model"] == "lifter-fp32"
    # the same answers as the library with the same camera (100 deg FOV at 1920x1080)
    lifter = StreamingLifter.from_manifest(assets, LifterParams(precision="fp32"),
                                           camera=CameraModel.from_fov(1920, 1080), keypoint_format="coco")
    for i in range(12):
        np.testing.assert_allclose(frames[i]["joints_cam_m"], lifter.push(i * PERIOD, kp[i]).joints_cam_m, atol=1e-4)
    printed = capsys.readouterr().out
    assert "40 frames, valid 37 (92.5%" in printed and "mean lifter time" in printed


def test_camera_file_and_person_by_id(assets, tmp_path):
    kp_file, _ = _keypoint_file(tmp_path)
    cam = tmp_path / "cam.json"
    cam.write_text(json.dumps({"fx_px": 1100.0, "fy_px": 1100.0, "cx_px": 960.0, "cy_px": 540.0, "width_px": 1920,
                               "height_px": 1080, "dist": [-0.2, 0.05, 0.0, 0.0, 0.0]}))
    rc, out = _lift(assets, tmp_path, "--keypoints", str(kp_file), "--camera", str(cam), "--person", "id:7")
    assert rc == 0
    frames, summary = _read(out)
    assert {f["person"] for f in frames} == {7, None}
    assert summary["camera"]["dist"] == [-0.2, 0.05, 0.0, 0.0, 0.0]


@pytest.mark.parametrize("content, message", [
    ('{"t": 0, "people": []}\n{"t": 0.03, "people": [}\n', "kp.jsonl:2: not valid JSON"),
    ("", "kp.jsonl: no frames"),
])
def test_malformed_keypoint_file_is_one_line_exit_2(assets, tmp_path, capsys, content, message):
    p = tmp_path / "kp.jsonl"
    p.write_text(content)
    rc, out = _lift(assets, tmp_path, "--keypoints", str(p), "--width", "640", "--height", "480")
    err = capsys.readouterr().err
    assert rc == 2 and message in err and len(err.strip().splitlines()) == 1
    assert not out.exists()  # checked before anything is written


def test_bad_usage_and_tampered_model(assets, tmp_path, capsys):
    kp_file, _ = _keypoint_file(tmp_path, n=3)
    rc, _ = _lift(assets, tmp_path, "--keypoints", str(kp_file))
    assert rc == 2 and "--width and --height" in capsys.readouterr().err
    cam = tmp_path / "cam.json"
    cam.write_text(json.dumps(CameraModel.from_fov(640, 480).to_dict()))
    rc, _ = _lift(assets, tmp_path, "--keypoints", str(kp_file), "--camera", str(cam), "--width", "800")
    assert rc == 2 and "--width 800 disagrees" in capsys.readouterr().err
    rc, _ = _lift(assets, tmp_path, "--keypoints", str(kp_file), "--width", "640", "--height", "480",
                  "--person", "tallest")
    assert rc == 2 and "--person tallest" in capsys.readouterr().err
    import shutil

    d = tmp_path / "tampered"
    shutil.copytree(assets, d)
    (d / "lifter.fp32.onnx").write_bytes((d / "lifter.fp32.onnx").read_bytes()[:-1] + b"\1")
    rc = main(["lift", "--assets", str(d), "--precision", "fp32", "--keypoints", str(kp_file),
               "--width", "640", "--height", "480"])
    err = capsys.readouterr().err
    assert rc == 2 and "lifter.fp32.onnx" in err and "sha256" in err


def test_video_with_pose_model(assets, tmp_path):
    video = write_video(tmp_path / "v.avi", n=6, size=(160, 80), bgr=(0, 0, 255), fps=30)
    pose = make_pose_model(tmp_path / "pose.onnx")
    rc, out = _lift(assets, tmp_path, "--video", str(video), "--pose-model", str(pose), "--quiet")
    assert rc == 0
    frames, summary = _read(out)
    assert len(frames) == 6 and all(f["valid"] for f in frames)
    assert summary["camera"]["width_px"] == 160 and summary["camera_source"]["frames"] == 6
    assert summary["camera_source"]["ended"] == 1


def test_video_errors_exit_2(assets, tmp_path, capsys):
    rc, _ = _lift(assets, tmp_path, "--video", str(tmp_path / "none.avi"), "--pose-model", str(tmp_path / "p.onnx"))
    assert rc == 2 and "p.onnx: pose model file not found" in capsys.readouterr().err
    pose = make_pose_model(tmp_path / "pose.onnx")
    rc, _ = _lift(assets, tmp_path, "--video", str(tmp_path / "none.avi"), "--pose-model", str(pose))
    assert rc == 2 and "none.avi: video file not found" in capsys.readouterr().err
    rc, _ = _lift(assets, tmp_path, "--video", str(tmp_path / "none.avi"))
    assert rc == 2 and "--pose-model" in capsys.readouterr().err


@pytest.mark.slow
def test_subprocess_exit_status_and_no_traceback(tmp_path):
    p = tmp_path / "kp.jsonl"
    p.write_text('{"t": 0, "people": [{"keypoints": [1, 2]}]\n')
    r = subprocess.run([sys.executable, "-m", "edge_runtime", "lift", "--keypoints", str(p), "--width", "10",
                        "--height", "10"], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.strip().startswith(f"error: {p}:1: not valid JSON (Expecting ','")
    assert len(r.stderr.strip().splitlines()) == 1


def test_config_lifter_section_and_flags(assets, tmp_path, capsys):
    kp_file, _ = _keypoint_file(tmp_path)
    box = tmp_path / "box.toml"
    box.write_text("[lifter]\nhold_frames = 0\nprecision = \"int8\"\n")
    rc, out = _lift(assets, tmp_path, "--keypoints", str(kp_file), "--width", "1920", "--height", "1080",
                    "--config", str(box))
    assert rc == 0
    frames, summary = _read(out)
    assert summary["model"] == "lifter-fp32"  # the flag --precision fp32 beats the file
    # no holding: the NaN hip (10..15), the 15-joint frame (20) and nobody (30, 31) are all invalid
    assert [f["frame"] for f in frames if not f["valid"]] == [10, 11, 12, 13, 14, 15, 20, 30, 31]
    rc, _ = _lift(assets, tmp_path, "--keypoints", str(kp_file), "--width", "1920", "--height", "1080",
                  "--hold-frames", "-1")
    err = capsys.readouterr().err
    assert rc == 2 and "[lifter] hold_frames" in err and len(err.strip().splitlines()) == 1
