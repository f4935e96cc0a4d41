"""The simulated chapter-4 worker: cohort, reach and gaze, styles, variation, own comfort optimum."""
import math
from dataclasses import replace

import numpy as np
import pytest

from edge_runtime.core.skeleton import BASE_HEIGHT_M, INDEX
from edge_runtime.posture.cap import cap_score
from firmware_sim.people.human import Body
from firmware_sim.people.worker import EYE_MOVER, NECK_BENDER, Worker, make_cohort


def test_cohort_is_half_women_with_the_dissertations_stature():
    c = make_cohort(20, 0)
    assert [w.body.sex for w in c].count("F") == 10
    h = np.array([w.body.height_m for w in c])
    assert 1.64 < h.mean() < 1.80 and 0.06 < h.std(ddof=1) < 0.16
    assert {w.style.kind for w in c} == {"eye-mover", "neck-bender"}
    assert [w.body.height_m for w in make_cohort(20, 0)] == list(h)          # reproducible
    assert [w.body.height_m for w in make_cohort(20, 1)] != list(h)


@pytest.mark.parametrize("height_m,pitch_deg", [(0.9, 0.0), (1.055, 0.0), (1.25, 30.0), (1.4, 50.0)])
def test_hands_are_on_the_board(height_m, pitch_deg):
    w = Worker(1, Body.from_height(1.72, "M"), EYE_MOVER)
    wp = w.posture_at(height_m, pitch_deg)
    assert wp.reach_error_m < 0.005
    _, _, target = w.board(height_m, pitch_deg)
    j = w.perform(height_m, pitch_deg, np.random.default_rng(0))
    # one repetition varies, but the wrists stay near the grasp point
    assert np.linalg.norm(j[INDEX["right_wrist"], 1:] - target[1:]) < 0.08


def test_a_low_board_bends_the_trunk_of_a_tall_worker():
    w = Worker(1, Body.from_height(1.88, "M"), EYE_MOVER)
    low, good = w.posture_at(0.90, 0.0), w.posture_at(1.25, 30.0)
    assert low.posture.trunk_flexion_deg > good.posture.trunk_flexion_deg + 10.0


def test_neck_benders_bend_the_neck_and_eye_movers_move_the_eyes():
    body = Body.from_height(1.72, "F")
    bender = Worker(1, body, NECK_BENDER).posture_at(1.10, 0.0)
    mover = Worker(2, body, EYE_MOVER).posture_at(1.10, 0.0)
    assert bender.posture.neck_flexion_deg > mover.posture.neck_flexion_deg + 8.0
    assert mover.eye_rotation_deg > bender.eye_rotation_deg + 8.0


def test_tilting_the_board_toward_the_face_helps():
    w = Worker(1, Body.from_height(1.75, "M"), EYE_MOVER)
    flat, tilted = w.posture_at(1.30, 0.0), w.posture_at(1.30, 40.0)
    assert tilted.view_deg < flat.view_deg and tilted.cost < flat.cost


def test_repetitions_vary_but_are_reproducible():
    w = make_cohort(1, 0)[0]
    a = w.perform(1.1, 10.0, np.random.default_rng(5))
    b = w.perform(1.1, 10.0, np.random.default_rng(5))
    c = w.perform(1.1, 10.0, np.random.default_rng(6))
    assert np.array_equal(a, b) and not np.allclose(a, c)
    caps = [cap_score(w.perform(1.1, 10.0, np.random.default_rng(k))).cap for k in range(12)]
    assert 0.02 < np.std(caps) < 0.6


def test_worker_selected_is_the_workers_own_comfort_optimum():
    w = make_cohort(2, 0)[1]
    h, a = w.selected_position()
    best = w.comfort(h, a)
    for hh, aa in ((1.055, 0.0), (w.elbow_height_m(), 0.0), (h + 0.1, a), (h - 0.1, a), (h, a - 20.0)):
        assert best <= w.comfort(hh, aa) + 1e-6


def test_comfort_is_not_cap_a_shoulder_averse_worker_picks_a_lower_board():
    body = Body.from_height(1.70, "F")
    plain = Worker(1, body, NECK_BENDER)
    averse = Worker(2, body, replace(NECK_BENDER, shoulder_weight=4.0))
    h_plain, _ = plain.selected_position()
    h_averse, a_averse = averse.selected_position()
    assert h_averse < h_plain - 0.03
    # at the lower board this worker's neck is more flexed: CAP disagrees with the worker's choice
    assert averse.posture_at(h_averse, a_averse).posture.neck_flexion_deg > \
        averse.posture_at(h_plain, a_averse).posture.neck_flexion_deg


def test_elbow_height_follows_stature():
    short, tall = (Worker(1, Body.from_height(h, "M")) for h in (1.60, 1.90))
    assert short.elbow_height_m() == pytest.approx(0.632 * 1.60, abs=0.01)
    assert tall.elbow_height_m() - short.elbow_height_m() == pytest.approx(0.632 * 0.30, abs=0.01)


def test_joints_are_in_the_robot_frame_facing_the_robot():
    w = Worker(1, Body.from_height(1.72, "M"))
    j = w.perform(1.1, 0.0, np.random.default_rng(0))
    feet = min(j[INDEX["left_ankle"], 1], j[INDEX["right_ankle"], 1]) + BASE_HEIGHT_M
    assert feet == pytest.approx(0.039 * 1.72, abs=0.01)                     # on the floor
    assert j[INDEX["hip"], 2] > w.workpiece_xz_m[1]                           # on the work side (+z)
    assert j[INDEX["right_wrist"], 2] < j[INDEX["hip"], 2]                    # reaching toward the robot
    assert not math.isnan(cap_score(j).cap)


class _DepthOracleLifter:
    """Stands in for the pose lifter: back-projects each 2D keypoint at the true depth of the
    posture (what a perfect lifter would recover), so the test checks the vision path's
    plumbing (camera frames, timestamps, invalid frames), not a model."""

    def __init__(self, camera, truth_m):
        self.camera = camera
        self.depth = camera.to_camera(truth_m)[:, 2]
        self.restarts = 0
        self.times = []

    def restart(self):
        self.restarts += 1

    def push(self, t_s, kp):
        from edge_runtime.robot.lifter import LiftedPose

        self.times.append(t_s)
        k = self.camera.intrinsics
        uv = np.asarray(kp, float)[:, :2]
        ok = bool(np.isfinite(uv).all())
        xyz = np.column_stack([(uv[:, 0] - k.cx_px) / k.fx_px * self.depth,
                               (uv[:, 1] - k.cy_px) / k.fy_px * self.depth, self.depth])
        return LiftedPose(t_s, xyz if ok else np.full((17, 3), np.nan), xyz[0], ok,
                          None if ok else "missing_joints: some", np.isfinite(uv).all(1))


def test_vision_path_measures_cap_close_to_the_true_joints():
    from edge_runtime.posture.cap import cycle_cap
    from firmware_sim.devices.camera import Camera, DetectorNoise
    from firmware_sim.people.worker import VisionPath

    w = Worker(1, Body.from_height(1.72, "M"), NECK_BENDER)
    truth = w.perform(1.1, 0.0, np.random.default_rng(0))
    cam = Camera.look_at((3.0, 0.6, 1.1), (0.0, 0.2, 1.1))
    lifter = _DepthOracleLifter(cam, truth)
    vp = VisionPath(lifter, cam, frames=30, noise=DetectorNoise().scaled(0.25))
    seen = vp.observe(truth, np.random.default_rng(1))
    assert seen.shape == (30, 17, 3) and lifter.restarts == 1
    assert np.all(np.diff(lifter.times) > 0)
    assert np.nanmax(np.abs(np.nanmedian(seen, axis=0) - truth)) < 0.05          # back in the robot frame
    assert abs(cycle_cap(seen).cap - cap_score(truth).cap) < 0.6
    # a worker the detector never finds: no CAP, and the result says why
    blind = VisionPath(_DepthOracleLifter(cam, truth), cam, frames=10, noise=replace(DetectorNoise(), p_miss_frame=1.0))
    r = cycle_cap(blind.observe(truth, np.random.default_rng(2)))
    assert not r.valid and "0 of 10" in r.reason
