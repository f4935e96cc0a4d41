"""edge_runtime.robot.lifter: the streaming pose lifter on a stand-in ONNX model of the shipped contract.

The stand-in (built here with onnx.helper, random weights) has exactly the lifter's
interface: keypoints_2d (N, 27, 17, 2) -> pose_3d (N, 1, 17, 3), root_3d (N, 1, 3);
every output depends on every input frame, so a wrong buffer order shows.
Other test files import ``make_lifter_assets`` from here.
"""
import json
import shutil

import numpy as np
import pytest
from support.lifter import CANONICAL, F_CANON, RF, make_lifter_assets, random_walk_keypoints

from edge_runtime.core.manifest import (
    CLASSIFIER_ARCHS,
    ModelIntegrityError,
    select_model,
    write_manifest,
)
from edge_runtime.robot.keypoints import CameraModel, normalize_screen
from edge_runtime.robot.lifter import (
    BAD_TIME,
    JOINT_COUNT,
    MISSING_JOINTS,
    NO_PERSON,
    TIME_NOT_INCREASING,
    LifterParams,
    StreamingLifter,
    padded_windows,
)

PERIOD = 1 / 30






@pytest.fixture(scope="module")
def assets(tmp_path_factory):
    return make_lifter_assets(tmp_path_factory.mktemp("lifter_assets"))




def _lifter(assets, **kw) -> StreamingLifter:
    precision = kw.pop("precision", "fp32")
    camera = kw.pop("camera", None)
    fmt = kw.pop("keypoint_format", "h36m")
    return StreamingLifter.from_manifest(assets, LifterParams(precision=precision, **kw), camera=camera,
                                         keypoint_format=fmt)


# ---------------------------------------------------------------------------- golden equivalence


@pytest.mark.parametrize("precision", ["fp32", "int8"])
@pytest.mark.parametrize("seed", [1, 2])
def test_streaming_equals_batch_over_padded_sequence(assets, precision, seed):
    rng = np.random.default_rng(seed)
    n = 45
    kp = random_walk_keypoints(rng, n)
    lifter = _lifter(assets, precision=precision, ray_tolerance_px=0.0)
    stream = [lifter.push(i * PERIOD, kp[i]) for i in range(n)]
    assert all(p.valid for p in stream)
    assert [p.warming_up for p in stream] == [i < RF - 1 for i in range(n)]
    norm = normalize_screen(kp[..., :2], 1280, 720).astype(np.float32)
    pose, root = lifter.lift_windows(padded_windows(norm, RF))
    want = pose + root[:, None, :]
    got = np.stack([p.joints_model_cam_m for p in stream])
    np.testing.assert_allclose(got, want, atol=2e-5)
    # the output keeps the model's depth and lies on the keypoints' rays: it projects onto them
    out = np.stack([p.joints_cam_m for p in stream])
    np.testing.assert_allclose(out[..., 2], want[..., 2], atol=2e-5)
    reproj = out[..., :2] / out[..., 2:] * F_CANON + [640.0, 360.0]
    np.testing.assert_allclose(reproj, kp[..., :2], atol=1e-3)
    np.testing.assert_allclose(np.stack([p.root_cam_m for p in stream]), out[:, 0], atol=1e-12)
    assert lifter.stats.inferences == n and lifter.stats.valid == n and lifter.stats.warming_up == RF - 1
    # the stand-in really uses old frames: a different first frame changes the 27th output
    other = norm.copy()
    other[0] += 0.1
    p2, r2 = lifter.lift_windows(padded_windows(other, RF))
    assert np.abs((p2 + r2[:, None])[RF - 1] - want[RF - 1]).max() > 1e-3
    assert np.allclose((p2 + r2[:, None])[RF], want[RF], atol=1e-5)  # ... and the 28th no longer sees it


@pytest.mark.parametrize("tol_px", [1.5, 5.0])
def test_joints_move_toward_the_model_by_at_most_the_ray_tolerance(assets, tol_px):
    # each joint: the model's depth, on the ray of the point within tol_px of its keypoint nearest to
    # the model joint's own projection (the model joint itself when that projects within tol_px)
    kp = random_walk_keypoints(np.random.default_rng(6), 30)
    lifter = _lifter(assets, ray_tolerance_px=tol_px)
    for i in range(30):
        p = lifter.push(i * PERIOD, kp[i])
    m = p.joints_model_cam_m
    model_px = m[:, :2] / m[:, 2:] * F_CANON + [640.0, 360.0]
    out_px = p.joints_cam_m[:, :2] / p.joints_cam_m[:, 2:] * F_CANON + [640.0, 360.0]
    np.testing.assert_allclose(p.joints_cam_m[:, 2], m[:, 2], atol=1e-9)
    gap = np.linalg.norm(model_px - kp[29, :, :2], axis=1)
    moved = np.linalg.norm(out_px - kp[29, :, :2], axis=1)
    assert (gap > tol_px).any()
    np.testing.assert_allclose(moved, np.minimum(gap, tol_px), atol=1e-6)
    # toward the model's projection: what is left of the gap is the gap less the distance moved
    np.testing.assert_allclose(np.linalg.norm(model_px - out_px, axis=1), gap - np.minimum(gap, tol_px), atol=1e-6)


def test_dropped_frame_is_interpolated_into_the_buffer(assets):
    rng = np.random.default_rng(3)
    kp = random_walk_keypoints(rng, 40)
    lifter = _lifter(assets)
    keep = [i for i in range(40) if i not in (20, 31, 32)]
    out = {i: lifter.push(i * PERIOD, kp[i]) for i in keep}
    assert all(p.valid for p in out.values())
    assert lifter.stats.frames_dropped == 3 and lifter.stats.frames_interpolated == 3
    norm = normalize_screen(kp[..., :2], 1280, 720)
    filled = norm.copy()
    filled[20] = (norm[19] + norm[21]) / 2
    filled[31] = norm[30] + (norm[33] - norm[30]) / 3
    filled[32] = norm[30] + (norm[33] - norm[30]) * 2 / 3
    pose, root = lifter.lift_windows(padded_windows(filled.astype(np.float32), RF))
    for i in keep:
        np.testing.assert_allclose(out[i].joints_model_cam_m, pose[i] + root[i], atol=2e-5)


# ---------------------------------------------------------------------------- missing data


def test_low_score_and_nan_joints_are_held_then_the_frame_is_invalid(assets):
    rng = np.random.default_rng(4)
    kp = random_walk_keypoints(rng, 12)
    lifter = _lifter(assets, hold_frames=2, min_score=0.5)
    p0 = lifter.push(0.0, kp[0])
    assert p0.valid and p0.observed.all()
    kp[1:, 4, 2] = 0.2           # left hip: low score from frame 1 on
    kp[2:, 3, 0] = np.nan        # right ankle: NaN from frame 2 on
    p1 = lifter.push(PERIOD, kp[1])
    assert p1.valid and not p1.observed[4] and p1.observed.sum() == 16
    # the held hip is the frame-0 observation: the buffer's last frame holds it
    np.testing.assert_allclose(lifter.window()[-1, 4], normalize_screen(kp[0, 4, :2], 1280, 720), atol=1e-6)
    p2 = lifter.push(2 * PERIOD, kp[2])
    assert p2.valid and not p2.observed[3]
    before = lifter.window().copy()
    p3 = lifter.push(3 * PERIOD, kp[3])  # a hip (the trunk: required) missing for 3 frames > hold 2
    assert not p3.valid and p3.code == MISSING_JOINTS and "left_hip" in p3.reason
    assert "right_ankle" not in p3.reason  # the ankle is still within its hold
    assert np.isnan(p3.joints_cam_m).all() and np.isnan(p3.root_cam_m).all()
    assert p3.to_json()["joints_cam_m"] is None
    np.testing.assert_array_equal(lifter.window(), before)  # nothing fed through
    assert lifter.stats.invalid[MISSING_JOINTS] == 1 and lifter.stats.joints_held == 3  # hip x2, ankle x1
    assert lifter.stats.inferences == 3
    # the hip comes back: valid again, with the invalid frame bridged in the buffer
    kp[4, 4, 2] = 0.9
    kp[4, 3, 0] = 600.0
    p4 = lifter.push(4 * PERIOD, kp[4])
    assert p4.valid and p4.observed.all() and lifter.stats.frames_interpolated == 1


@pytest.fixture
def missing_allowed(monkeypatch):
    """hazard.MAX_MISSING_JOINTS = 3 (0, off, as shipped: reports/hrc/report.md, session 10)."""
    from edge_runtime.robot import hazard

    monkeypatch.setattr(hazard, "MAX_MISSING_JOINTS", 3)


def test_a_person_missing_a_limb_joint_beyond_the_hold_is_lifted_with_it_flagged(assets, missing_allowed):
    """With missing joints allowed, a wrist gone for longer than hold_frames does not make the frame
    invalid: the person shows his trunk, head and ankles; the wrist is flagged missing, and the model is
    fed its last keypoint moved with the image motion of the joints he shows; a keypoint far outside
    the image is missing and never reaches the model."""
    kp = random_walk_keypoints(np.random.default_rng(7), 13)
    kp[12, 3, 0] = 1e300
    lifter = _lifter(assets, hold_frames=2)
    assert all(lifter.push(i * PERIOD, kp[i]).valid for i in range(3))
    kp[3:, 13, :2] = np.nan  # the left wrist from frame 3 on
    outs = [lifter.push(i * PERIOD, kp[i]) for i in range(3, 12)]
    assert all(p.valid for p in outs)
    assert outs[0].held[13] and outs[1].held[13] and not outs[0].missing.any()
    assert all(p.missing[13] and p.missing.sum() == 1 and not p.held[13] for p in outs[2:])
    assert np.isfinite(outs[-1].joints_cam_m).all() and outs[-1].to_json()["missing"][13] is True
    assert lifter.stats.joints_missing == 7 and lifter.stats.joints_held == 2
    norm = normalize_screen(kp[..., :2], 1280, 720)
    others = np.delete(np.arange(17), 13)
    moved = sum(np.median(norm[i, others] - norm[i - 1, others], axis=0) for i in range(3, 12))
    np.testing.assert_allclose(lifter.window()[-1, 13], norm[2, 13] + moved, atol=1e-5)
    far = lifter.push(12 * PERIOD, kp[12])    # and an ankle 1e300 px out: not seen (held)
    assert far.valid and far.held[3] and far.missing[13] and far.missing.sum() == 1
    assert np.isfinite(lifter.window()).all() and np.abs(lifter.window()).max() <= 10


@pytest.mark.parametrize("hide", [(4,), (10,), (3, 6), (2, 5, 12, 15)])
def test_a_person_missing_his_trunk_head_both_ankles_or_four_joints_is_not_lifted(assets, hide, missing_allowed):
    kp = random_walk_keypoints(np.random.default_rng(8), 6)
    lifter = _lifter(assets, hold_frames=1)
    lifter.push(0.0, kp[0])
    kp[1:, list(hide), :2] = np.nan
    outs = [lifter.push(i * PERIOD, kp[i]) for i in range(1, 6)]
    assert outs[0].valid and not any(p.valid for p in outs[1:])
    assert all(p.code == MISSING_JOINTS for p in outs[1:])


def test_never_seen_joint_makes_frames_invalid(assets):
    kp = random_walk_keypoints(np.random.default_rng(5), 3)
    kp[:, 10, :2] = np.nan  # the head is never seen
    lifter = _lifter(assets)
    outs = [lifter.push(i * PERIOD, kp[i]) for i in range(3)]
    assert not any(p.valid for p in outs) and all("head" in p.reason for p in outs)
    assert lifter.stats.inferences == 0


def test_fewer_joints_and_bad_timestamps(assets):
    kp = random_walk_keypoints(np.random.default_rng(6), 5)
    lifter = _lifter(assets, hold_frames=0)
    assert lifter.push(0.0, kp[0]).valid
    short = lifter.push(PERIOD, kp[1][:15])
    assert not short.valid and short.code == JOINT_COUNT and "(15, 3)" in short.reason
    back = lifter.push(PERIOD, kp[1])  # same timestamp again
    assert not back.valid and back.code == TIME_NOT_INCREASING
    nan_t = lifter.push(float("nan"), kp[1])
    assert not nan_t.valid and nan_t.code == BAD_TIME
    assert lifter.push(2 * PERIOD, kp[2]).valid
    s = lifter.stats
    assert s.invalid == {JOINT_COUNT: 1, TIME_NOT_INCREASING: 1, BAD_TIME: 1} and s.wrong_joint_count == 1
    assert s.frames == 5 and s.valid == 2 and s.frames_interpolated == 1


def test_a_timestamp_of_1_7e308_is_a_bad_time_not_an_overflow(assets):
    kp = random_walk_keypoints(np.random.default_rng(6), 3)
    lifter = _lifter(assets)
    assert lifter.push(0.0, kp[0]).valid
    far = lifter.push(1.7e308, kp[1])
    assert not far.valid and far.code == BAD_TIME
    assert lifter.push(PERIOD, kp[2]).valid


def test_a_joint_far_outside_the_image_is_missing_and_never_reaches_the_model(assets):
    kp = random_walk_keypoints(np.random.default_rng(8), 2)
    lifter = _lifter(assets, hold_frames=0)
    assert lifter.push(0.0, kp[0]).valid
    far = kp[1].copy()
    far[3, 0] = 1e300  # finite, but inf once the model's float32 input holds it
    pose = lifter.push(PERIOD, far)
    assert not pose.valid and pose.code == MISSING_JOINTS
    assert np.isfinite(lifter.window()).all() and np.abs(lifter.window()).max() <= 10


def test_person_who_disappears_is_held_then_invalid_then_resets(assets):
    kp = random_walk_keypoints(np.random.default_rng(7), 80)
    lifter = _lifter(assets, hold_frames=2, lost_timeout_s=0.3)
    outs = []
    for i in range(80):
        present = not (30 <= i < 50)  # gone for 20 frames = 0.67 s > 0.3 s
        outs.append(lifter.push(i * PERIOD, kp[i] if present else None))
    assert all(p.valid for p in outs[:30])
    assert outs[30].valid and outs[31].valid and not outs[30].observed.any()  # held 2 frames
    assert all(not p.valid and p.code == NO_PERSON for p in outs[32:50])
    assert lifter.stats.resets == 1 and lifter.stats.invalid[NO_PERSON] == 18 and lifter.stats.no_person == 20
    back = outs[50]
    assert back.valid and back.warming_up  # a fresh warm-up after the reset
    assert all(p.warming_up for p in outs[50:50 + RF - 1]) and not outs[50 + RF - 1].warming_up
    # after the reset the window is padding of the first frame back: equal to a fresh lifter's answer
    fresh = _lifter(assets)
    np.testing.assert_allclose(fresh.push(0.0, kp[50]).joints_cam_m, back.joints_cam_m, atol=1e-6)


def test_short_disappearance_is_bridged_not_reset(assets):
    kp = random_walk_keypoints(np.random.default_rng(8), 40)
    lifter = _lifter(assets, hold_frames=1, lost_timeout_s=0.5)
    for i in range(40):
        lifter.push(i * PERIOD, None if 20 <= i < 25 else kp[i])
    s = lifter.stats
    assert s.resets == 0 and s.invalid[NO_PERSON] == 4 and s.frames_interpolated == 4 and s.valid == 36


def test_clock_going_back_far_starts_a_new_stream(assets):
    kp = random_walk_keypoints(np.random.default_rng(11), 40)
    lifter = _lifter(assets, lost_timeout_s=0.5)
    for i in range(30):
        lifter.push(10.0 + i * PERIOD, kp[i])
    assert not lifter.push(10.0 + 28.5 * PERIOD, kp[30]).valid  # a little back: refused
    again = lifter.push(0.0, kp[31])  # far back: a new stream, warming up from this frame
    assert again.valid and again.warming_up and lifter.stats.restarts == 1
    fresh = _lifter(assets)
    np.testing.assert_allclose(again.joints_cam_m, fresh.push(0.0, kp[31]).joints_cam_m, atol=1e-6)


def test_slow_camera_is_spaced_out_to_the_model_rate(assets):
    kp = random_walk_keypoints(np.random.default_rng(12), 30)
    lifter = _lifter(assets)
    outs = [lifter.push(i * 3 * PERIOD, kp[i]) for i in range(10)]  # a 10 Hz camera
    assert all(p.valid for p in outs) and lifter.stats.frames_interpolated == 18
    norm = normalize_screen(kp[:10, :, :2], 1280, 720)
    t = np.arange(28) / 3  # 30 Hz model frames in units of camera frames
    dense = np.stack([np.stack([np.interp(t, np.arange(10), norm[:, j, d]) for d in range(2)], -1)
                      for j in range(17)], 1)
    pose, root = lifter.lift_windows(padded_windows(dense.astype(np.float32), RF))
    np.testing.assert_allclose(outs[-1].joints_model_cam_m, pose[-1] + root[-1], atol=2e-5)


def test_long_timestamp_gap_resets(assets):
    kp = random_walk_keypoints(np.random.default_rng(9), 4)
    lifter = _lifter(assets, lost_timeout_s=0.5)
    for i in range(3):
        lifter.push(i * PERIOD, kp[i])
    p = lifter.push(2.0, kp[3])  # 2 s without frames
    assert p.valid and p.warming_up and lifter.stats.resets == 1
    assert lifter.stats.frames_dropped == round((2.0 - 2 * PERIOD) * 30) - 1


def test_distorted_camera_keypoints_are_undistorted_before_lifting(assets):
    import cv2

    cam = CameraModel(700.0, 700.0, 650.0, 350.0, 1280, 720, (-0.3, 0.1, 0.001, -0.001, -0.02))
    canon = CameraModel.from_dict(CANONICAL)
    rng = np.random.default_rng(10)
    canon_px = random_walk_keypoints(rng, 1)[0]
    rays = cv2.undistortPoints(canon_px[:, None, :2], canon.K, None).reshape(-1, 2)
    obj = np.concatenate([rays, np.ones((17, 1))], axis=1) * 4.0
    img, _ = cv2.projectPoints(obj, np.zeros(3), np.zeros(3), cam.K, cam.dist_array)
    kp_img = np.concatenate([img.reshape(17, 2), np.full((17, 1), 0.9)], axis=1)
    a = _lifter(assets, camera=cam, ray_tolerance_px=0.0).push(0.0, kp_img)
    b = _lifter(assets, ray_tolerance_px=0.0).push(0.0, canon_px)
    np.testing.assert_allclose(a.joints_cam_m, b.joints_cam_m, atol=1e-3)
    # projected with the distorted camera itself, the 3D joints land on the keypoints they came from
    back, _ = cv2.projectPoints(a.joints_cam_m, np.zeros(3), np.zeros(3), cam.K, cam.dist_array)
    np.testing.assert_allclose(back.reshape(17, 2), kp_img[:, :2], atol=0.01)
    # with a tolerance in this camera's pixels they land within it (the stand-in's joints are far off
    # their keypoints, so every joint uses all of it)
    t = _lifter(assets, camera=cam, ray_tolerance_px=1.5).push(0.0, kp_img)
    back, _ = cv2.projectPoints(t.joints_cam_m, np.zeros(3), np.zeros(3), cam.K, cam.dist_array)
    off = np.linalg.norm(back.reshape(17, 2) - kp_img[:, :2], axis=1)
    assert off.max() <= 1.5 + 0.01 and np.median(off) > 1.0


# ---------------------------------------------------------------------------- model loading


def test_loads_only_through_manifest_and_refuses_tampered_or_missing(assets, tmp_path):
    d = tmp_path / "a"
    shutil.copytree(assets, d)
    lifter = _lifter(d, precision="int8")
    assert lifter.name == "lifter-int8" and lifter.receptive_field == RF
    assert lifter.session.get_session_options().intra_op_num_threads == 1
    with (d / "lifter.int8.onnx").open("ab") as f:
        f.write(b"\0")
    with pytest.raises(ModelIntegrityError, match=r"lifter\.int8\.onnx.*sha256"):
        _lifter(d, precision="int8")
    (d / "lifter.fp32.onnx").unlink()
    with pytest.raises(ModelIntegrityError, match=r"lifter\.fp32\.onnx.*missing"):
        _lifter(d, precision="fp32")


def test_manifest_without_lifter_or_with_wrong_contract_is_refused(assets, tmp_path):
    d = tmp_path / "b"
    shutil.copytree(assets, d)
    m = json.loads((d / "manifest.json").read_text())
    for e in m["models"]:
        e["arch"] = "something"
    write_manifest(d, m)
    with pytest.raises(ModelIntegrityError, match="no model of arch 'lifter'"):
        _lifter(d)
    for e in m["models"]:
        e["arch"] = "lifter"
        del e["camera"]
    write_manifest(d, m)
    with pytest.raises(ModelIntegrityError, match="'camera'"):
        _lifter(d)
    e27 = make_lifter_assets(tmp_path / "rf9", rf=9)
    m = json.loads((e27 / "manifest.json").read_text())
    for e in m["models"]:
        e["receptive_field"] = 27  # manifest says 27, model takes 9 frames
    write_manifest(e27, m)
    with pytest.raises(ModelIntegrityError, match=r"does not take \(1, 27, 17, 2\)"):
        _lifter(e27)


def test_classifier_and_lifter_share_a_manifest(tmp_path):
    conv = {"name": "convlstm-int8", "file": "convlstm.int8.onnx", "sha256": "0" * 64, "precision": "int8",
            "arch": "convlstm", "parameters": {}, "classes": ["A", "B"],
            "inputs": [{"name": "imu"}], "outputs": [{"name": "probs"}]}
    d = make_lifter_assets(tmp_path / "c", extra_entries=[conv])
    assert _lifter(d, precision="int8").name == "lifter-int8"  # not the classifier listed first
    m = json.loads((d / "manifest.json").read_text())
    m["models"] = m["models"][1:] + m["models"][:1]  # lifters first: the classifier is still found
    assert select_model(m, "int8", arch=CLASSIFIER_ARCHS)["name"] == "convlstm-int8"
    conv["classes"] = []  # a classifier must list its classes; a lifter lists none
    with pytest.raises(ModelIntegrityError, match=r"models\[0\].classes"):
        make_lifter_assets(tmp_path / "e", extra_entries=[conv])


def test_params_are_validated():
    for bad in ({"precision": "int4"}, {"ray_tolerance_px": 5.5}, {"ray_tolerance_px": -1.0}, {"threads": 0},
                {"hold_frames": -1}, {"min_score": 1.5}, {"max_gap_periods": 0.5}, {"lost_timeout_s": 0}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            LifterParams(**bad)


def test_held_joints_are_marked_and_stay_on_their_last_ray(assets):
    kp = random_walk_keypoints(np.random.default_rng(4), 5)
    lifter = _lifter(assets, ray_tolerance_px=0.0)
    for i in range(4):
        lifter.push(i * PERIOD, kp[i])
    gone = kp[4].copy()
    gone[3, 2] = 0.0  # the right ankle not seen: held at frame 3's position
    pose = lifter.push(4 * PERIOD, gone)
    assert pose.valid and not pose.observed[3] and pose.held[3] and pose.held.sum() == 1
    assert pose.to_json()["held"][3] is True and pose.to_json()["observed"][3] is False
    x, y, z = pose.joints_cam_m[3]
    np.testing.assert_allclose([x / z * F_CANON + 640, y / z * F_CANON + 360], kp[3, 3, :2], atol=1e-3)


def test_people_lifter_gives_each_person_his_own_window(assets):
    from edge_runtime.robot.keypoints import Person
    from edge_runtime.robot.lifter import PeopleLifter

    rng = np.random.default_rng(5)
    a, b = random_walk_keypoints(rng, 30), random_walk_keypoints(rng, 30)
    people = PeopleLifter(_lifter(assets))
    alone = _lifter(assets)
    for i in range(30):
        both = people.push(i * PERIOD, [Person(a[i], 7), Person(b[i], 9)] if i % 3 != 2 else [Person(a[i], 7)])
        want = alone.push(i * PERIOD, a[i])
        np.testing.assert_allclose(dict(both)[7].joints_cam_m, want.joints_cam_m, atol=1e-6)
    assert set(people.lifters) == {7, 9}  # 9 missed the last frame only: his window waits for him
    people.push(30 * PERIOD + 0.6, [Person(a[0], 7)])
    assert set(people.lifters) == {7}  # gone longer than lost_timeout_s (0.5 s): dropped
    assert people.stats.frames == 31 + 20
