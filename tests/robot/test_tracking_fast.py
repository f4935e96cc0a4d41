"""The person tracker's, the lifter's and the floor anchoring's fast forms (session 15, per-frame CPU) pinned to
the forms they replaced: the same floating-point results to the bit on random inputs, so no decision changes."""
import math
from types import SimpleNamespace

import numpy as np
import pytest

from edge_runtime.robot import calibration as cal
from edge_runtime.robot import keypoints as kpm
from edge_runtime.robot.calibration import CalibrationParams, anchor_factor
from edge_runtime.robot.keypoints import (
    EYES_FOR_EARS,
    HEAD,
    W_EARS,
    W_EYES,
    CameraModel,
    PeopleTrackParams,
    PersonTracker,
    _pair_costs,
    _seen,
    _size_px,
    _Track,
    as_keypoints,
)
from edge_runtime.robot.lifter import StreamingLifter


def same(a, b):
    """Equal to the bit (NaN where NaN, the sign of zero too)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return a.shape == b.shape and a.tobytes() == b.tobytes()


def old_map(c, w):
    used = w != 0
    finite = np.isfinite(c[..., :2])
    xy = np.einsum("hc,...cd->...hd", w, np.where(finite, c[..., :2], 0.0))
    bad = np.einsum("hc,...c->...h", used, ~finite.all(axis=-1)) > 0
    score = np.min(np.where(used, c[..., None, :, 2], np.inf), axis=-1)
    xy[bad] = np.nan
    score[bad] = np.nan
    return np.concatenate([xy, score[..., None]], axis=-1)


def old_coco_to_h36m(kp):
    c = as_keypoints(kp)
    out = old_map(c, W_EARS)
    from_eyes = old_map(c, W_EYES[HEAD:HEAD + 1])[..., 0, :]
    ears_score = out[..., HEAD, 2]
    use_eyes = np.isfinite(from_eyes[..., 0]) & ~(ears_score >= EYES_FOR_EARS * from_eyes[..., 2])
    out[..., HEAD, :] = np.where(use_eyes[..., None], from_eyes, out[..., HEAD, :])
    return out


def old_size_px(kp, min_score):
    seen = _seen(kp, min_score)
    heights = [np.linalg.norm(kp[a, :2] - kp[b, :2]) / frac for a, b, frac in kpm._BONES if seen[a] and seen[b]]
    if len(heights) >= 2:
        return max(float(np.sort(heights)[-2]), 1.0)
    xy = kp[seen, :2]
    return max(float(np.linalg.norm(xy.max(axis=0) - xy.min(axis=0))), 1.0)


def _cost(tracker, tr, kp, t_s, seen=None):
    """One pair's match cost as the tracker weighs it (:func:`_pair_costs` of one track and one detection)."""
    seen = _seen(kp, tracker.params.min_score) if seen is None else seen
    return _pair_costs([(0, tr)], kp[None], seen[None], t_s, tracker.params)[0, 0]


def _follow(tracker, tr, kp, t_s, seen=None):
    """The tracker's move of one track to detection ``kp`` (its ``_follow_all`` of one)."""
    seen = _seen(kp, tracker.params.min_score) if seen is None else seen
    tracker._follow_all([tr], kp[None], seen[None], [_size_px(kp, tracker.params.min_score, seen)], t_s)


def old_cost(p, tr, kp, t_s):
    if len(tr.xy) != len(kp):
        return math.inf
    pred = tr.predicted(t_s, p.max_predict_s)
    both = _seen(kp, p.min_score) & np.isfinite(pred).all(axis=1)
    if both.sum() < 2:
        return math.inf
    d = float(np.median(np.linalg.norm(kp[both, :2] - pred[both], axis=1))) / tr.size_px
    gate = p.gate + p.gate_growth_per_s * max(t_s - tr.t_s, 0.0)
    return d / gate if d <= gate else math.inf


def old_follow(p, tr, kp, t_s):
    seen = _seen(kp, p.min_score)
    dt = t_s - tr.t_s
    both = seen & np.isfinite(tr.xy).all(axis=1)
    if dt > 0 and both.any():
        v = np.mean(kp[both, :2] - tr.xy[both], axis=0) / dt
        a = p.velocity_smoothing
        tr.velocity_pxps = a * v + (1 - a) * tr.velocity_pxps
    moved = tr.xy + tr.velocity_pxps * max(dt, 0.0)
    tr.xy = np.where(seen[:, None], kp[:, :2], moved)
    tr.size_px = old_size_px(kp, p.min_score)
    tr.t_s = t_s


def random_keypoints(rng, lead=()):
    """COCO/H36M-shaped (..., 17, 3): pixels of various scales, some NaN / inf / -0 coordinates, scores in
    [0, 1] with some NaN, ties at the threshold."""
    kp = rng.uniform(-50, 1500, lead + (17, 3)) * rng.choice([1e-3, 1.0, 1e3])
    kp[..., 2] = rng.choice([rng.uniform(0, 1), 0.3, 1.0, 0.0])
    kp[..., 2] = np.where(rng.random(lead + (17,)) < 0.5, rng.uniform(0, 1, lead + (17,)), kp[..., 2])
    for value, share in ((np.nan, 0.08), (np.inf, 0.02), (-np.inf, 0.02), (-0.0, 0.02), (0.0, 0.02)):
        kp[rng.random(kp.shape) < share * rng.uniform(0, 2)] = value
    return kp


def test_coco_to_h36m_is_the_old_conversion():
    rng = np.random.default_rng(1501)
    for case in range(3000):
        lead = () if case % 4 else tuple(rng.integers(1, 4, rng.integers(1, 3)))
        kp = random_keypoints(rng, lead)
        if case % 7 == 0:
            kp = kp[..., :2]
        kpm._H36M_MEMO.clear()
        want = old_coco_to_h36m(kp)
        assert same(kpm.coco_to_h36m(kp), want), case
        assert same(kpm.coco_to_h36m(kp), want), case  # the memo's copy


def test_coco_to_h36m_of_clean_keypoints_is_the_old_conversion():
    """The usual frame, every coordinate finite and every score 1 (session 23's shortcuts for it), and now and
    then scores of zero of either sign."""
    rng = np.random.default_rng(2302)
    for case in range(1500):
        lead = () if case % 4 else tuple(rng.integers(1, 4, rng.integers(1, 3)))
        kp = np.nan_to_num(random_keypoints(rng, lead), nan=321.5, posinf=1e300, neginf=-1e300)
        kp[..., 2] = np.where(rng.random(lead + (17,)) < (0.2 if case % 3 == 0 else 0.0),
                              rng.choice([0.0, -0.0]), 1.0)
        kpm._H36M_MEMO.clear()
        assert same(kpm.coco_to_h36m(kp), old_coco_to_h36m(kp)), case


def test_size_px_is_the_old_size():
    rng = np.random.default_rng(1502)
    for case in range(3000):
        kp = random_keypoints(rng)
        ms = float(rng.choice([0.0, 0.3, 0.5, 0.9]))
        if not _seen(kp, ms).any():
            continue
        want = old_size_px(kp, ms)
        assert same(_size_px(kp, ms), want), case
        assert same(_size_px(kp, ms, _seen(kp, ms)), want), case
        assert type(_size_px(kp, ms)) is float


def test_cost_and_follow_are_the_old_ones():
    rng = np.random.default_rng(1503)
    p = PeopleTrackParams()
    tracker = PersonTracker(p, keypoint_format="h36m")
    n_finite = 0
    for case in range(3000):
        kp = random_keypoints(rng) if case % 3 else np.column_stack(
            [rng.uniform(0, 1000, (17, 2)), rng.uniform(0.2, 1, 17)])
        xy = kp[:, :2] + rng.normal(0, rng.choice([1.0, 20.0, 200.0]), (17, 2))
        xy[rng.random(17) < 0.15] = np.nan
        t0 = float(rng.uniform(0, 100))
        t1 = t0 + float(rng.choice([0.0, 1 / 30, rng.uniform(0, 3), -0.01]))
        size, velocity = float(rng.uniform(50, 600)), rng.normal(0, 30, 2)
        tracks = [_Track(7, xy.copy(), size, t0, velocity.copy()) for _ in range(4)]
        want = old_cost(p, tracks[0], kp, t1)
        n_finite += math.isfinite(want)
        assert same(_cost(tracker, tracks[1], kp, t1), want), case
        assert same(_cost(tracker, tracks[1], kp, t1, _seen(kp, p.min_score)), want), case
        if _seen(kp, p.min_score).any():
            a, b = tracks[2], tracks[3]
            old_follow(p, a, kp, t1)
            _follow(tracker, b, kp, t1, _seen(kp, p.min_score) if case % 2 else None)
            for f in ("xy", "velocity_pxps", "size_px", "t_s"):
                assert same(getattr(b, f), getattr(a, f)), (case, f)
    assert n_finite > 300


def test_tracker_ids_as_before():
    """Whole-tracker check: a stream of noisy walkers gets the same ids from the tracker and from a copy of it
    using the old cost and follow."""
    rng = np.random.default_rng(1504)

    class Old(PersonTracker):
        def _costs(self, kps, seen, t_s, all_seen=False):  # every pair's old cost, one by one (session 18 made them
            # in one pass; all_seen: session 24's note that every joint is seen, which the old way does not use)
            return {(tid, i): old_cost(self.params, tr, kp, t_s) for tid, tr in self.tracks.items()
                    for i, kp in enumerate(kps)}

        def _follow_all(self, tracks, kps, seen, sizes_px, t_s, all_seen=False):  # one by one, the old way
            for tr, kp in zip(tracks, kps):
                old_follow(self.params, tr, kp, t_s)

    new, old = PersonTracker(), Old()
    for k, _ in enumerate(range(300)):
        t = k / 30
        people = []
        for w in range(int(rng.integers(0, 4))):
            kp = np.column_stack([rng.uniform(0, 60, (17, 2)) + (300 * w + 3 * k, 200), rng.uniform(0, 1, 17)])
            kp[rng.random((17, 3)) < 0.03] = np.nan
            people.append(kpm.Person(kp))
        a = new.update(t, people)
        b = old.update(t, people)
        assert [x.id for x in a] == [x.id for x in b]
        for tid in old.tracks:
            for f in ("xy", "velocity_pxps", "size_px", "t_s"):
                assert same(getattr(new.tracks[tid], f), getattr(old.tracks[tid], f))


def old_rays(self, model_joints=None):
    """StreamingLifter._rays as it was through session 15's first round (np.linalg.norm, np.column_stack)."""
    c = self.canonical_camera
    fx_in = c.fx_px if self.camera is None else self.camera.fx_px
    pixels = (self._last_seen + (1.0, c.height_px / c.width_px)) * (c.width_px / 2)
    if model_joints is not None and self.params.ray_tolerance_px * c.fx_px / fx_in > 0:
        to_model = (model_joints[:, :2] / model_joints[:, 2:3] * np.array([c.fx_px, c.fy_px])
                    + (c.cx_px, c.cy_px) - pixels)
        limit = self.params.ray_tolerance_px * c.fx_px / fx_in
        pixels = pixels + to_model * np.minimum(
            1.0, limit / np.maximum(np.linalg.norm(to_model, axis=1, keepdims=True), 1e-9))
    return np.column_stack([(pixels[:, 0] - c.cx_px) / c.fx_px, (pixels[:, 1] - c.cy_px) / c.fy_px, np.ones(17)])


def test_rays_are_the_old_rays():
    rng = np.random.default_rng(1505)
    canonical = CameraModel.from_fov(1000, 1002, 80.0)
    for case in range(2000):
        stub = SimpleNamespace(canonical_camera=canonical,
                               camera=None if case % 2 else CameraModel.from_fov(1920, 1080, rng.uniform(60, 120)),
                               params=SimpleNamespace(ray_tolerance_px=float(rng.choice([0.0, 3.0, 40.0]))),
                               _last_seen=rng.uniform(-1.2, 1.2, (17, 2)))
        mj = np.column_stack([rng.normal(0, 1, (17, 2)), rng.uniform(0.5, 9, 17)])
        if case % 5 == 0:
            mj[rng.integers(17)] = np.nan
        for m in (None, mj):
            assert same(StreamingLifter._rays(stub, m), old_rays(stub, m)), case


def old_anchor_factor(joints_cam_m, A, b, params=CalibrationParams(), observed=None):
    j = np.asarray(joints_cam_m, float).reshape(-1, 3)
    A, b = np.asarray(A, float), np.asarray(b, float)
    ankles = j[[cal.L_ANKLE, cal.R_ANKLE]]
    rays = ankles @ A.T
    ok = np.isfinite(rays).all(axis=1)
    if observed is not None:
        seen = ok & np.asarray(observed, bool)[[cal.L_ANKLE, cal.R_ANKLE]]
        ok = seen if seen.any() else ok
    if not ok.any():
        return 1.0, cal.ANCHOR_NO_ANKLE
    rays = rays[ok]
    lower = np.argmin(rays[:, 1])
    feet = rays if np.ptp(rays[:, 1]) <= cal.ANCHOR_LEVEL_FEET_M else rays[[lower]]
    drop_m = b[1] - (params.floor_y_m + params.ankle_height_m)
    if not drop_m >= params.anchor_min_camera_height_m:
        return 1.0, cal.ANCHOR_CAMERA_LOW
    if (-feet[:, 1] < np.sin(np.radians(params.anchor_min_ray_deg)) * np.linalg.norm(feet, axis=1)).any():
        return 1.0, cal.ANCHOR_RAY_FLAT
    log_floor = float(np.mean(np.log(drop_m / -feet[:, 1])))
    k = np.exp(log_floor)
    if np.isfinite(cal.ANCHOR_LIFTER_DEPTH_SD):
        k = cal._nearer_to_arm(j[cal.HIP] @ A.T, b, k, np.exp(cal._fused_with_lifter(log_floor, feet, drop_m)))
    return float(np.clip(k, params.anchor_min_scale, params.anchor_max_scale)), None


@pytest.mark.parametrize("params", [CalibrationParams(), CalibrationParams(anchor_min_scale=0.95, anchor_max_scale=1.05)])
def test_anchor_factor_is_the_old_one(params):
    rng = np.random.default_rng(1506)
    reasons = set()
    for case in range(3000):
        c, s = math.cos(rng.uniform(0.1, 0.9)), math.sin(rng.uniform(0.1, 0.9))
        A = np.array([[1.0, 0, 0], [0, c, -s], [0, s, c]]) @ np.diag(rng.choice([-1.0, 1.0], 3) if case % 9 == 0
                                                                         else np.ones(3))
        b = np.array([0.0, rng.uniform(-0.5, 4.0), 0.0])
        j = np.column_stack([rng.normal(0, 0.5, 17), rng.normal(0.8, 0.6, 17), rng.uniform(0.5, 8, 17)])
        j[rng.random((17, 3)) < 0.03] = np.nan
        obs = None if case % 3 == 0 else rng.random(17) < 0.8
        want = old_anchor_factor(j, A, b, params, obs)
        got = anchor_factor(j, A, b, params, obs)
        assert got[1] == want[1] and same(got[0], want[0]) and type(got[0]) is float, case
        reasons.add(want[1])
        if want[1] is None and want[0] in (params.anchor_min_scale, params.anchor_max_scale):
            reasons.add("clamped")
    assert {None, cal.ANCHOR_NO_ANKLE, cal.ANCHOR_CAMERA_LOW, cal.ANCHOR_RAY_FLAT, "clamped"} <= reasons
