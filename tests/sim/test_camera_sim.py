"""The simulated camera and 2D detector (firmware_sim/devices/camera.py)."""
import math

import numpy as np
import pytest

from edge_runtime.core import skeleton as sk
from edge_runtime.robot.keypoints import CameraModel, coco_to_h36m, read_keypoints_jsonl
from firmware_sim.devices.camera import (
    CELL_TARGET_M,
    F_PX,
    PERFECT,
    TYPICAL_WEBCAM_DIST,
    Camera,
    DetectorNoise,
    detect,
    random_placement,
    resample,
    to_model_input,
    write_jsonl,
)
from firmware_sim.people import motions as mo
from firmware_sim.people.human import Body, Posture, joints

FLOOR = -sk.BASE_HEIGHT_M
BODY = Body.from_height(1.75)


def test_canonical_camera_has_a_100_degree_horizontal_field_of_view():
    assert F_PX == pytest.approx(640 / math.tan(math.radians(50)))
    cam = Camera.look_at((0, 0, 0), (0, 0, 1))          # looking along +z from the origin
    edge = cam.project(np.array([[-math.sin(math.radians(50)), 0, math.cos(math.radians(50))]]))
    assert edge[0] == pytest.approx([1280.0, 360.0], abs=1e-6)   # image right = the robot's -x here
    assert np.isnan(cam.project(np.array([[0.0, 0.0, -1.0]]))).all()   # behind the camera


def test_look_at_centres_the_target_with_the_image_upright():
    eye, target = np.array([4.0, 1.5, 6.0]), np.array([0.0, 0.1, 0.9])
    cam = Camera.look_at(eye, target)
    assert np.allclose(cam.R @ cam.R.T, np.eye(3)) and np.linalg.det(cam.R) == pytest.approx(1.0)
    assert cam.position_m == pytest.approx(eye)
    assert cam.project(target[None])[0] == pytest.approx([640.0, 360.0], abs=1e-6)
    above = cam.project((target + [0, 0.5, 0])[None])[0]
    assert above[1] < 360.0 and abs(above[0] - 640.0) < 1.0
    assert np.allclose(cam.to_robot(cam.to_camera(target)), target)


def test_random_placements_follow_the_dissertation_and_see_the_cell():
    rng = np.random.default_rng(0)
    for _ in range(50):
        cam = random_placement(rng)
        pos = cam.position_m
        horiz = np.hypot(pos[0] - CELL_TARGET_M[0], pos[2] - CELL_TARGET_M[2])
        assert 3.0 <= horiz <= 8.0 and 1.0 <= pos[1] - FLOOR <= 3.0
        assert cam.in_image(cam.project(np.array(CELL_TARGET_M)[None]))[0]


def test_distorted_pixels_undistort_back_to_the_canonical_camera():
    cam = Camera.look_at((3.0, 1.0, 5.0))
    wide = cam.with_intrinsics(CameraModel(F_PX, F_PX, 640.0, 360.0, 1280, 720, TYPICAL_WEBCAM_DIST))
    # the central part of the image (cv2.undistortPoints' default 5 iterations leave ~1 px in the corners)
    u, v = np.meshgrid(np.linspace(-0.6, 0.6, 7), np.linspace(-0.4, 0.4, 5))
    j = cam.to_robot(np.stack([u.ravel(), v.ravel(), np.ones(u.size)], 1) * 4.0)
    raw, ideal = wide.project(j), cam.project(j)
    assert np.abs(raw - ideal).max() > 3.0                    # the distortion is visible
    assert np.abs(to_model_input(raw, wide) - to_model_input(ideal)).max() * 640 < 0.05   # < 0.05 px


def test_detector_noise_shrinks_with_distance_and_perfect_is_exact():
    walk = mo.walk(BODY, [(0, 1), (0, 2)], 1.0)
    noise = DetectorNoise(p_outlier=0, p_swap=0, p_miss=0, p_miss_frame=0)
    errs = []
    for d in (3.0, 8.0):
        cam = Camera.look_at((0.0, 0.5, 1.5 + d), (0.0, 0.0, 1.5))
        det = detect(cam, walk.joints_m, np.random.default_rng(1), noise)
        errs.append(np.median(np.linalg.norm(det[..., :2] - cam.project(walk.joints_m), axis=-1)))
        exact = detect(cam, walk.joints_m, np.random.default_rng(1), PERFECT)
        assert np.allclose(exact[..., :2], cam.project(walk.joints_m)) and (exact[..., 2] > 0.8).all()
    assert errs[0] / errs[1] == pytest.approx(8 / 3, rel=0.3)


def test_missed_and_out_of_image_joints_have_no_position_and_score_zero():
    walk = mo.walk(BODY, [(-3, 1), (3, 1)], 1.4)
    cam = Camera.look_at((0.0, 0.5, 2.5), (0.0, 0.0, 1.0))    # too close: feet and sides leave the image
    det = detect(cam, walk.joints_m, np.random.default_rng(2), DetectorNoise(p_miss=0.05))
    missing = np.isnan(det[..., 0])
    assert np.array_equal(missing, det[..., 2] == 0) and np.isnan(det[missing, :2]).all()
    outside = ~cam.in_image(cam.project(walk.joints_m))
    assert outside.any() and missing[outside].mean() > 0.95
    assert 0.02 < missing[~outside].mean() < 0.4                 # bursts of misses inside the image
    gone = detect(cam, walk.joints_m, np.random.default_rng(2), DetectorNoise(p_miss_frame=1.0))
    assert np.isnan(gone[..., 0]).all()


def test_coco_output_maps_back_to_the_h36m_limbs():
    cam = Camera.look_at((2.0, 1.0, 5.0))
    j = joints(BODY, Posture(elbow_flexion_deg=(60, 20)), (0.3, 1.2), 0.4)[None]
    coco = detect(cam, j, np.random.default_rng(3), PERFECT, fmt="coco")
    back = coco_to_h36m(coco)[0]
    truth = cam.project(j)[0]
    limbs = [sk.R_KNEE, sk.L_ANKLE, sk.L_WRIST, sk.R_ELBOW, sk.NECK]
    assert np.allclose(back[limbs, :2], truth[limbs], atol=1e-6)
    # midpoints in 3D vs midpoints of projections differ only by perspective
    assert np.allclose(back[[sk.HIP, sk.THORAX], :2], truth[[sk.HIP, sk.THORAX]], atol=0.5)
    with pytest.raises(ValueError, match="fmt"):
        detect(cam, j, np.random.default_rng(3), fmt="openpose")


def test_jsonl_export_is_what_the_runtime_reads(tmp_path):
    cam = Camera.look_at((2.0, 1.0, 5.0))
    walk = mo.walk(BODY, [(0, 1), (0, 2)], 1.0)
    det = detect(cam, walk.joints_m, np.random.default_rng(4), DetectorNoise(p_miss=0.05))
    det[3] = np.nan
    det[3, :, 2] = 0
    path = write_jsonl(tmp_path / "kp.jsonl", det, 30.0, fmt="h36m")
    frames = list(read_keypoints_jsonl(path, fmt="h36m"))
    assert len(frames) == len(det) and frames[3].people == []
    assert frames[5].t_s == pytest.approx(5 / 30)
    for k in (0, 10, len(det) - 1):
        got = frames[k].people[0].keypoints
        assert np.allclose(got[:, :2], det[k, :, :2], atol=0.01, equal_nan=True)
        assert np.allclose(got[:, 2], det[k, :, 2], atol=0.001)


def test_resample_to_the_dissertation_rate():
    x = np.arange(31, dtype=float)[:, None, None] * np.ones((1, 17, 3))     # 1 s at 30 Hz, linear
    y = resample(x, 30.0, 5.8)
    assert len(y) == 6 and np.allclose(y[:, 0, 0], np.arange(6) / 5.8 * 30)
