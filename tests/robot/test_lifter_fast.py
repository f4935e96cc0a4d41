"""The lifter's per-frame path of session 16 (StreamingLifter._prepare / _observe / _finish, the pixel constants
made once, PeopleLifter's one call for everyone) pinned to the path it replaced: every LiftedPose field, the
joint memory, the ring buffer and the counters the same to the bit, frame by frame, on random streams with
NaN, +-inf, +-0, low scores, nobody, wrong shapes, dropped frames, clocks going back, with and without a
camera of its own (distorted or not), in H36M and COCO order."""
import math
from types import SimpleNamespace

import numpy as np
import pytest
from support.lifter import CANONICAL, make_lifter_assets, onnx_calls, random_walk_keypoints

from edge_runtime.core.numeric import median, norms2
from edge_runtime.core.skeleton import HIP, JOINTS, N_JOINTS
from edge_runtime.robot import hazard
from edge_runtime.robot import lifter as lm
from edge_runtime.robot.hazard import enough_joints
from edge_runtime.robot.keypoints import CameraModel, image_to_canonical, to_h36m
from edge_runtime.robot.lifter import LiftedPose, LifterParams, PeopleLifter, StreamingLifter


@pytest.fixture(scope="module")
def assets(tmp_path_factory):
    return make_lifter_assets(tmp_path_factory.mktemp("lifter_fast_assets"))


class SessionSixteenLifter(StreamingLifter):
    """StreamingLifter.push as it was before session 16 (one call per person; the arithmetic of each step
    written out as it stood), the reference the new path must equal."""

    def push(self, t_s, keypoints):
        st, t_s, last = self.stats, float(t_s), self._last_t
        st.frames += 1
        if not (math.isfinite(t_s) and abs(t_s) <= lm.MAX_TIMESTAMP_S):
            return self._invalid(t_s, f"{lm.BAD_TIME}: timestamp {t_s}", None)
        if last is not None and t_s < last - self.params.lost_timeout_s:
            self.restart()  # a new stream
        elif last is not None and t_s <= last:
            return self._invalid(t_s, f"{lm.TIME_NOT_INCREASING}: {t_s:.4f} s after {last:.4f} s", None)
        steps = self._steps_since_last(t_s)
        self._last_t = t_s
        self._frames_since_buffered += steps
        observed, why = self.old_observe(keypoints)
        self._age[~observed] += steps
        held = ~observed & (self._age <= self.params.hold_frames)
        stale = ~observed & ~held
        if self._buffered_t is not None and t_s - self._buffered_t > self.params.lost_timeout_s + 1e-9:
            st.resets += 1
            self.reset()
        if stale.any() and (why is not None or not enough_joints(~stale)):
            if why is None:
                why = f"{lm.MISSING_JOINTS}: " + ", ".join(JOINTS[j] for j in np.flatnonzero(stale))
            return self._invalid(t_s, why, observed)
        st.joints_held += int(held.sum())
        st.joints_missing += int(stale.sum())
        frame = self._last_seen.astype(np.float32)
        self._impute(frame, stale)
        self._buffer(frame)
        return self.old_run(t_s, observed, held, stale)

    def old_observe(self, keypoints):
        kp = None if keypoints is None else np.asarray(keypoints, dtype=np.float64)
        if kp is None or kp.shape[1:] not in ((2,), (3,)) or len(kp) != N_JOINTS:
            return StreamingLifter._observe(self, keypoints)  # nobody, or not 17 joints: not changed
        kp = to_h36m(kp, self.keypoint_format)
        ok = np.isfinite(kp[:, :2]).all(axis=1) & (kp[:, 2] >= self.params.min_score)
        if ok.any():
            norm = image_to_canonical(kp[ok], self.camera, self.canonical_camera)
            ok_norm = np.isfinite(norm).all(axis=1) & (np.abs(norm) <= lm.MAX_NORMALISED).all(axis=1)
            idx = np.flatnonzero(ok)
            ok[idx[~ok_norm]] = False
            again = ok & (self._age == 0)
            if again.any():
                step = median(norm[ok_norm][again[idx[ok_norm]]] - self._last_seen[again], axis=0)
                self._moved[~ok] += step
            self._moved[ok] = 0.0
            self._last_seen[idx[ok_norm]] = norm[ok_norm]
            self._age[idx[ok_norm]] = 0
        return ok, None

    def old_run(self, t_s, observed, held, missing):
        pose, root = self.session.run(self._outputs, {lm.INPUT_NAME: self.window()[None]})
        self.stats.inferences += 1
        return self.old_finish(t_s, observed, held, missing, pose, root)

    def old_finish(self, t_s, observed, held, missing, pose, root):
        model_joints = pose.reshape(N_JOINTS, 3).astype(np.float64) + root.reshape(3)
        if not np.isfinite(model_joints).all():
            return self._invalid(t_s, "model_output: non-finite joints", observed)
        if model_joints[:, 2].min() < lm.MIN_DEPTH_M:
            return self._invalid(t_s, f"model_output: a joint {model_joints[:, 2].min():.2f} m in front of the "
                                      "camera", observed)
        joints = self.old_rays(model_joints) * model_joints[:, 2:3]
        joints[missing] = model_joints[missing]
        self.stats.valid += 1
        self.stats.warming_up += self.warming_up
        return LiftedPose(t_s, joints, joints[HIP].copy(), True, None, observed, self.warming_up, 0.0, held,
                          model_joints, missing)

    def old_rays(self, model_joints):
        c = self.canonical_camera
        pixels = (self._last_seen + (1.0, c.height_px / c.width_px)) * (c.width_px / 2)
        limit = self.params.ray_tolerance_px * c.fx_px / (self.camera.fx_px if self.camera is not None else c.fx_px)
        if limit > 0:
            d = model_joints[:, :2] / model_joints[:, 2:3] * np.array([c.fx_px, c.fy_px]) + (c.cx_px, c.cy_px) - pixels
            pixels = pixels + d * np.minimum(1.0, limit / np.maximum(norms2(d)[:, None], 1e-9))
        out = np.ones((N_JOINTS, 3))
        out[:, 0] = (pixels[:, 0] - c.cx_px) / c.fx_px
        out[:, 1] = (pixels[:, 1] - c.cy_px) / c.fy_px
        return out


def same(a, b) -> bool:
    """Equal to the bit (None as None); arrays of the same dtype and shape."""
    if a is None or b is None:
        return a is None and b is None
    a, b = np.asarray(a), np.asarray(b)
    return a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes()


POSE_ARRAYS = ("joints_cam_m", "root_cam_m", "observed", "held", "joints_model_cam_m", "missing")
STATE_ARRAYS = ("_ring", "_last_seen", "_moved", "_age")


def assert_same_pose(got: LiftedPose, want: LiftedPose, where) -> None:
    assert (got.t_s, got.valid, got.reason, got.warming_up) == (want.t_s, want.valid, want.reason,
                                                                  want.warming_up), where
    for name in POSE_ARRAYS:
        assert same(getattr(got, name), getattr(want, name)), (where, name)


def assert_same_state(new: StreamingLifter, old: StreamingLifter, where) -> None:
    for name in STATE_ARRAYS:
        assert same(getattr(new, name), getattr(old, name)), (where, name)
    assert (new._pos, new._filled, new._buffered_t, new._frames_since_buffered, new._last_t) == \
           (old._pos, old._filled, old._buffered_t, old._frames_since_buffered, old._last_t), where


def stats_of(lifter) -> dict:
    d = lifter.stats.to_json()
    return {k: v for k, v in d.items() if k not in ("infer_s", "mean_infer_ms")}


def _odd_keypoints(rng, kp: np.ndarray, fmt: str) -> np.ndarray:
    """The frame with some of: a hidden or low-scored joint, NaN / inf / -inf coordinates or scores, signed
    zeros, points far outside the image."""
    kp = kp.copy()
    r = rng.random()
    if r < 0.25:
        kp[rng.integers(17, size=rng.integers(1, 4)), 2] = rng.choice([0.0, 0.1, np.nan, -0.0, 0.3])
    elif r < 0.35:
        kp[rng.integers(17), rng.integers(2)] = rng.choice([np.nan, np.inf, -np.inf])
    elif r < 0.4:
        kp[rng.integers(17), :2] = rng.choice([-0.0, 0.0, 1e7, -1e7, 1e300])
    elif r < 0.43:
        kp[:, 2] = np.nan
    elif r < 0.46 and fmt == "coco":
        kp[rng.integers(17), 2] = np.inf
    return kp


CAMERAS = {
    "none": None,
    "same": CameraModel(**CANONICAL),
    "wide": CameraModel.from_fov(1920, 1080, 100.0),
    "distorted": CameraModel(900.0, 905.0, 655.0, 352.0, 1280, 720, (-0.21, 0.06, 0.001, -0.0005, -0.01)),
}


def _stream(rng, n_frames: int):
    """(t_s, keypoints or None or a wrongly shaped array) for a stream with gaps, repeats and jumps back."""
    walk = random_walk_keypoints(rng, n_frames)
    t = 0.0
    for k in range(n_frames):
        r = rng.random()
        t += 1 / 30 if r > 0.08 else rng.choice([2 / 30, 5 / 30, 0.7, 0.0, -0.02, -1.0])
        if r < 0.01:
            yield float(rng.choice([np.nan, np.inf, 2e10])), walk[k]
        elif r < 0.04:
            yield t, None
        elif r < 0.05:
            yield t, walk[k, :12]
        elif r < 0.07:
            yield t, walk[k, :, :2]
        else:
            yield t, walk[k]


@pytest.mark.parametrize("camera", sorted(CAMERAS))
@pytest.mark.parametrize("fmt", ["h36m", "coco"])
@pytest.mark.parametrize("precision", ["fp32", "int8"])
def test_push_is_the_old_push(assets, camera, fmt, precision, monkeypatch):
    rng = np.random.default_rng(1600 + len(camera) + 10 * (fmt == "coco"))
    codes, counted = set(), []
    # shipped, no joint may be missing beyond hold_frames; with a few allowed, the imputation runs too
    for tolerance_px, max_missing in ((1.5, 0), (0.0, 3)):
        monkeypatch.setattr(hazard, "MAX_MISSING_JOINTS", max_missing)
        params = LifterParams(precision=precision, ray_tolerance_px=tolerance_px, hold_frames=2)
        new = StreamingLifter.from_manifest(assets, params, camera=CAMERAS[camera], keypoint_format=fmt)
        old = SessionSixteenLifter.from_manifest(assets, params, camera=CAMERAS[camera], keypoint_format=fmt)
        for k, (t, kp) in enumerate(_stream(rng, 300)):
            if kp is not None and kp.shape == (17, 3):
                kp = _odd_keypoints(rng, kp, fmt)
                if k % 40 < 6:  # a wrist hidden for longer than hold_frames
                    kp[9 if fmt == "coco" else 16, 2] = 0.0
            got, want = new.push(t, kp), old.push(t, kp)
            assert_same_pose(got, want, (camera, fmt, k))
            assert_same_state(new, old, (camera, fmt, k))
            codes.add(want.code)
        assert stats_of(new) == stats_of(old)
        counted.append(new.stats)
    assert {None, lm.NO_PERSON, lm.MISSING_JOINTS, lm.TIME_NOT_INCREASING, lm.BAD_TIME} <= codes
    for name in ("joints_held", "joints_missing", "frames_interpolated", "restarts", "resets", "wrong_joint_count"):
        assert sum(getattr(st, name) for st in counted) > 0, name


def test_people_lifter_is_one_old_lifter_per_person(assets, monkeypatch):
    """Up to four people, coming and going, hidden joints, nobody: PeopleLifter's one call per frame gives each
    person what his own old lifter gives him."""
    rng = np.random.default_rng(1601)
    camera = CAMERAS["wide"]
    params = LifterParams(precision="int8", hold_frames=2)
    people = PeopleLifter(StreamingLifter.from_manifest(assets, params, camera=camera, keypoint_format="coco"))
    calls = onnx_calls(people.template, monkeypatch)
    old: dict = {}
    walks = [random_walk_keypoints(rng, 300) for _ in range(4)]
    for k in range(300):
        t = k / 30
        here = [pid for pid in range(4) if (k // (15 + 7 * pid)) % 3 != 2]
        frame = [SimpleNamespace(id=pid, keypoints=_odd_keypoints(rng, walks[pid][k], "coco")) for pid in here]
        got = people.push(t, frame)
        for (gid, g), person in zip(got, frame, strict=True):
            ref = old.setdefault(person.id, SessionSixteenLifter.from_manifest(assets, params, camera=camera,
                                                                             keypoint_format="coco"))
            assert gid == person.id
            assert_same_pose(g, ref.push(t, person.keypoints), (k, gid))
            assert_same_state(people.lifters[gid], ref, (k, gid))
        for pid in list(old):  # as PeopleLifter forgets people: after the frame, gone for longer than the timeout
            if not (t - params.lost_timeout_s <= old[pid]._last_t <= t):
                del old[pid]
        assert sorted(people.lifters) == sorted(old)
    assert max(calls) >= 3 and calls.count(1) > 0  # batches of several people, and of one
    assert len(calls) < people.stats.inferences


def test_a_model_of_fixed_batch_takes_one_call_per_person(assets, monkeypatch):
    people = PeopleLifter(StreamingLifter.from_manifest(assets, LifterParams(precision="fp32")))
    assert people.template._batches
    people.template._batches = False  # what _symbolic_batch says of an input (1, 27, 17, 2)
    calls = onnx_calls(people.template, monkeypatch)
    rng = np.random.default_rng(1602)
    walks = [random_walk_keypoints(rng, 5) for _ in range(2)]
    for k in range(5):
        out = people.push(k / 30, [SimpleNamespace(id=i, keypoints=walks[i][k]) for i in range(2)])
        assert all(p.valid for _, p in out)
    assert calls == [1] * 10
    assert lm._symbolic_batch(SimpleNamespace(get_inputs=lambda: [SimpleNamespace(name=lm.INPUT_NAME,
                                                                                  shape=[1, 27, 17, 2])])) is False
    for batch in ("N", None, "batch"):
        stub = SimpleNamespace(get_inputs=lambda b=batch: [SimpleNamespace(name=lm.INPUT_NAME, shape=[b, 27, 17, 2])])
        assert lm._symbolic_batch(stub) is True


@pytest.mark.parametrize("camera", sorted(CAMERAS))
def test_normalised_is_image_to_canonical(camera):
    rng = np.random.default_rng(1603)
    canonical = CameraModel(**CANONICAL)
    maps = lm._PixelMaps(CAMERAS[camera], canonical, LifterParams())
    for case in range(500):
        kp = np.column_stack([rng.uniform(-300, 1600, 17), rng.uniform(-300, 1000, 17), rng.random(17)])
        kp[rng.random((17, 3)) < 0.05] = rng.choice([np.nan, np.inf, -np.inf, 0.0, -0.0])
        rows = rng.random(17) < 0.7 if case % 2 else np.ones(17, bool)
        want = image_to_canonical(kp[rows], CAMERAS[camera], canonical)
        assert same(maps.normalised(kp[rows]), want), case
        if rows.all():  # each row is mapped on its own: the rows of the whole equal the rows mapped alone
            part = rng.random(17) < 0.5
            assert same(maps.normalised(kp)[part],
                        image_to_canonical(kp[part], CAMERAS[camera], canonical)), case


def column_stacked_rays(keypoints, camera, canonical, keypoint_format, min_score):
    """rays.keypoint_rays before session 16 (np.column_stack, the NaN rows set afterwards)."""
    kp = np.asarray(keypoints, dtype=np.float64)
    out = np.full((N_JOINTS, 3), np.nan)
    if kp.ndim != 2 or kp.shape[0] != N_JOINTS or kp.shape[1] not in (2, 3):
        return out
    if kp.shape[1] == 2:
        kp = np.column_stack([kp, np.ones(N_JOINTS)])
    kp = to_h36m(kp, keypoint_format)
    seen = np.isfinite(kp[:, :2]).all(axis=1) & (kp[:, 2] >= min_score)
    if seen.any():
        xy = kp[seen, :2] if camera is None else camera.to_camera(kp[seen, :2], canonical)
        out[seen] = np.column_stack([(xy[:, 0] - canonical.cx_px) / canonical.fx_px,
                                     (xy[:, 1] - canonical.cy_px) / canonical.fy_px, np.ones(len(xy))])
        out[~np.isfinite(out).all(axis=1)] = np.nan
    return out


@pytest.mark.parametrize("camera", sorted(CAMERAS))
def test_keypoint_rays_are_the_old_rays(camera):
    from edge_runtime.robot.rays import keypoint_rays

    rng = np.random.default_rng(1604)
    canonical = CameraModel(**CANONICAL)
    for case in range(1500):
        fmt = "coco" if case % 2 else "h36m"
        kp = np.column_stack([rng.uniform(-300, 1600, 17), rng.uniform(-300, 1000, 17), rng.random(17)])
        kp[rng.random((17, 3)) < 0.06] = rng.choice([np.nan, np.inf, -np.inf, 0.0, -0.0, 1e300, -1e300])
        if case % 7 == 0:
            kp = kp[:, :2]
        elif case % 29 == 0:
            kp = kp[:11]
        want = column_stacked_rays(kp, CAMERAS[camera], canonical, fmt, 0.3)
        assert same(keypoint_rays(kp, CAMERAS[camera], canonical, fmt, 0.3), want), case


def test_finish_judges_each_output_as_the_old_one(assets):
    """A batch's outputs one non-finite, one too near the camera, the rest fine (one of them with a joint
    missing): each person's verdict and pose as his own old call's on the same output."""
    rng = np.random.default_rng(1605)
    params = LifterParams(precision="fp32")
    template = StreamingLifter.from_manifest(assets, params, camera=CAMERAS["wide"])
    reasons = set()
    for case in range(200):
        n = int(rng.integers(1, 6))
        new = [template.sibling() for _ in range(n)]
        old = [SessionSixteenLifter.from_manifest(assets, params, camera=CAMERAS["wide"]) for _ in range(n)]
        ready = []
        for a, b in zip(new, old):
            kp = random_walk_keypoints(rng, 1)[0]
            ready.append(a._prepare(0.0, kp))
            b.push(0.0, kp)
        pose = rng.normal(0, 0.3, (n, 1, 17, 3)).astype(np.float32)
        root = np.column_stack([rng.normal(0, 1, (n, 2)), rng.uniform(1, 8, n)]).astype(np.float32)[:, None]
        for i in range(n):
            r = rng.random()
            if r < 0.2:
                pose[i, 0, rng.integers(17), rng.integers(3)] = rng.choice([np.nan, np.inf])
            elif r < 0.4:
                pose[i, 0, rng.integers(17), 2] = 0.05 - root[i, 0, 2] + rng.choice([0.0, -1.0, 0.06])
            elif r < 0.5:
                # a joint missing: the model's own joint stands for it (the prepared flags may be the shared
                # read-only mask of no joint, core.skeleton.NO_JOINTS: a copy of them)
                missing = ready[i][3].copy()
                missing[rng.integers(17)] = True
                ready[i] = (*ready[i][:3], missing)
        got = lm._finish(new, ready, pose, root, 0.001)
        for i, (g, b) in enumerate(zip(got, old)):
            t_s, observed, held, missing = ready[i]
            assert_same_pose(g, b.old_finish(t_s, observed, held, missing, pose[i:i + 1], root[i:i + 1]), (case, i))
            reasons.add((g.reason or "valid")[:22] + ("+missing" if g.valid and missing.any() else ""))
    assert reasons == {"valid", "valid+missing", "model_output: non-fini", "model_output: a joint "}
