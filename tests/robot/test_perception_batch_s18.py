"""Session 18 (perfB): the perception stages' per-person numpy work made in one pass over everyone, pinned to
the per-person forms they replaced (session 17's, copied here) to the bit, on random inputs: the person
tracker (H36M conversion, match costs, sizes, following), the lifter's keypoint normalisation and the floor
anchoring (ankle rays and anchored joints of everyone in one matrix product)."""
import copy
import itertools
import math

import numpy as np
import pytest

from edge_runtime.core.numeric import median, median_floats, norms2
from edge_runtime.robot import calibration as cal
from edge_runtime.robot import keypoints as kpm
from edge_runtime.robot.keypoints import N_JOINTS, CameraModel, PeopleTrackParams, Person, PersonTracker


def same(a, b):
    """Equal to the bit (NaN where NaN, the sign of zero too)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return a.shape == b.shape and a.tobytes() == b.tobytes()


def random_coco(rng, n_people, two_columns=False, clean=False):
    """Keypoints as a detector sends them: some joints NaN, some scored low, now and then exact zeros; ``clean``:
    as the bench's simulated camera sends them, every joint there and scored 1 (the usual frame, session 23)."""
    kp = np.column_stack([rng.uniform(-50, 1400, (n_people * 17, 2)), rng.uniform(0, 1, n_people * 17)])
    kp = kp.reshape(n_people, 17, 3)
    if clean:
        kp[..., 2] = 1.0
        return kp[..., :2] if two_columns else kp
    kp[rng.random((n_people, 17, 3)) < rng.choice([0.0, 0.03, 0.2])] = np.nan
    if rng.random() < 0.2:
        kp[rng.random((n_people, 17, 3)) < 0.1] = 0.0
    return kp[..., :2] if two_columns else kp


# ------------------------------------------------------------------------ session 17's tracker, per person


class Session17Tracker(PersonTracker):
    """PersonTracker.update with session 17's per-detection conversion, cost and following."""

    def update(self, t_s, people):
        p = self.params
        for tid in [k for k, tr in self.tracks.items() if t_s - tr.t_s > p.max_lost_s or t_s < tr.t_s]:
            del self.tracks[tid]
        dets = []
        for person in people:
            kp = np.asarray(person.keypoints, float)
            if kp.shape not in ((N_JOINTS, 2), (N_JOINTS, 3)):
                self.rejected += 1
                continue
            kp = kpm.to_h36m(kp, self.keypoint_format)
            seen = kpm._seen(kp, p.min_score)
            if seen.sum() < p.min_joints:
                self.rejected += 1
                continue
            dets.append((person, kp, seen))
        costs = {}
        for tid, tr in self.tracks.items():
            for i, (_, kp, seen) in enumerate(dets):
                costs[tid, i] = self.old_cost(tr, kp, t_s, seen)
        assigned = kpm._assign(costs)
        out = []
        for i, (person, kp, seen) in enumerate(dets):
            tid = assigned.get(i)
            if tid is None:
                tid = next(self._ids)
                self.created += 1
                self.tracks[tid] = kpm._Track(tid, np.where(seen[:, None], kp[:, :2], np.nan),
                                              kpm._size_px(kp, p.min_score, seen), t_s)
            else:
                self.old_follow(self.tracks[tid], kp, t_s, seen)
            out.append(Person(person.keypoints, tid, person.id))
        return out

    def old_cost(self, tr, kp, t_s, seen):
        p = self.params
        if len(tr.xy) != len(kp):
            return math.inf
        pred = tr.predicted(t_s, p.max_predict_s)
        both = seen & np.isfinite(pred).all(axis=1)
        if both.sum() < 2:
            return math.inf
        d = float(median(norms2(kp[both, :2] - pred[both]))) / tr.size_px
        gate = p.gate + p.gate_growth_per_s * max(t_s - tr.t_s, 0.0)
        return d / gate if d <= gate else math.inf

    def old_follow(self, tr, kp, t_s, seen):
        p = self.params
        dt = t_s - tr.t_s
        both = seen & np.isfinite(tr.xy).all(axis=1)
        if dt > 0 and both.any():
            step = kp[both, :2] - tr.xy[both]
            v = step.sum(axis=0) / len(step) / dt
            a = p.velocity_smoothing
            tr.velocity_pxps = a * v + (1 - a) * tr.velocity_pxps
        moved = tr.xy + tr.velocity_pxps * max(dt, 0.0)
        tr.xy = np.where(seen[:, None], kp[:, :2], moved)
        tr.size_px = kpm._size_px(kp, p.min_score, seen)
        tr.t_s = t_s


def walkers(rng, n_frames, clean=False):
    """Frames of 0-5 walkers (and now and then a wrong-shaped or near-empty detection), with dropped frames
    and time jumps longer than a track is kept; ``clean``: every walker's keypoints :func:`random_coco`'s clean ones."""
    t = 0.0
    base = rng.uniform(0, 1200, (6, 2))
    velocity = rng.normal(0, 8, (6, 2))
    for k in range(n_frames):
        t += float(rng.choice([1 / 30, 1 / 30, 1 / 30, 2 / 30, 0.7, 3.5])) if k else 0.0
        people = []
        for w in rng.permutation(int(rng.integers(0, 6))):
            kp = random_coco(rng, 1, two_columns=rng.random() < 0.1, clean=clean)[0]
            kp[:, :2] = base[w] + velocity[w] * k + rng.normal(0, rng.choice([2.0, 30.0]), (17, 2)) \
                + rng.uniform(-60, 60, (17, 2))
            people.append(Person(kp, int(w)))
        if rng.random() < 0.05:
            people.append(Person(np.ones((12, 3))))
        if rng.random() < 0.05:
            lone = np.full((17, 3), np.nan)
            lone[:3] = 1.0
            people.append(Person(lone))
        yield t, people


@pytest.mark.parametrize("fmt, clean", [("coco", False), ("h36m", False), ("coco", True), ("h36m", True)])
def test_tracker_is_session17s(fmt, clean):
    """``clean``: the usual frame, every keypoint there and seen (the tracker's all-seen passes and its
    assignment without the search, session 23)."""
    rng = np.random.default_rng(1801 + (fmt == "h36m") + 2 * clean)
    for params in (PeopleTrackParams(), PeopleTrackParams(min_joints=3, gate=2.0, gate_growth_per_s=0.0)):
        new, old = PersonTracker(params, fmt), Session17Tracker(params, fmt)
        for t, people in walkers(rng, 400, clean):
            a, b = new.update(t, copy.deepcopy(people)), old.update(t, copy.deepcopy(people))
            assert [(x.id, x.source_id) for x in a] == [(x.id, x.source_id) for x in b]
            assert list(new.tracks) == list(old.tracks)
            for tid in old.tracks:
                for f in ("xy", "velocity_pxps", "size_px", "t_s"):
                    assert same(getattr(new.tracks[tid], f), getattr(old.tracks[tid], f)), (t, tid, f)
        assert (new.created, new.rejected) == (old.created, old.rejected)
        assert old.created > 20 and (clean or old.rejected > 10)


@pytest.mark.parametrize("clean", [False, True])
def test_follow_all_is_one_by_one(clean):
    """Several tracks followed at once, each as when followed alone (times that go back, joints never seen);
    ``clean``: every joint seen now (session 23's pass for it)."""
    rng = np.random.default_rng(1803 + 100 * clean)
    tracker = Session17Tracker(keypoint_format="h36m")
    for case in range(500):
        m = int(rng.integers(1, 5))
        kps = random_coco(rng, m, clean=clean)
        seen = kpm._seen(kps, 0.3)
        t1 = float(rng.uniform(0, 10))
        tracks = []
        for _ in range(m):
            xy = rng.uniform(0, 1000, (17, 2))
            xy[rng.random(17) < 0.3] = np.nan
            t0 = t1 - float(rng.choice([0.0, 1 / 30, -0.01, rng.uniform(0, 2)]))
            tracks.append(kpm._Track(0, xy, 100.0, t0, rng.normal(0, 30, 2) * rng.choice([0.0, 1.0])))
        mine = copy.deepcopy(tracks)
        sizes = [kpm._size_px(kp, 0.3, s) if s.any() else 1.0 for kp, s in zip(kps, seen)]
        tracker._follow_all(mine, kps, seen, sizes, t1)
        for tr, kp, s, size, got in zip(tracks, kps, seen, sizes, mine):
            assert got.size_px == size
            if not s.any():
                continue
            tracker.old_follow(tr, kp, t1, s)
            for f in ("xy", "velocity_pxps", "t_s"):
                assert same(getattr(got, f), getattr(tr, f)), (case, f)


def test_to_h36m_each_is_one_by_one():
    rng = np.random.default_rng(1804)
    for case in range(1500):
        kps = list(random_coco(rng, int(rng.integers(1, 6)), two_columns=case % 7 == 0))
        kpm._H36M_MEMO.clear()
        together = kpm.to_h36m_each(kps, "coco")
        remembered = [kpm.coco_to_h36m(kp) for kp in kps]  # from the memo, as the lifter gets them
        kpm._H36M_MEMO.clear()
        for kp, t, r in zip(kps, together, remembered):
            alone = kpm.coco_to_h36m(kp)
            assert same(t, alone) and same(r, alone), case
        assert same(kpm.to_h36m_each(kps, "h36m"), np.stack([kpm.as_keypoints(kp) for kp in kps]))
    assert kpm.to_h36m_each([], "coco").shape == (0, 17, 3)
    with pytest.raises(ValueError):
        kpm.to_h36m_each(kps, "openpose")


@pytest.mark.parametrize("clean", [False, True])
def test_sizes_px_is_size_px(clean):
    rng = np.random.default_rng(1805 + 100 * clean)
    for case in range(1000):
        kps = kpm.to_h36m_each(list(random_coco(rng, int(rng.integers(1, 6)), clean=clean)), "coco")
        if case % 5 == 0:
            kps[..., :2] *= rng.choice([1e-3, 1e3])
        seen = kpm._seen(kps, 0.3)
        keep = seen.any(axis=1)
        kps, seen = kps[keep], seen[keep]
        got = kpm._sizes_px(kps, seen, 0.3)
        for kp, s, g in zip(kps, seen, got):
            assert type(g) is float and same(g, kpm._size_px(kp, 0.3, s)), case


# ------------------------------------------------------------------------ the lifter's normalisation


def test_canonical_normalisation_is_image_to_canonical():
    from edge_runtime.robot.lifter import LifterParams, _PixelMaps

    rng = np.random.default_rng(1806)
    canonical = CameraModel.from_fov(1000, 1002, 80.0)
    for camera in (None, CameraModel.from_fov(1000, 1002, 80.0), CameraModel.from_fov(1920, 1080, 90.0)):
        maps = _PixelMaps(camera, canonical, LifterParams())
        assert maps.canonical_pixels == (camera is None or camera.same_pixels_as(canonical))
        for _ in range(300):
            kp = random_coco(rng, 1)[0]
            n = int(rng.integers(1, 18))
            for rows in (kp, kp[:n]):
                assert same(maps.normalised(rows), kpm.image_to_canonical(rows, camera, canonical))


# ------------------------------------------------------------------------ the floor anchoring


def session17_anchor_call(self, joints_cam_m, observed=None, ids=None):
    """FloorAnchor.__call__ as session 17 left it (one skeleton after the other; its matching, unchanged since,
    now FloorAnchor._match)."""
    c, p = self.calibration, self.calibration.params
    window = max(1, int(c.anchor_window_frames))
    flat = np.asarray(joints_cam_m, float).reshape(-1, 17, 3)
    seen = [None] * len(flat) if observed is None else np.asarray(observed, bool).reshape(-1, 17)
    out, todo, matched = self._match(flat, ids, window)  # unchanged in session 18
    for i in todo:
        k, reason = cal.anchor_factor(flat[i], c.A, c.b, p, seen[i])
        t = matched.get(i)
        if t is None:
            t = cal._AnchorTrack(cal.deque(maxlen=window), k, np.full(3, np.nan), None if ids is None else ids[i])
            self.tracks.append(t)
        if reason is None and p.anchor_min_scale < k < p.anchor_max_scale:
            t.factors.append(k)
        t.k = median_floats(t.factors) if t.factors else k
        out[i] = c.apply(t.k * flat[i])
        if np.isfinite(out[i][cal.HIP]).all():
            t.root_m = out[i][cal.HIP]
        t.last_in, t.last_out = flat[i].copy(), out[i].copy()
    return out


def _calibration(rng):
    """A camera 2-3 m above the robot's base, looking down 20-40 degrees (robot frame: y up)."""
    tilt, pan = math.radians(rng.uniform(20, 40)), rng.uniform(-0.5, 0.5)
    A = np.array([[1, 0, 0], [0, -math.cos(tilt), -math.sin(tilt)], [0, -math.sin(tilt), math.cos(tilt)]])
    A = np.array([[math.cos(pan), 0, math.sin(pan)], [0, 1, 0], [-math.sin(pan), 0, math.cos(pan)]]) @ A
    return cal.Calibration(A=A, b=np.array([0.3, rng.uniform(2.0, 3.0), -1.0]), method="test",
                           worker_height_m=1.75, head_cam_m=np.zeros((3, 3)), ankle_cam_m=np.zeros((3, 3)))


def _bodies_cam(rng, c, n):
    """``n`` standing people 3-6 m in front of the camera (camera frame), their depths off by up to 20 %."""
    floor = c.params.floor_y_m
    robot = np.empty((n, 17, 3))
    robot[..., 1] = floor + rng.uniform(0.1, 1.75, (n, 17))
    robot[:, [cal.L_ANKLE, cal.R_ANKLE], 1] = floor + c.params.ankle_height_m + rng.uniform(0, 0.15, (n, 2))
    robot[..., 0] = rng.uniform(-2, 2, (n, 1)) + rng.normal(0, 0.2, (n, 17))
    robot[..., 2] = rng.uniform(2, 5, (n, 1)) + rng.normal(0, 0.1, (n, 17))
    cam = (robot - c.b) @ np.linalg.inv(c.A).T
    return cam * rng.uniform(0.8, 1.2, (n, 1, 1))


@pytest.mark.parametrize("with_ids", [False, True])
def test_floor_anchor_is_session17s(with_ids):
    rng = np.random.default_rng(1807 + with_ids)
    factors = 0
    for _ in range(20):
        c = _calibration(rng)
        new, old = cal.FloorAnchor(c), cal.FloorAnchor(c)
        bodies = _bodies_cam(rng, c, 5)
        last = None
        for k in range(60):
            people = rng.permutation(5)[:int(rng.integers(0, 5))]
            joints = bodies[people] * rng.uniform(0.97, 1.03) + rng.normal(0, 0.01, (len(people), 17, 3))
            joints[rng.random(joints.shape) < 0.02] = np.nan
            if last is not None and rng.random() < 0.2:
                joints = last  # the same frame given again
            last = joints
            observed = rng.random((len(joints), 17)) < 0.9
            ids = [int(p) for p in people][:len(joints)] if with_ids else None
            if with_ids and len(ids) != len(joints):
                ids = list(range(len(joints)))
            a = new(joints, observed, ids)
            b = session17_anchor_call(old, joints, observed, ids)
            assert same(a, b), k
            assert len(new.tracks) == len(old.tracks)
            for s, t in zip(new.tracks, old.tracks):
                assert s.k == t.k and list(s.factors) == list(t.factors) and same(s.root_m, t.root_m)
                assert same(s.last_in, t.last_in) and same(s.last_out, t.last_out)
                factors += len(t.factors)
    assert factors > 500  # the anchoring applied (not only refused)


def test_stacked_products_are_each_ones():
    """What the anchoring's one product relies on: numpy's matmul of a stack of skeletons multiplies each as
    it multiplies one alone."""
    rng = np.random.default_rng(1809)
    for n in itertools.chain(range(1, 7), [12]):
        A = rng.normal(size=(3, 3))
        j = rng.normal(size=(n, 17, 3)) * rng.uniform(0.1, 10)
        k = rng.uniform(0.5, 2, n)
        stacked = (k[:, None, None] * j) @ A.T
        rays = j[:, cal._ANKLES] @ A.T
        for i in range(n):
            assert same(stacked[i], (float(k[i]) * j[i]) @ A.T)
            assert same(rays[i], j[i][cal._ANKLES] @ A.T)


def test_usable_all_is_each_ones():
    """The lifter's usable joints and normalised keypoints of everyone in a frame, made in one pass, are each
    person's own (StreamingLifter._usable), and people whose keypoints are not (17, 2|3) are left to their own
    lifter."""
    from types import SimpleNamespace

    from edge_runtime.robot.lifter import LifterParams, StreamingLifter, _PixelMaps, _usable_all

    rng = np.random.default_rng(1810)
    nobody = 0
    canonical = CameraModel.from_fov(1280, 720, 100.0)
    for camera in (None, canonical, CameraModel.from_fov(1920, 1080, 90.0)):
        for fmt in ("coco", "h36m"):
            params = LifterParams(min_score=float(rng.choice([0.0, 0.3])))
            maps = _PixelMaps(camera, canonical, params)
            stub = SimpleNamespace(keypoint_format=fmt, params=params, _pixel_maps=lambda maps=maps: maps)
            for case in range(200):
                # a third of the frames clean, as the bench's: every keypoint usable (session 23's pass for it)
                people = list(random_coco(rng, int(rng.integers(1, 5)), two_columns=case % 9 == 0, clean=case % 3 == 1))
                if case % 4 == 0:
                    people[0][:, :2] *= rng.choice([10.0, 1e4])  # beyond MAX_NORMALISED
                if case % 5 == 0 and people[-1].shape[1] == 3:
                    people[-1][:, 2] = -1.0  # nobody's joint usable
                if case % 6 == 0:
                    people.insert(int(rng.integers(0, len(people))), None if case % 12 else np.ones((12, 3)))
                got = _usable_all(stub, people)
                assert len(got) == len(people)
                batched = maps.canonical_pixels and sum(k is not None and np.shape(k)[0] == 17 for k in people) > 1
                for kp, g in zip(people, got):
                    if kp is None or np.shape(kp)[0] != 17 or not batched:
                        assert g is None
                        continue
                    ok, norm = StreamingLifter._usable(stub, np.asarray(kp, float))
                    assert np.array_equal(g[0], ok) and g[0].dtype == bool
                    assert (g[1] is None) == (norm is None)
                    if norm is not None:
                        assert same(g[1], norm), case
                    nobody += norm is None
    assert nobody > 50
