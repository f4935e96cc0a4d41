"""The 3-marker calibration (Eq. 1-2) recovers a simulated camera's placement; ground
anchoring of lifted skeletons: the floor fixes the lifter's depth."""
import json

import numpy as np
import pytest
from support.robot import anchored_worker, true_calibration

from edge_runtime.core.skeleton import HEAD, L_ANKLE, R_ANKLE
from edge_runtime.robot import calibration
from edge_runtime.robot.calibration import (
    ANCHOR_CAMERA_LOW,
    ANCHOR_NO_ANKLE,
    ANCHOR_RAY_FLAT,
    MAX_UNLABELLED_STANDS,
    Calibration,
    CalibrationError,
    CalibrationParams,
    anchor_factor,
    fit,
    from_recording,
    head_and_ankles,
    segment_stands,
)
from firmware_sim.devices.camera import Camera
from firmware_sim.people import human

MARKERS = ((0.0, 1.0), (1.0, 1.0), (0.0, 2.0))
BODY = human.Body.from_height(1.75)
NOISE_M = np.array([0.03, 0.03, 0.08])  # camera frame: a monocular lifter is worst in depth


@pytest.fixture
def floor_rays_only(monkeypatch):
    """The floor rays' geometry alone: the lifter's own depth given no weight in the anchoring (an
    infinite error), so that a perfect ankle ray gives the exact factor."""
    monkeypatch.setattr(calibration, "ANCHOR_LIFTER_DEPTH_SD", np.inf)


def standing(xz, heading=0.0):
    return human.joints(BODY, human.Posture(), pelvis_xz_m=xz, heading_rad=heading)


def camera(eye=(1.5, 1.6, 7.0)):
    return Camera.look_at(eye, target_m=(0.0, 0.1 - 0.914 + 1.0, 1.0))


def recording(cam, rng, frames_per_marker=60, fps=30.0, scale=1.0):
    """The worker stands on markers 1, 2, 3 (2 s each) and walks between them (1 s)."""
    joints, label = [], []
    pts = [np.array(m) for m in MARKERS]
    for i, p in enumerate(pts):
        for _ in range(frames_per_marker):
            joints.append(standing(p))
            label.append(i + 1)
        if i + 1 < len(pts):
            for s in np.linspace(0, 1, int(fps))[1:-1]:
                joints.append(standing(p + s * (pts[i + 1] - p)))
                label.append(0)
    cam_j = cam.to_camera(np.stack(joints)) * scale
    cam_j = cam_j + rng.normal(0, 1, cam_j.shape) * NOISE_M
    t = np.arange(len(cam_j)) / fps
    return t, cam_j, np.array(label)


def head_errors(cal, cam, rng, n=400, scale=1.0):
    """Robot-frame head error of workers at random spots 3-8 m from the camera."""
    errs = []
    eye = cam.position_m
    while len(errs) < n:
        xz = rng.uniform([-2.5, -1.0], [2.5, 3.5])
        d = np.hypot(xz[0] - eye[0], xz[1] - eye[2])
        if not 3.0 <= d <= 8.0:
            continue
        j = standing(xz, rng.uniform(-np.pi, np.pi))
        seen = cam.to_camera(j[HEAD]) * scale + rng.normal(0, 1, 3) * NOISE_M
        errs.append(np.linalg.norm(cal.apply(seen) - j[HEAD]))
    return np.array(errs)


def test_recovers_a_known_camera_from_a_noisy_recording_and_rigid_beats_eq2(tmp_path):
    rng = np.random.default_rng(0)
    cam = camera()
    t, cam_j, label = recording(cam, rng)
    results = {}
    for method in ("rigid", "eq2"):
        cal = from_recording(t, cam_j, CalibrationParams(method=method))  # segmentation finds the 3 stands
        errs = head_errors(cal, cam, np.random.default_rng(1))
        results[method] = (np.median(errs), np.percentile(errs, 95))
        if method == "rigid":
            # the transform itself: robot = R^T (cam - t)
            assert np.allclose(cal.A, cam.R.T, atol=0.03)
            assert np.allclose(cal.b, -cam.R.T @ cam.t, atol=0.1)
            assert cal.scale == pytest.approx(1.0, abs=0.03)
            assert cal.worker_height_m == pytest.approx(BODY.height_m * (1 - 0.039), abs=0.03)
            assert max(cal.residuals_m()["head"] + cal.residuals_m()["ankle"]) < 0.1
    print({k: (round(float(a), 3), round(float(b), 3)) for k, (a, b) in results.items()})
    assert results["rigid"][0] < 0.12 and results["rigid"][1] < 0.25
    assert results["rigid"][1] < results["eq2"][1]


def test_labelled_frames_and_a_lifter_scale_bias():
    rng = np.random.default_rng(3)
    cam = camera((-2.0, 2.2, 6.5))
    t, cam_j, label = recording(cam, rng, scale=1.15)  # the lifter's depths are 15 % too large
    cal = from_recording(t, cam_j, CalibrationParams(method="rigid"), marker=label)
    assert cal.scale == pytest.approx(1 / 1.15, rel=0.03)
    errs = head_errors(cal, cam, np.random.default_rng(4), scale=1.15)
    assert np.median(errs) < 0.12
    # eq2 is exact at the markers by construction (per-axis scale)
    e2 = from_recording(t, cam_j, CalibrationParams(method="eq2"), marker=label)
    assert max(e2.residuals_m()["head"]) < 1e-6


def test_save_and_load_keep_everything(tmp_path):
    rng = np.random.default_rng(5)
    cam = camera()
    t, cam_j, label = recording(cam, rng)
    cal = from_recording(t, cam_j, marker=label)
    path = tmp_path / "cal.json"
    cal.save(path)
    data = json.loads(path.read_text())
    assert data["version"] == 1 and data["method"] == "pnp" and len(data["inputs"]["head_cam_m"]) == 3
    assert data["worker_height_m"] == pytest.approx(cal.worker_height_m)
    assert set(data["residuals_m"]) == {"head", "ankle"} and data["inputs"]["frames_per_marker"] == [60, 60, 60]
    again = Calibration.load(path)
    p = rng.normal(0, 3, (10, 3))
    assert np.allclose(again.apply(p), cal.apply(p)) and again.params == cal.params


def _saved(**changes) -> str:
    """A valid calibration file's text with some fields replaced (None deletes one)."""
    t, cam_j, label = recording(camera(), np.random.default_rng(5), frames_per_marker=20)
    data = from_recording(t, cam_j, marker=label).to_json()
    for key, value in changes.items():
        section, _, name = key.partition("__")
        target = data[section] if name else data
        if value is None:
            target.pop(name or section)
        else:
            target[name or section] = value
    return json.dumps(data)


@pytest.mark.parametrize("text, match", [
    ("{", "not valid JSON"),
    ('{"version": 9}', "field 'version': 9"),
    ('{"version": 1, "A": [[1, 0], [0, 1]], "b": [0, 0, 0]}', "field 'method': missing"),
    ('{"version": 1, "A": [[0, 0, 0], [0, 0, 0], [0, 0, 0]], "b": [0, 0, 0], "method": "rigid", '
     '"worker_height_m": 1.7, "inputs": {}}', "singular"),
])
def test_bad_calibration_files_say_why(tmp_path, text, match):
    p = tmp_path / "cal.json"
    p.write_text(text)
    with pytest.raises(CalibrationError, match=match) as e:
        Calibration.load(p)
    assert str(p) in str(e.value)
    with pytest.raises(CalibrationError, match="cannot read"):
        Calibration.load(tmp_path / "missing.json")


@pytest.mark.parametrize("changes, match", [
    ({"params__ground_anchor": "false"}, r"\[calibration\] ground_anchor: expected true/false, got 'false'"),
    ({"worker_height_m": "1.7"}, r"field 'worker_height_m': expected a finite number"),
    ({"b": [0, "1", 0]}, r"field 'b'\[1\]: expected a finite number"),
    ({"A": [[1, 0, 0], [0, 1, 0], [0, 0, 10**400]]}, r"field 'A'\[2\]\[2\]: expected a finite number"),
    ({"A": [[1, 0], [0, 1]]}, r"field 'A': expected a list of 3"),
    ({"method": ["rigid"]}, r"field 'method': expected one of"),
    ({"inputs__head_cam_m": None}, r"field 'inputs.head_cam_m': expected a list of 3"),
    ({"inputs__frames_per_marker": [60, 60.5, 60]}, r"frames_per_marker': expected an integer"),
    ({"params__markers_xz_m": [[0, 1], [1, 1]]}, r"markers_xz_m: must be three"),
    ({"params__min_frames": 0}, r"\[calibration\] min_frames: must be an integer of at least 1"),
    ({"params": []}, r"field 'params': expected an object"),
])
def test_every_calibration_field_is_checked_and_named(tmp_path, changes, match):
    p = tmp_path / "cal.json"
    p.write_text(_saved(**changes))
    with pytest.raises(CalibrationError, match=match) as e:
        Calibration.load(p)
    assert str(e.value).startswith(f"{p}: ") and "\n" not in str(e.value)
    p.write_text(_saved())
    assert Calibration.load(p).params.ground_anchor is True


def test_degenerate_inputs_are_refused():
    cam = camera()
    heads, ankles = head_and_ankles(cam.to_camera(np.stack([standing(m) for m in MARKERS])))
    fit(heads, ankles)  # fine
    with pytest.raises(CalibrationError, match="collinear"):
        fit(heads, ankles, CalibrationParams(markers_xz_m=((0, 1), (1, 1), (2, 1))))
    with pytest.raises(CalibrationError, match="did not move from marker 1 to marker 2"):
        fit(heads[[0, 0, 2]], ankles[[0, 0, 2]])
    line = np.stack([heads[0], heads[1], 2 * heads[1] - heads[0]])
    with pytest.raises(CalibrationError, match="collinear"):  # the lifted positions' fits (pnp uses rays only)
        fit(line, ankles, CalibrationParams(method="rigid"))
    with pytest.raises(CalibrationError, match="misses a marker's ray"):  # pnp: by its residuals
        fit(line, ankles, CalibrationParams(method="pnp"))
    with pytest.raises(CalibrationError, match="misses a marker's ray"):  # two markers' stands swapped
        fit(heads[[0, 2, 1]], ankles, CalibrationParams(method="pnp"))
    bad = heads.copy()
    bad[1, 0] = np.nan
    with pytest.raises(CalibrationError, match="non-finite"):
        fit(bad, ankles)
    # a recording in which the worker never moves has one standing period
    still = cam.to_camera(np.stack([standing(MARKERS[0])] * 200))
    with pytest.raises(CalibrationError, match="found 1 standing period"):
        from_recording(np.arange(200) / 30, still)
    with pytest.raises(CalibrationError, match="marker 3: 0 usable frames"):
        from_recording(np.arange(200) / 30, still, marker=np.r_[np.ones(100), 2 * np.ones(100)])
    with pytest.raises(ValueError, match="method"):
        CalibrationParams(method="magic")


def test_pnp_ignores_the_lifters_depth_scale():
    """The pnp fit uses only the points' directions: a lifter that sees everything 25 % too
    far still gives the camera's pose (scale 1); the floor anchoring then removes the depth
    error of a worker elsewhere."""
    rng = np.random.default_rng(3)
    cam = camera()
    t, cam_j, label = recording(cam, rng, scale=1.25)
    pnp = from_recording(t, cam_j, CalibrationParams(method="pnp"), marker=label)
    assert pnp.scale == pytest.approx(1.0, abs=1e-9)
    assert np.linalg.norm(pnp.b - cam.position_m) < 0.6
    angle = np.degrees(np.arccos(np.clip((np.trace(pnp.A @ cam.R) - 1) / 2, -1, 1)))
    assert angle < 3.0
    truth = standing((-1.0, 2.5))
    lifted = cam.to_camera(truth) * 1.25
    robot, applied = pnp.anchor_to_floor(lifted)
    assert applied
    assert np.linalg.norm(robot[HEAD] - truth[HEAD]) < 0.5 * np.linalg.norm(pnp.apply(lifted[HEAD]) - truth[HEAD])


def test_a_marker_behind_another_is_fitted_from_the_rays_not_refused():
    """Marker 3 nearly on marker 1's line of sight (a camera straight down the +z axis, 7 m out):
    a lifter that takes depth from apparent body size sees the worker move 0.1 m where he walked
    1 m. He did move (his rays did), so the fit falls back to the rays alone (pnp) instead of
    refusing 'did not move' (hard:200 seed 1, hard_156); a worker who stays put is still refused."""
    cam = camera(eye=(0.15, 0.5, 8.0))
    heads, ankles = head_and_ankles(cam.to_camera(np.stack([standing(m) for m in MARKERS])))
    for pts in (heads, ankles):  # the lifter's depth at marker 3: hardly nearer than at marker 1
        pts[2] *= (pts[0, 2] - 0.1) / pts[2, 2]
    assert np.linalg.norm(heads[2] - heads[0]) < CalibrationParams().min_move_m
    cal = fit(heads, ankles)
    assert cal.method == "pnp"
    assert np.linalg.norm(cal.b - cam.position_m) < 0.3
    with pytest.raises(CalibrationError, match="did not move from marker 1 to marker 3"):
        fit(heads[[0, 1, 0]], ankles[[0, 1, 0]])


# ------------------------------------------------------------------ ground anchoring

def project(p):
    return p[..., :2] / p[..., 2:3]


@pytest.mark.usefixtures("floor_rays_only")
@pytest.mark.parametrize("scale", [0.8, 0.93, 1.12, 1.3])
def test_recovers_a_known_depth_and_keeps_the_2d_projections(scale):
    cam = Camera.look_at((2.0, 1.2, 6.5), (0.0, -0.2, 1.0))
    cal = true_calibration(cam)
    truth = anchored_worker((0.5, 1.5))
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


@pytest.mark.usefixtures("floor_rays_only")
def test_anchors_on_an_observed_ankle_not_a_held_one():
    cam = Camera.look_at((0.0, 1.5, 6.0), (0.0, -0.2, 1.0))
    cal = true_calibration(cam)
    truth = anchored_worker((0.0, 1.5))
    lifted = cam.to_camera(truth) * 1.15
    lifted[L_ANKLE] *= 1.3                              # a held ankle on a stale ray, lower in the robot frame
    observed = np.ones(17, bool)
    observed[L_ANKLE] = False
    robot = cal.to_robot(lifted, observed)
    np.testing.assert_allclose(robot[R_ANKLE], truth[R_ANKLE], atol=1e-6)
    unmasked = true_calibration(cam).to_robot(lifted)  # a new stream: to_robot remembers each person
    assert np.abs(unmasked[R_ANKLE] - truth[R_ANKLE]).max() > 0.05  # the held one would move it


@pytest.mark.usefixtures("floor_rays_only")
def test_uses_the_lower_ankle_of_a_stride():
    cam = Camera.look_at((0.0, 1.5, 6.0), (0.0, -0.2, 1.0))
    cal = true_calibration(cam)
    truth = anchored_worker((0.0, 1.5))
    truth[R_ANKLE, 1] += 0.25                           # right foot swinging through the air
    robot, applied = cal.anchor_to_floor(cam.to_camera(truth) * 1.15)
    assert applied
    np.testing.assert_allclose(robot, truth, atol=1e-6)


def test_refuses_a_flat_ray_and_a_low_camera_and_clamps_the_factor():
    truth = anchored_worker((0.0, 1.5))
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


def _factor_seen_from(eye_m, truth, lifter_scale):
    """anchor_factor of ``truth`` seen by a camera at ``eye_m`` aimed at the cell, lifted
    ``lifter_scale`` times too far."""
    cam = Camera.look_at(eye_m, (0.0, -0.4, 0.0))
    cal = true_calibration(cam)
    return anchor_factor(cam.to_camera(truth) * lifter_scale, cal.A, cal.b, cal.params)


@pytest.fixture
def fused_with_lifter(monkeypatch):
    """The anchoring fused with the lifter's own depth as session 10 measured it (not shipped)."""
    monkeypatch.setattr(calibration, "ANCHOR_LIFTER_DEPTH_SD", calibration.ANCHOR_LIFTER_DEPTH_SD_FUSED)


@pytest.mark.usefixtures("fused_with_lifter")
def test_the_lifters_depth_counts_only_toward_the_arm():
    """A worker between the camera and the arm: a lifter that puts him too far from the camera (nearer
    the arm) pulls the anchoring toward its depth, more from a low camera, whose floor rays are
    shallow; one that puts him too near the camera (farther from the arm) is not listened to: the floor
    rays' exact factor stands."""
    truth = anchored_worker((0.0, 4.0))
    high, reason = _factor_seen_from((0.0, 2.1, 8.0), truth, 1.2)        # 3 m above the floor
    low, _ = _factor_seen_from((0.0, 0.1, 8.0), truth, 1.2)              # 1 m above the floor
    assert reason is None and 1 / 1.2 < high < low < 1.0
    assert _factor_seen_from((0.0, 2.1, 8.0), truth, 0.8) == (pytest.approx(1 / 0.8, rel=1e-9), None)


@pytest.mark.usefixtures("fused_with_lifter")
def test_the_anchoring_never_puts_anyone_farther_from_the_arm_than_the_floor_rays_do(monkeypatch):
    rng = np.random.default_rng(7)
    cases = []
    for _ in range(60):
        az = rng.uniform(-2.0, 2.0)
        cam = Camera.look_at((6.0 * np.sin(az), rng.uniform(0.1, 2.1), 6.0 * np.cos(az)), (0.0, -0.4, 0.5))
        truth = anchored_worker(rng.uniform([-2.0, 0.5], [2.0, 3.0]), rng.uniform(-np.pi, np.pi))
        cases.append((true_calibration(cam), cam.to_camera(truth) * rng.uniform(0.8, 1.25)))

    def pelvis_from_arm_m():
        out = []
        for cal, lifted in cases:
            k, reason = anchor_factor(lifted, cal.A, cal.b, cal.params)
            assert reason is None
            out.append((k, np.hypot(*cal.apply(k * lifted[0])[[0, 2]])))
        return np.array(out)

    fused = pelvis_from_arm_m()
    monkeypatch.setattr(calibration, "ANCHOR_LIFTER_DEPTH_SD", np.inf)
    floor = pelvis_from_arm_m()
    assert (fused[:, 1] <= floor[:, 1] + 1e-9).all()
    # between the floor rays' factor and the lifter's own depth (1), and not always the floor's
    assert (np.abs(np.log(fused[:, 0])) <= np.abs(np.log(floor[:, 0])) + 1e-9).all()
    assert (fused[:, 1] < floor[:, 1] - 0.01).any()


def test_switched_off_it_is_apply():
    cam = Camera.look_at((2.0, 1.2, 6.5), (0.0, -0.2, 1.0))
    cal = true_calibration(cam, CalibrationParams(ground_anchor=False))
    lifted = cam.to_camera(anchored_worker((0.5, 1.5))) * 1.2
    robot, applied = cal.anchor_to_floor(lifted)
    assert not applied and np.allclose(robot, cal.apply(lifted))
    np.testing.assert_allclose(cal.to_robot(lifted[None]), cal.apply(lifted[None]))


def test_nan_joints_give_a_defined_result():
    cam = Camera.look_at((2.0, 1.2, 6.5), (0.0, -0.2, 1.0))
    cal = true_calibration(cam)
    lifted = cam.to_camera(anchored_worker((0.5, 1.5))) * 1.2
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
    two = np.stack([lifted, cam.to_camera(anchored_worker((-1.0, 2.0))) * 0.9])
    out = cal.to_robot(two)
    np.testing.assert_allclose(out[1], anchored_worker((-1.0, 2.0)), atol=1e-6)


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


def test_pnp_measures_the_worker_from_the_rays_not_the_lifters_depth():
    from edge_runtime.robot.calibration import targets

    cam = Camera.look_at((2.5, 1.6, 6.5), (0.0, -0.2, 1.0))
    params = CalibrationParams(method="pnp")
    heads, ankles = targets(params, 1.62)
    depth_wrong = np.array([1.25, 0.9, 1.1])[:, None]           # the lifter misjudged each stand's depth
    cal = fit(cam.to_camera(heads) * depth_wrong, cam.to_camera(ankles) * depth_wrong, params)
    assert cal.worker_height_m == pytest.approx(1.62, abs=0.011)
    np.testing.assert_allclose(cal.b, cam.position_m, atol=0.02)  # the camera centre, from the rays alone
    r = cal.residuals_m()  # across the rays: the lifter's wrong depths are no residual of a ray fit
    assert max(r["head"] + r["ankle"]) < 0.02


# ------------------------------------------------------------------ anchoring over time (FloorAnchor)
STREAM_CAMERA = Camera.look_at((2.0, 1.2, 6.5), (0.0, -0.2, 1.0))


def noisy_ankle_stream(rng, frames=90, ankle_sd_m=0.08, scale=1.15):
    """A worker standing still, lifted at a wrong depth, whose ankle keypoints err by ``ankle_sd_m``
    across the line of sight each frame (a real detector's ankle noise): (truth, camera frames)."""
    truth = anchored_worker((0.5, 1.5))
    lifted = STREAM_CAMERA.to_camera(truth) * scale
    frames_cam = np.repeat(lifted[None], frames, axis=0)
    frames_cam[:, [L_ANKLE, R_ANKLE], :2] += rng.normal(0.0, ankle_sd_m, (frames, 2, 2)) * scale
    return truth, frames_cam


def ankle_ground(robot):
    return head_and_ankles(robot)[1][..., [0, 2]]


def test_a_noisy_ankle_stream_is_anchored_steadier_than_each_frame_alone():
    truth, frames_cam = noisy_ankle_stream(np.random.default_rng(3))
    per_frame = np.stack([true_calibration(STREAM_CAMERA).anchor_to_floor(j)[0] for j in frames_cam])
    cal = true_calibration(STREAM_CAMERA)
    streamed = np.stack([cal.to_robot(j) for j in frames_cam])
    settled = slice(cal.anchor_window_frames, None)             # once the window is full
    err_frame = np.linalg.norm(ankle_ground(per_frame) - ankle_ground(truth), axis=1)[settled]
    err_stream = np.linalg.norm(ankle_ground(streamed) - ankle_ground(truth), axis=1)[settled]
    assert np.ptp(ankle_ground(streamed)[settled], axis=0).max() < 0.5 * np.ptp(ankle_ground(per_frame)[settled],
                                                                                   axis=0).max()
    assert np.percentile(err_stream, 95) < 0.6 * np.percentile(err_frame, 95)
    # the skeleton is only scaled about the camera centre: every joint stays on its ray
    back = np.stack([STREAM_CAMERA.to_camera(r) for r in streamed])
    np.testing.assert_allclose(project(back), project(frames_cam), atol=1e-9)


@pytest.mark.usefixtures("floor_rays_only")
def test_one_wild_ankle_frame_does_not_move_the_anchoring():
    truth, frames_cam = noisy_ankle_stream(np.random.default_rng(4), frames=30, ankle_sd_m=0.002)
    frames_cam[20, [L_ANKLE, R_ANKLE], 1] += 0.4                 # both ankle keypoints far below the feet
    cal = true_calibration(STREAM_CAMERA)
    streamed = np.stack([cal.to_robot(j) for j in frames_cam])
    alone = true_calibration(STREAM_CAMERA).anchor_to_floor(frames_cam[20])[0]
    assert np.linalg.norm(ankle_ground(alone) - ankle_ground(truth)) > 0.3
    assert np.linalg.norm(streamed[20, HEAD] - truth[HEAD]) < 0.02
    # a second look at the same frame (a monitor reading what the loop saw) gets the same answer
    np.testing.assert_allclose(cal.to_robot(frames_cam[29]), streamed[29], atol=0)


@pytest.mark.usefixtures("floor_rays_only")
def test_each_person_keeps_his_own_anchoring_whatever_the_order():
    near, far = anchored_worker((0.5, 2.5)), anchored_worker((-1.0, 0.0))
    lifted = np.stack([STREAM_CAMERA.to_camera(near) * 1.2, STREAM_CAMERA.to_camera(far) * 0.85])
    cal = true_calibration(STREAM_CAMERA)
    for t in range(20):
        order = [0, 1] if t % 2 else [1, 0]                    # the loop gives no ids
        out = cal.to_robot(lifted[order])
        np.testing.assert_allclose(out[order.index(0)], near, atol=1e-6)
        np.testing.assert_allclose(out[order.index(1)], far, atol=1e-6)
    assert len(cal._anchor.tracks) == 2


@pytest.mark.usefixtures("floor_rays_only")
def test_a_trackers_ids_key_the_anchoring_when_given():
    near, far = anchored_worker((0.5, 2.5)), anchored_worker((-1.0, 0.0))
    lifted = np.stack([STREAM_CAMERA.to_camera(near) * 1.2, STREAM_CAMERA.to_camera(far) * 0.85])
    cal = true_calibration(STREAM_CAMERA)
    for t in range(10):
        order = [0, 1] if t % 2 else [1, 0]
        # new frames (a lifter never repeats itself exactly): 0.01 % steps in depth
        out = cal.to_robot(lifted[order] * (1 + 1e-4 * t), ids=[("a", "b")[k] for k in order])
        np.testing.assert_allclose(out[order.index(0)], near, atol=5e-3)
        np.testing.assert_allclose(out[order.index(1)], far, atol=5e-3)
    assert sorted(t.pid for t in cal._anchor.tracks) == ["a", "b"]


# ------------------------------------------------------------- standing periods found without labels
def walk_with_stands(cam, rng, stops, fps=30.0, stand_frames=60, walk_frames=30):
    """The worker stands at each of ``stops`` (floor x, z) and walks straight between them."""
    joints = []
    pts = [np.array(p, float) for p in stops]
    for i, p in enumerate(pts):
        joints += [standing(p)] * stand_frames
        if i + 1 < len(pts):
            joints += [standing(p + s * (pts[i + 1] - p)) for s in np.linspace(0, 1, walk_frames)[1:-1]]
    cam_j = cam.to_camera(np.stack(joints))
    return np.arange(len(cam_j)) / fps, cam_j + rng.normal(0, 1, cam_j.shape) * NOISE_M


def test_a_stand_the_noise_broke_in_two_is_one_stand():
    """A detector glitch in the middle of marker 2's stand (8 frames of the whole person 0.6 m off)
    leaves two pieces; they are joined, so the three stands are the markers."""
    rng = np.random.default_rng(5)
    t, cam_j, label = recording(camera(), rng)
    mid = np.flatnonzero(label == 2)[30]
    cam_j[mid:mid + 8] += [0.6, 0.0, 0.0]
    _, ankles = head_and_ankles(cam_j)
    stands = segment_stands(t, ankles)
    assert len(stands) == 3
    for k, s in enumerate(stands, 1):  # each stand lies within its marker's frames and covers most of them
        assert set(label[s]) == {k} and len(s) >= 20


def test_a_pause_on_the_way_is_not_taken_for_a_marker():
    """Four standing periods (a pause between markers 1 and 2): the three that fit the marker layout are
    the markers, whatever comes first; the first three would fit a layout nobody walked."""
    rng = np.random.default_rng(6)
    cam = camera()
    t, cam_j = walk_with_stands(cam, rng, [MARKERS[0], (-1.5, 2.5), MARKERS[1], MARKERS[2]])
    for method in ("rigid", "pnp"):
        cal = from_recording(t, cam_j, CalibrationParams(method=method))
        assert np.allclose(cal.A / cal.scale, cam.R.T, atol=0.03), method
        assert np.linalg.norm(cal.b - cam.position_m) < 0.15, method


def test_a_pause_that_also_fits_the_layout_is_refused_not_guessed():
    """A pause at (0.5, 0.4): with markers 1 and 2 it makes a triangle a fit with a free scale (rigid) or
    height (pnp) puts within its residual limit, with the camera turned by 70-80 degrees. The right
    three fit better, but by how much a real detector's noise leaves is not a safe margin: refused."""
    rng = np.random.default_rng(6)
    t, cam_j = walk_with_stands(camera(), rng, [MARKERS[0], (0.5, 0.4), MARKERS[1], MARKERS[2]])
    for method in ("rigid", "pnp"):
        with pytest.raises(CalibrationError, match="more than one way"):
            from_recording(t, cam_j, CalibrationParams(method=method))


def test_stands_that_do_not_fit_the_markers_are_refused():
    """The worker's third stand was 1.4 m from marker 3 (beyond marker 2 instead of behind marker 1):
    pnp, which fits the keypoints' rays, refuses rather than calibrates wrongly. (A scaled rigid fit
    absorbs much of such a mismatch in its scale: 0.55 m of residual here, under its 0.6 m limit, which
    catches the fits to the wrong stands seen in development, 0.88-1.04 m.)"""
    rng = np.random.default_rng(7)
    t, cam_j = walk_with_stands(camera(), rng, [(0.0, 1.0), (1.0, 1.0), (2.0, 2.0)])
    with pytest.raises(CalibrationError, match="fit the marker layout"):
        from_recording(t, cam_j, CalibrationParams(method="pnp"))


def test_stands_that_fit_the_markers_two_ways_are_refused():
    """A pause 0.2 m beside marker 1, and the lifter's depth a few per cent off at markers 2 and 3: the
    right three stands fit the layout (rigid), but so do the pause and markers 1 and 2 when the fit falls
    back to pnp, with the camera turned by 90 degrees. Nothing says which: refused, not guessed."""
    rng = np.random.default_rng(0)
    t, cam_j = walk_with_stands(camera(), rng, [MARKERS[0], (0.2, 1.0), MARKERS[1], MARKERS[2]])
    stand, walk = 60, 28
    cam_j[2 * (stand + walk):2 * (stand + walk) + stand] *= 1.06
    cam_j[3 * (stand + walk):] *= 0.94
    with pytest.raises(CalibrationError, match="more than one way"):
        from_recording(t, cam_j, CalibrationParams(method="rigid"))


def test_eq2_without_labels_takes_the_first_three_stands_as_before():
    """eq2 is exact at the markers: no residual to choose stands by, so the first three are taken."""
    rng = np.random.default_rng(1)
    t, cam_j, label = recording(camera(), rng)
    _, ankles = head_and_ankles(cam_j)
    stands = segment_stands(t, ankles)
    marker = np.zeros(len(t), int)
    for k, s in enumerate(stands[:3], 1):
        marker[s] = k
    unlabelled = from_recording(t, cam_j, CalibrationParams(method="eq2"))
    labelled = from_recording(t, cam_j, CalibrationParams(method="eq2"), marker=marker)
    assert np.array_equal(unlabelled.A, labelled.A) and np.array_equal(unlabelled.b, labelled.b)


def test_a_recording_with_too_many_stands_is_refused_not_searched():
    rng = np.random.default_rng(2)
    stops = [(0.4 * k, 1.0 + 0.3 * (k % 2)) for k in range(MAX_UNLABELLED_STANDS + 1)]
    t, cam_j = walk_with_stands(camera(), rng, stops)
    with pytest.raises(CalibrationError, match=f"found {len(stops)} standing periods"):
        from_recording(t, cam_j, CalibrationParams(method="pnp"))
