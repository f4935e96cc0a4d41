"""python -m firmware_sim head-error: a tiny run through the CLI."""
import json
import subprocess
import sys

import pytest

from firmware_sim.scenarios.head_error import BINS_M

pytestmark = pytest.mark.slow  # every test here starts a process


def run(*args):
    return subprocess.run([sys.executable, "-m", "firmware_sim", "head-error", *args],
                          capture_output=True, text=True, timeout=300)


def test_a_tiny_run_writes_the_figures(tmp_path):
    out = tmp_path / "he.json"
    r = run("--placements", "2", "--seed", "4", "--json", str(out), "--plot", str(tmp_path / "he.png"),
            "--ray-tolerance-px", "1.5")
    assert r.returncode == 0, r.stderr
    data = json.loads(out.read_text())
    assert "--ray-tolerance-px 1.5" in data["command"]
    assert set(data["methods"]) == {"off", "on"} and len(data["per_placement"]) == 2
    assert data["frames"] > 100
    for m in data["methods"].values():
        assert list(m["by_distance"]) == [f"{lo}-{lo + 1}m" for lo in BINS_M[:-1]]
        a = m["all"]
        assert a["n"] == data["frames"] and 0 < a["error_ground_m"]["median"] <= a["error_3d_m"]["median"]
        assert a["error_3d_m"]["median"] <= a["error_3d_m"]["p95"]
        assert sum(b["n"] for b in m["by_distance"].values()) <= a["n"]
        far = m["farther_from_arm"]  # the signed side: how often the head is placed farther from the arm
        assert 0 <= far["share_over_0.3_m"] <= far["share_over_0.1_m"] <= far["share_over_0_m"] <= 1
        assert far["p95_m"] <= far["p99_m"]
    assert 0 <= data["anchoring"]["applied_fraction"] <= 1
    assert data["true_depth"]["all"]["n"] == data["frames"]
    assert data["calibration_pose_error"]["rotation_deg"]["median"] > 0  # a fit from noisy keypoints is not exact
    assert all("rotation_deg" in p and "camera_position_m" in p for p in data["per_placement"])
    assert (tmp_path / "he.png").stat().st_size > 1000


@pytest.mark.parametrize("args, word", [(["--placements", "0"], "--placements"),
                                        (["--anchor", "maybe"], "--anchor"),
                                        (["--json", "/nonexistent/dir/x.json"], "/nonexistent/dir"),
                                        (["--assets", "/nonexistent/assets"], "lifter int8"),
                                        (["--ray-tolerance-px", "9"], "ray_tolerance_px")])
def test_bad_arguments_are_one_line_and_exit_2(tmp_path, args, word):
    if "--json" not in args:
        args = [*args, "--json", str(tmp_path / "x.json")]
    r = run(*args)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and word in r.stderr


def test_the_pose_error_of_a_calibration_is_its_rotation_and_camera_offset():
    import numpy as np

    from firmware_sim.devices.camera import random_placement
    from firmware_sim.scenarios.head_error import calibration_error, true_calibration

    camera = random_placement(np.random.default_rng(3))
    cal = true_calibration(camera)
    e = calibration_error(cal, camera)
    assert e["rotation_deg"] < 1e-4 and e["camera_position_m"] < 1e-9
    turn = np.radians(5.0)  # the fit turned 5 deg about the vertical, the camera 0.2 m too high, scale 1.1
    Ry = np.array([[np.cos(turn), 0, np.sin(turn)], [0, 1, 0], [-np.sin(turn), 0, np.cos(turn)]])
    cal.A, cal.b = 1.1 * Ry @ cal.A, cal.b + [0.0, 0.2, 0.0]
    e = calibration_error(cal, camera)
    assert abs(e["rotation_deg"] - 5.0) < 1e-6 and abs(e["camera_height_m"] - 0.2) < 1e-9
    assert abs(e["camera_position_m"] - 0.2) < 1e-9 and abs(e["scale"] - 1.1) < 1e-9


def test_unlabelled_calibration_is_the_runtimes_own_and_says_so(tmp_path):
    out = tmp_path / "he.json"
    r = run("--placements", "2", "--seed", "4", "--unlabelled", "--calibration-method", "pnp", "--json", str(out))
    assert r.returncode == 0, r.stderr
    data = json.loads(out.read_text())
    assert data["labelled_calibration"] is False and "--unlabelled" in data["command"]
    assert len(data["per_placement"]) == 2
    made = len(data["per_placement"]) - len(data["calibrations_refused"])
    assert made == 0 or 0 <= data["calibration_pose_error"]["over_10_deg"] <= made
