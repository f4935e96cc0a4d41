"""Ground anchoring of lifted skeletons: the floor fixes the lifter's depth."""
import numpy as np
import pytest

from edge_runtime.core.skeleton import BASE_HEIGHT_M, HEAD, L_ANKLE, R_ANKLE
from edge_runtime.robot.calibration import (
    ANCHOR_CAMERA_LOW,
    ANCHOR_NO_ANKLE,
    ANCHOR_RAY_FLAT,
    Calibration,
    CalibrationParams,
    anchor_factor,
)
from firmware_sim.devices.camera import Camera
from firmware_sim.people import human

BODY = human.Body.from_height(1.75)


def true_calibration(cam: Camera, params: CalibrationParams = CalibrationParams()) -> Calibration:
    """The exact camera -> robot map of a simulated camera."""
    z = np.zeros((3, 3))
    return Calibration(cam.R.T, cam.position_m, "rigid", 1.6, z, z, params)


def worker(xz, heading=0.3):
    """A standing worker's robot-frame joints, ankles put exactly at the anchoring's ankle height."""
    j = human.joints(BODY, human.Posture(), pelvis_xz_m=xz, heading_rad=heading)
    floor = -BASE_HEIGHT_M + CalibrationParams().ankle_height_m
    return j - [0.0, min(j[L_ANKLE, 1], j[R_ANKLE, 1]) - floor, 0.0]


def project(p):
    return p[..., :2] / p[..., 2:3]


@pytest.mark.parametrize("scale", [0.8, 0.93, 1.12, 1.3])
def test_recovers_a_known_depth_and_keeps_the_2d_projections(scale):
    cam = Camera.look_at((2.0, 1.2, 6.5), (0.0, -0.2, 1.0))
    cal = true_calibration(cam)
    truth = worker((0.5, 1.5))
    lifted = cam.to_camera(truth) * scale               # a lifter that misjudged the depth
    k, reason = anchor_factor(lifted, cal.A, cal.b, cal.params)
    assert reason is None and k == pytest.approx(1 / scale, rel=1e-6)
    robot, applied = cal.anchor_to_floor(lifted)
    assert applied
    np.testing.assert_allclose(robot, truth, atol=1e-6)
    np.testing.assert_allclose(project(cam.to_camera(robot)), project(lifted), atol=1e-9)
    # without the anchoring the head is off by the depth error
    off = np.linalg.norm(cal.apply(lifted[HEAD]) - truth[HEAD])
    assert off > 0.2 * abs(scale - 1) * np.linalg.norm(cam.to_camera(truth[HEAD]))


def test_uses_the_lower_ankle_of_a_stride():
    cam = Camera.look_at((0.0, 1.5, 6.0), (0.0, -0.2, 1.0))
    cal = true_calibration(cam)
    truth = worker((0.0, 1.5))
    truth[R_ANKLE, 1] += 0.25                           # right foot swinging through the air
    robot, applied = cal.anchor_to_floor(cam.to_camera(truth) * 1.15)
    assert applied
    np.testing.assert_allclose(robot, truth, atol=1e-6)


def test_refuses_a_flat_ray_and_a_low_camera_and_clamps_the_factor():
    truth = worker((0.0, 1.5))
    flat = Camera.look_at((0.0, -0.7, 30.0), (0.0, -0.8, 1.5))     # camera 0.21 m above the floor, far off
    cal = true_calibration(flat)
    lifted = flat.to_camera(truth) * 1.2
    assert anchor_factor(lifted, cal.A, cal.b, cal.params) == (1.0, ANCHOR_CAMERA_LOW)
    robot, applied = cal.anchor_to_floor(lifted)
    assert not applied and np.allclose(robot, cal.apply(lifted))
    far = Camera.look_at((0.0, 0.0, 40.0), (0.0, -0.5, 1.5))       # 0.91 m high, 38 m away: ray ~1.3 deg
    cal = true_calibration(far)
    assert anchor_factor(far.to_camera(truth), cal.A, cal.b, cal.params)[1] == ANCHOR_RAY_FLAT
    near = Camera.look_at((2.0, 1.2, 6.5), (0.0, -0.2, 1.0))
    cal = true_calibration(near)
    k, reason = anchor_factor(near.to_camera(truth) * 2.0, cal.A, cal.b, cal.params)
    assert reason is None and k == cal.params.anchor_min_scale


def test_switched_off_it_is_apply():
    cam = Camera.look_at((2.0, 1.2, 6.5), (0.0, -0.2, 1.0))
    cal = true_calibration(cam, CalibrationParams(ground_anchor=False))
    lifted = cam.to_camera(worker((0.5, 1.5))) * 1.2
    robot, applied = cal.anchor_to_floor(lifted)
    assert not applied and np.allclose(robot, cal.apply(lifted))
    np.testing.assert_allclose(cal.to_robot(lifted[None]), cal.apply(lifted[None]))


def test_nan_joints_give_a_defined_result():
    cam = Camera.look_at((2.0, 1.2, 6.5), (0.0, -0.2, 1.0))
    cal = true_calibration(cam)
    lifted = cam.to_camera(worker((0.5, 1.5))) * 1.2
    one = lifted.copy()
    one[L_ANKLE] = np.nan                              # the other ankle anchors
    k, reason = anchor_factor(one, cal.A, cal.b, cal.params)
    assert reason is None and np.isfinite(k)
    both = lifted.copy()
    both[[L_ANKLE, R_ANKLE]] = np.nan
    assert anchor_factor(both, cal.A, cal.b, cal.params) == (1.0, ANCHOR_NO_ANKLE)
    robot, applied = cal.anchor_to_floor(np.full((17, 3), np.nan))
    assert not applied and np.isnan(robot).all()
    # several people at once: each anchored on its own
    two = np.stack([lifted, cam.to_camera(worker((-1.0, 2.0))) * 0.9])
    out = cal.to_robot(two)
    np.testing.assert_allclose(out[1], worker((-1.0, 2.0)), atol=1e-6)


def test_old_calibration_files_still_load(tmp_path):
    cam = Camera.look_at((2.0, 1.2, 6.5), (0.0, -0.2, 1.0))
    data = true_calibration(cam).to_json()
    for key in ("ground_anchor", "anchor_min_ray_deg", "anchor_min_camera_height_m", "anchor_min_scale",
                "anchor_max_scale"):
        del data["params"][key]
    loaded = Calibration.from_json(data)
    assert loaded.params == CalibrationParams() and np.allclose(loaded.A, cam.R.T)
    with pytest.raises(ValueError, match="anchor_min_scale"):
        CalibrationParams(anchor_min_scale=1.2)


class NullLink:
    """A link that takes every command (no state)."""

    def __getattr__(self, name):
        return lambda *a, **k: None


@pytest.mark.parametrize("anchor", [True, False])
def test_the_robot_loop_anchors_camera_frame_joints_when_the_calibration_says_so(anchor):
    from edge_runtime.robot.loop import RobotLoop

    cam = Camera.look_at((2.0, 1.2, 6.5), (0.0, -0.2, 1.0))
    truth = worker((0.8, 2.2))
    t = iter(np.arange(0, 10, 0.05))
    seen = RobotLoop(NullLink(), clock=lambda: next(t)).feed_joints(truth).distance_m
    loop = RobotLoop(NullLink(), calibration=true_calibration(cam, CalibrationParams(ground_anchor=anchor)),
                     clock=lambda: next(t))
    got = loop.feed_joints(cam.to_camera(truth) * 1.25).distance_m
    assert (got == pytest.approx(seen, abs=1e-6)) == anchor
