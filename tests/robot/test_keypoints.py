"""edge_runtime.robot.keypoints: COCO-17 -> H36M-17, JSON lines, person selection, camera models."""
import json
import math

import cv2
import numpy as np
import pytest

from edge_runtime.core.skeleton import HEAD, HIP, INDEX, JOINTS, N_JOINTS, SPINE, THORAX
from edge_runtime.robot.keypoints import (
    COCO_JOINTS,
    CameraModel,
    KeypointInputError,
    Person,
    PersonSelector,
    coco_to_h36m,
    h36m_to_coco_3d,
    image_to_canonical,
    normalize_screen,
    read_keypoints_jsonl,
    to_h36m,
)
from edge_runtime.wearable.sources import InputError

H = 1.75  # body height (m); fractions from docs/design.md section 5 (Drillis & Contini)
CANON = CameraModel.from_fov(1280, 720, 100.0)


def skeleton_3d(yaw_deg: float = 0.0, bend_deg: float = 0.0, distance_m: float = 5.0) -> np.ndarray:
    """A standing H36M skeleton (17, 3) in camera coordinates (x right, y down, z forward),
    facing the camera when yaw is 0, its trunk bent forward by ``bend_deg``."""
    def body(x, up, fwd):  # person frame: x to the person's left, up, forward
        return np.array([x, up, fwd], float)

    j = {}
    j["hip"] = body(0, 0.530 * H, 0)
    for side, s in (("left", 1), ("right", -1)):
        j[f"{side}_hip"] = body(s * 0.0955 * H, 0.530 * H, 0)
        j[f"{side}_knee"] = body(s * 0.09 * H, 0.285 * H, 0.02)
        j[f"{side}_ankle"] = body(s * 0.085 * H, 0.04 * H, 0)
    upper = {"thorax": body(0, 0.818 * H, 0), "spine": body(0, (0.530 + 0.45 * 0.288) * H, 0),
             "neck_nose": body(0, 0.905 * H, 0.10), "head": body(0, 1.0 * H, 0)}
    for side, s in (("left", 1), ("right", -1)):
        upper[f"{side}_shoulder"] = body(s * 0.1295 * H, 0.818 * H, 0)
        upper[f"{side}_elbow"] = body(s * 0.15 * H, (0.818 - 0.186) * H, 0.03)
        upper[f"{side}_wrist"] = body(s * 0.16 * H, (0.818 - 0.186 - 0.146) * H, 0.12)
    b = math.radians(bend_deg)
    pelvis = j["hip"]
    for name, p in upper.items():  # bend the trunk forward about the pelvis
        d = p - pelvis
        j[name] = pelvis + np.array([d[0], d[1] * math.cos(b) - d[2] * math.sin(b),
                                     d[2] * math.cos(b) + d[1] * math.sin(b)])
    pts = np.stack([j[n] for n in JOINTS])
    y = math.radians(yaw_deg)  # person frame -> camera frame: facing the camera (forward = -z)
    x_cam = -pts[:, 0] * math.cos(y) + pts[:, 2] * math.sin(y)
    z_cam = distance_m - (pts[:, 2] * math.cos(y) + pts[:, 0] * math.sin(y))
    return np.stack([x_cam, 1.5 - pts[:, 1], z_cam], axis=1)


def project(points_3d, cam: CameraModel) -> np.ndarray:
    img, _ = cv2.projectPoints(np.asarray(points_3d, np.float64).reshape(-1, 3), np.zeros(3), np.zeros(3),
                               cam.K, cam.dist_array)
    return img.reshape(np.shape(points_3d)[:-1] + (2,))


# ---------------------------------------------------------------------------- COCO -> H36M


@pytest.mark.parametrize("yaw, bend", [(0, 0), (35, 0), (-60, 20), (0, 45), (90, 10)])
def test_h36m_projected_to_coco_maps_back_close(yaw, bend):
    j3 = skeleton_3d(yaw, bend)
    truth = project(j3, CANON)
    coco = project(h36m_to_coco_3d(j3), CANON)
    got = coco_to_h36m(np.concatenate([coco, np.full((17, 1), 0.8)], axis=1))
    height_px = np.ptp(truth[:, 1])
    err = np.linalg.norm(got[:, :2] - truth, axis=1)
    copied = [i for i in range(N_JOINTS) if i not in (HIP, SPINE, THORAX, HEAD)]
    assert err[copied].max() < 1e-9  # limbs and nose are the same points
    assert err[[HIP, THORAX, SPINE]].max() < 0.005 * height_px  # midpoints (perspective makes them inexact)
    assert err[HEAD] < 0.02 * height_px
    assert np.all(got[:, 2] == 0.8)


def test_head_falls_back_to_eyes_and_missing_points_propagate():
    j3 = skeleton_3d(0, 0)
    truth = project(j3, CANON)
    coco = np.concatenate([project(h36m_to_coco_3d(j3), CANON), np.full((17, 1), 0.9)], axis=1)
    eyes = [COCO_JOINTS.index("left_eye"), COCO_JOINTS.index("right_eye")]
    coco[COCO_JOINTS.index("left_ear"), 2] = 0.8  # a little less sure of the ears: still the ears
    np.testing.assert_allclose(coco_to_h36m(coco)[HEAD], [*truth[HEAD], 0.8], atol=1e-6)
    coco[eyes, :2] += 30.0  # (moved, to see which pair the head comes from)
    coco[COCO_JOINTS.index("left_ear"), 2] = 0.1  # ears hidden: the eyes stand in
    got = coco_to_h36m(coco)
    assert np.linalg.norm(got[HEAD, :2] - truth[HEAD] - 1.5 * 30.0) < 0.03 * np.ptp(truth[:, 1])
    assert got[HEAD, 2] == pytest.approx(0.9)
    coco[eyes, :2] -= 30.0
    coco[COCO_JOINTS.index("right_hip"), 0] = np.nan
    coco[COCO_JOINTS.index("left_shoulder"), 2] = 0.2
    got = coco_to_h36m(coco)
    assert np.isnan(got[HIP, 2]) and np.isnan(got[SPINE, 2]) and np.isnan(got[INDEX["right_hip"], 0])
    assert got[THORAX, 2] == pytest.approx(0.2) and got[INDEX["left_shoulder"], 2] == pytest.approx(0.2)
    assert got[INDEX["left_hip"], 2] == pytest.approx(0.9)


def test_formats_and_batches():
    rng = np.random.default_rng(0)
    coco = rng.uniform(0, 500, (4, 17, 2))
    batch = coco_to_h36m(coco)
    assert batch.shape == (4, 17, 3) and np.all(batch[..., 2] == 1)
    np.testing.assert_allclose(batch[2], coco_to_h36m(coco[2]))
    h = rng.uniform(0, 500, (17, 3))
    np.testing.assert_array_equal(to_h36m(h, "h36m"), h)
    with pytest.raises(ValueError, match="format"):
        to_h36m(h, "openpose25")
    with pytest.raises(ValueError, match="shape"):
        coco_to_h36m(coco[:, :15])


# ---------------------------------------------------------------------------- JSON lines


def _write(tmp_path, lines, name="kp.jsonl"):
    p = tmp_path / name
    p.write_text("\n".join(lines) + "\n")
    return p


def test_reads_nested_flat_null_and_frame_only(tmp_path):
    kp = [[float(i), float(2 * i), 0.5] for i in range(17)]
    flat = [v for row in kp for v in row]
    flat_xy = [v for row in kp for v in row[:2]]
    kp_null = [row[:] for row in kp]
    kp_null[3] = [None, None, 0.0]
    p = _write(tmp_path, [
        json.dumps({"t": 0.0, "frame": 0, "people": [{"keypoints": kp, "id": 3}], "format": "coco"}),
        "",
        json.dumps({"frame": 2, "people": [{"keypoints": flat}, {"keypoints": flat_xy, "id": 5}]}),
        json.dumps({"t": 0.1, "people": [{"keypoints": kp_null}]}),
        json.dumps({"t": 0.2, "people": []}),
        json.dumps({"t": 0.3, "people": [{"keypoints": kp[:15]}]}),
    ])
    frames = list(read_keypoints_jsonl(p, "coco", fps=20))
    assert [f.t_s for f in frames] == [0.0, 0.1, 0.1, 0.2, 0.3]
    assert frames[0].people[0].id == 3 and frames[0].people[0].keypoints.shape == (17, 3)
    np.testing.assert_array_equal(frames[1].people[0].keypoints, frames[0].people[0].keypoints)
    assert np.all(frames[1].people[1].keypoints[:, 2] == 1.0) and frames[1].people[1].id == 5
    assert np.isnan(frames[2].people[0].keypoints[3, 0])
    assert frames[3].people == []
    assert frames[4].people[0].keypoints.shape == (15, 3)  # passed on; the lifter reports it


def test_non_utf8_bytes_name_file_and_line(tmp_path):
    p = tmp_path / "kp.jsonl"
    p.write_bytes(b'{"t": 0.0, "people": []}\n{"t": 0.1, "people": [], "x": "\xff"}\n')
    with pytest.raises(KeypointInputError, match=r"kp.jsonl:2: not UTF-8 text"):
        list(read_keypoints_jsonl(p, "coco"))


@pytest.mark.parametrize("line, message", [
    ('{"t": 0.1, "people": [', "not valid JSON"),
    ('[1, 2, 3]', "expected a JSON object"),
    ('{"people": []}', "neither 't'"),
    ('{"t": "soon", "people": []}', "t: expected a finite number"),
    ('{"t": 0.1, "people": {}}', "people: expected a list"),
    ('{"t": 0.1, "people": [{"kp": []}]}', "people[0]: expected an object with 'keypoints'"),
    ('{"t": 0.1, "people": [{"keypoints": [[1, 2, 3, 4]]}]}', "each keypoint must be"),
    ('{"t": 0.1, "people": [{"keypoints": [1, 2, 3, 4, 5]}]}', "neither x,y,score"),
    ('{"t": 0.1, "people": [{"keypoints": [["a", 2, 0.5]]}]}', "keypoints[0][0]: expected a finite number"),
    ('{"t": 0.1, "people": [{"keypoints": [[1e300, 2, 0.5]]}]}', "keypoints[0][0]: expected a finite number"),
    ('{"t": 0.1, "people": [{"keypoints": [[1, Infinity, 0.5]]}]}', "Infinity is not JSON"),
    ('{"t": 0.1, "people": [{"keypoints": [[1, 1e999, 0.5]]}]}', "keypoints[0][1]: expected a finite number"),
    ('{"t": 0.1, "people": [{"keypoints": [[1, 2, 1.5]]}]}', "keypoints score[0]: expected a finite number in [0, 1]"),
    ('{"t": 0.1, "people": [{"keypoints": [[1, 2, ' + "9" * 400 + ']]}]}', "expected a finite number in [0, 1]"),
    ('{"t": 1.7e308, "people": []}', "t: expected a finite number in [-1e+10, 1e+10]"),
    ('{"frame": ' + "9" * 400 + ', "people": []}', "frame: expected an integer"),
    ('{"t": 0.1, "people": ' + "[" * 5000 + "]" * 5000 + '}', "nested more than"),
    ('{"t": 0.1, "people": [{"keypoints": [], "id": ' + "1" * 400 + '}]}', "id: expected an integer"),
    ('{"t": 0.1, "people": [{"keypoints": ' + json.dumps([[1, 2, 1]] * 18) + '}]}', "18 keypoints"),
    ('{"t": 0.1, "format": "h36m", "people": []}', "declared 'coco'"),
    ('{"t": 0.1, "people": [{"keypoints": [], "id": "x"}]}', "id: expected an integer"),
])
def test_malformed_lines_name_file_and_line(tmp_path, line, message):
    good = json.dumps({"t": 0.0, "people": []})
    p = _write(tmp_path, [good, good, line, good])
    with pytest.raises(KeypointInputError) as e:
        list(read_keypoints_jsonl(p, "coco"))
    assert f"{p}:3:" in str(e.value) and message in str(e.value) and "\n" not in str(e.value)
    assert isinstance(e.value, InputError)


def test_missing_and_binary_files(tmp_path):
    with pytest.raises(KeypointInputError, match="nope.jsonl: cannot open"):
        list(read_keypoints_jsonl(tmp_path / "nope.jsonl"))
    p = tmp_path / "bin.jsonl"
    p.write_bytes(b'{"t": 0, "people": []}\n\xff\xfe\x00\n')
    with pytest.raises(KeypointInputError, match=r"bin.jsonl:2: not UTF-8"):
        list(read_keypoints_jsonl(p))


# ---------------------------------------------------------------------------- person selection


def _person(center, size, score=0.9, pid=None):
    rng = np.random.default_rng(int(center[0]))
    xy = np.asarray(center) + rng.uniform(-size, size, (17, 2))
    return Person(np.concatenate([xy, np.full((17, 1), score)], axis=1), pid)


def test_person_selection_modes():
    small_sure = _person((100, 100), 20, 0.99, pid=1)
    big_unsure = _person((600, 300), 200, 0.5, pid=2)
    people = [small_sure, big_unsure]
    assert PersonSelector("largest").select(people) is big_unsure
    assert PersonSelector("confident").select(people) is small_sure
    assert PersonSelector("largest").select([]) is None
    tracker = PersonSelector("track")
    assert tracker.select(people) is big_unsure and tracker.track_id == 2
    bigger = _person((300, 300), 400, 0.9, pid=7)
    assert tracker.select([small_sure, bigger, big_unsure]) is big_unsure  # follows id 2, not the biggest
    assert tracker.select([small_sure, bigger]) is None  # lost: nobody else is taken
    assert PersonSelector("track", track_id=1).select(people) is small_sure
    low = big_unsure.keypoints.copy()
    low[:, 2] = 0.1  # a big box of keypoints nobody trusts does not count as large
    assert PersonSelector("largest", min_score=0.3).select([small_sure, Person(low)]) is small_sure
    with pytest.raises(ValueError):
        PersonSelector("random")


# ---------------------------------------------------------------------------- cameras


def _distorted_camera():
    return CameraModel(820.0, 815.0, 652.0, 355.0, 1280, 720, (-0.28, 0.09, 0.0008, -0.0005, -0.012))


def test_undistortion_round_trips_projectpoints_within_half_a_pixel():
    cam = _distorted_camera()
    rng = np.random.default_rng(1)
    # 3D points spread over the distorted camera's view (including its corners)
    u = rng.uniform(0, 1280, 400)
    v = rng.uniform(0, 720, 400)
    rays = cv2.undistortPoints(np.stack([u, v], 1)[:, None], cam.K, None).reshape(-1, 2)
    pts = np.concatenate([rays, np.ones((400, 1))], 1) * rng.uniform(2, 8, (400, 1))
    distorted = project(pts, cam)
    ideal = project(pts, CameraModel(cam.fx_px, cam.fy_px, cam.cx_px, cam.cy_px, 1280, 720))
    no_dist = CameraModel(cam.fx_px, cam.fy_px, cam.cx_px, cam.cy_px, 1280, 720)
    assert np.abs(distorted - ideal).max() > 20  # the distortion is not negligible
    assert np.abs(cam.to_camera(distorted, no_dist) - ideal).max() < 0.05  # required: 0.5 px
    # into the canonical camera: equal to projecting the same 3D points with it
    np.testing.assert_allclose(cam.to_camera(distorted, CANON), project(pts, CANON), atol=0.05)


def test_camera_nan_identity_and_normalisation():
    cam = _distorted_camera()
    pts = np.array([[100.0, 200.0], [np.nan, 5.0], [640.0, 360.0]])
    out = cam.to_camera(pts, CANON)
    assert np.isnan(out[1]).all() and np.isfinite(out[[0, 2]]).all()
    np.testing.assert_array_equal(CANON.to_camera(pts, CANON), pts)
    n = normalize_screen([[0.0, 0.0], [1280.0, 720.0], [640.0, 360.0]], 1280, 720)
    np.testing.assert_allclose(n, [[-1, -720 / 1280], [1, 720 / 1280], [0, 0]])
    kp = np.concatenate([pts, np.ones((3, 1))], 1)
    np.testing.assert_allclose(image_to_canonical(kp, None, CANON), normalize_screen(pts, 1280, 720))


def test_camera_files(tmp_path):
    cam = _distorted_camera()
    p = tmp_path / "cam.json"
    p.write_text(json.dumps(cam.to_dict()))
    assert CameraModel.from_json(p) == cam
    p.write_text(json.dumps({"K": cam.K.tolist(), "dist": list(cam.dist), "width_px": 1280, "height_px": 720}))
    assert CameraModel.from_json(p) == cam
    f = 640 / math.tan(math.radians(50))
    assert CANON.fx_px == pytest.approx(f) and CANON.cx_px == 640 and CANON.cy_px == 360
    for bad, msg in (({k: v for k, v in cam.to_dict().items() if k != "height_px"}, "'height_px': missing"),
                     ({**cam.to_dict(), "fx_px": -1}, "fx_px"),
                     ({**cam.to_dict(), "dist": [0.1, 0.2, 0.3]}, "3 coefficients"),
                     ({**cam.to_dict(), "width_px": 12.5}, "integers")):
        p.write_text(json.dumps(bad))
        with pytest.raises(InputError, match=msg) as e:
            CameraModel.from_json(p)
        assert str(p) in str(e.value)
    p.write_text("{nope")
    with pytest.raises(InputError, match="cam.json: not valid JSON"):
        CameraModel.from_json(p)
    for text, msg in (('{"fx_px": ' + "9" * 400 + "}", "cam.json: "), ("[" * 5000 + "]" * 5000, "nested more than"),
                      ('{"fx_px": NaN}', "NaN is not JSON")):
        p.write_text(text)
        with pytest.raises(InputError, match=msg):
            CameraModel.from_json(p)


# ---------------------------------------------------------------------------- who is who


def _person_px(centre_x: float, height_px: float, rng) -> np.ndarray:
    """A standing person's 17 keypoints (x, y, score) around ``centre_x``, ``height_px`` tall."""
    shape = np.array([[0, -0.45], [-0.02, -0.47], [0.02, -0.47], [-0.05, -0.46], [0.05, -0.46], [-0.12, -0.3],
                      [0.12, -0.3], [-0.15, -0.1], [0.15, -0.1], [-0.16, 0.05], [0.16, 0.05], [-0.08, 0.05],
                      [0.08, 0.05], [-0.08, 0.28], [0.08, 0.28], [-0.08, 0.5], [0.08, 0.5]])
    xy = shape * height_px + [centre_x, 360] + rng.normal(0, 2, (17, 2))
    return np.column_stack([xy, np.full(17, 0.9)])


def test_tracker_keeps_ids_through_a_crossing_and_a_short_absence():
    from edge_runtime.robot.keypoints import PersonTracker

    rng = np.random.default_rng(0)
    tracker = PersonTracker()
    ids = []
    for k in range(90):                               # a near (big) and a far (small) person cross
        t = k / 30
        near, far = _person_px(200 + 10 * k, 400, rng), _person_px(1100 - 10 * k, 250, rng)
        people = [Person(far, 5), Person(near, 5)] if k % 2 else [Person(near, 5), Person(far, 5)]
        if 40 <= k < 50:
            people = [people[0]] if people[0].keypoints is near else [people[1]]  # the far one hidden
        out = tracker.update(t, people)
        ids.append({("near" if p.keypoints is near else "far"): p.id for p in out})
        assert all(p.source_id == 5 for p in out)
    assert len({d["near"] for d in ids}) == 1 and len({d["far"] for d in ids if "far" in d}) == 1
    assert ids[0]["near"] != ids[0]["far"]
    near_id = ids[0]["near"]
    # the near one leaves and comes back where he left within max_lost_s: the same id
    back = tracker.update(90 / 30 + 1.0, [Person(_person_px(200 + 10 * 90, 400, rng))])
    assert back[0].id == near_id
    # gone longer than max_lost_s: a new person
    again = tracker.update(90 / 30 + 1.0 + tracker.params.max_lost_s + 0.1, [Person(_person_px(1100, 400, rng))])
    assert again[0].id not in (near_id, ids[0]["far"]) and tracker.created == 3


def test_tracker_drops_detections_that_are_not_people():
    from edge_runtime.robot.keypoints import PersonTracker

    kp = _person_px(500, 300, np.random.default_rng(1))
    kp[4:, 2] = 0.0                                  # only 4 keypoints seen
    tracker = PersonTracker()
    assert tracker.update(0.0, [Person(kp)]) == [] and tracker.rejected == 1
