"""Session 24 (react24): the robot frame's cheaper forms pinned to what they replaced, to the bit, on random inputs:
the monitor's pass that also measures where a retraction began, the escape plan's separations taken from the
monitor, the single base rotation, the least of a few floats, frozen dataclasses made directly, a vector's norm, the
tracker's usual-frame shortcuts and the lifter's shared masks. (The whole runtime's decisions:
tests/robot/test_golden_trace_s24.py.)"""
import dataclasses
import math

import numpy as np
import pytest
from robot.test_frame_cost_s16 import same
from robot.test_hazard_vectorised import random_person

from edge_runtime.core.skeleton import ALL_JOINTS, NO_JOINTS
from edge_runtime.robot import hazard as hz
from edge_runtime.robot import keypoints as kpm

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")  # inf - inf and the like, in old and new alike


def test_the_joined_pass_is_each_sets_own_pass():
    """One pass over two capsule sets gives each set's clearances, to the bit, and with no second set the one."""
    rng = np.random.default_rng(2401)
    for case in range(300):
        caps, other = hz.arm_capsules(rng.uniform(-3, 3, 7)), hz.arm_capsules(rng.uniform(-3, 3, 7))
        pts = rng.normal(0.0, rng.choice([0.2, 1.0, 3.0]), (int(rng.choice([1, 25, 100, 400])), 3))
        if case % 7 == 0:
            pts[rng.random(len(pts)) < 0.2] = np.nan
        a, b = hz.point_clearances_m(pts, caps, other)
        assert same(a, hz.point_clearance_m(pts, caps)) and same(b, hz.point_clearance_m(pts, other)), case
        alone, none = hz.point_clearances_m(pts, caps)
        assert same(alone, hz.point_clearance_m(pts, caps)) and none is None


def test_separations_with_another_posture_are_each_ones_own():
    """Everyone now and ahead from the frame's arm, and now from another posture, in one pass: the first as
    separations_per_shift_m gives them, the second as people_separations_m of the unmoved spheres, both paths
    (whole skeletons stacked, and bodies of other sizes)."""
    rng = np.random.default_rng(2402)
    for case in range(200):
        caps, other = hz.arm_capsules(rng.uniform(-3, 3, 7)), hz.arm_capsules(rng.uniform(-3, 3, 7))
        people = [hz.body_spheres(random_person(rng)) for _ in range(int(rng.integers(1, 4)))]
        if case % 3 == 0:
            people.append(hz.body_spheres(rng.normal(0, 1, 3)))  # a lone head: another size
        bodies = [(c, r, tuple(rng.normal(0, 1.5, 3))) for c, r in people]
        seps, also = hz._separations_m(bodies, (0.0, 0.5), caps, other)
        for got, want in zip(seps, hz.separations_per_shift_m(bodies, (0.0, 0.5), caps)):
            assert same(got, want), case
        assert same(also, hz.people_separations_m(people, other)), case
        assert hz._separations_m(bodies, (0.0, 0.5), caps)[1] is None


def test_the_monitor_serves_the_start_postures_separations_it_measured():
    """observe(..., also_capsules=...) decides as observe without them, and people_separations_m of those capsules
    is then every kept body's measured separation (no pass of its own), the same numbers as a pass."""
    rng = np.random.default_rng(2403)
    with_start, without = hz.HazardMonitor(), hz.HazardMonitor()
    served = 0
    for k in range(300):
        q, q0 = rng.uniform(-2, 2, 7), rng.uniform(-2, 2, 7)
        start = hz.arm_capsules(q0)
        people = {w: random_person(rng) for w in range(3) if rng.random() < 0.8}
        eff = rng.normal(0, 0.5, 3)
        d1 = with_start.observe(k / 30, people, eff, q, also_capsules=start)
        d0 = without.observe(k / 30, people, eff, q)
        assert (d1.state, d1.reason, d1.distance_m, d1.worker, d1.speed_scale, d1.coming) == \
               (d0.state, d0.reason, d0.distance_m, d0.worker, d0.speed_scale, d0.coming), k
        spheres = with_start.people_spheres()
        if spheres:
            assert same(with_start.people_separations_m(start), hz.people_separations_m(spheres, start)), k
            served += all(s.known_separation_m(start) is not None for s in with_start._seen.values())
    assert 30 < served < 300  # frames whose every body was measured so, and frames with someone lost


def test_the_escape_plans_separations_now_are_the_monitors():
    """escape_separations_m is what the plan measures of escape_people itself, to the bit, so the plan given it
    turns the same way; None while someone is lost (his reach grown since)."""
    rng = np.random.default_rng(2404)
    mon = hz.HazardMonitor()
    given = 0
    for k in range(200):
        q = rng.uniform(-2, 2, 7)
        caps = hz.arm_capsules(q)
        people = {w: random_person(rng) for w in range(3) if rng.random() < 0.8}
        mon.observe(k / 30, people, rng.normal(0, 0.5, 3), q)
        escaping = mon.escape_people(sweep_m=0.5)
        here = mon.escape_separations_m(caps)
        if not escaping:
            continue
        centres, radii, starts = hz._gathered(escaping)
        measured = np.minimum.reduceat(hz.point_clearance_m(centres, caps) - radii, starts)
        if here is None:
            assert any(s.t_s != mon._last_pose_s for s in mon._seen.values()), k
            continue
        given += 1
        assert same(here, measured), k
        args = (caps, escaping, float(q[0]), 5.0, 0.05, 0.02, 180.0, 0.85)
        assert hz.plan_escape_turn(*args, here=here) == hz.plan_escape_turn(*args), k
    assert given > 50


def test_one_base_rotation_is_the_stacked_ones():
    rng = np.random.default_rng(2405)
    for t in [0.0, -0.0, math.pi, -math.pi, 1e-300, 1e6, *rng.uniform(-10, 10, 500)]:
        assert same(hz._base_rotation(t), hz._base_rotations([t])[0]), t
        eff = rng.normal(0, 1, 3)
        assert same(hz.turned_retraction(eff, 0.3, t).position_m, hz._base_rotations([t])[0] @ eff), t


def test_the_least_of_a_few_floats_is_numpys_min():
    rng = np.random.default_rng(2406)
    pool = [0.0, 1.0, -1.0, math.inf, -math.inf, math.nan, 1e-300, 2.5]
    for _ in range(3000):
        values = [float(rng.choice(pool)) if rng.random() < 0.5 else float(rng.normal()) for _ in range(rng.integers(1, 5))]
        assert same(hz._least(values), float(np.min(values))), values


def test_frozen_values_made_directly_are_the_constructed_ones():
    v = np.arange(3.0)
    for cls, fields in ((hz.HeadEstimate, dict(t_s=1.0, position_m=v, velocity_mps=v + 1, predicted_m=v + 2)),
                        (hz._Seen, dict(t_s=1.0, person_m=v, speed_mps=0.5, spheres=(v, v), clear_of=None,
                                        also_clear_of=((v,), 0.2)))):
        made, built = hz._frozen_new(cls, **fields), cls(**fields)
        assert type(made) is cls and vars(made).keys() == vars(built).keys()
        assert all(getattr(made, f.name) is getattr(built, f.name) for f in dataclasses.fields(cls))
        with pytest.raises(dataclasses.FrozenInstanceError):
            made.t_s = 2.0


def test_a_vectors_norm_is_numpys():
    rng = np.random.default_rng(2407)
    for _ in range(3000):
        v = rng.normal(0, 1, int(rng.integers(1, 4))) * rng.choice([1e-200, 1e-3, 1.0, 1e200])
        assert same(hz.vector_norm(v), float(np.linalg.norm(v))), v
    assert same(hz.vector_norm([3, 4]), 5.0)


def tracks_and_detections(rng, n_tracks: int, n_dets: int):
    """Tracks with every joint known and detections with every joint seen (the usual frame), and the detections'
    (D, 17) seen mask."""
    tracks = []
    for tid in range(n_tracks):
        xy = rng.uniform(0, 1280, (17, 2))
        tracks.append(kpm._Track(tid, xy, float(rng.uniform(50, 400)), float(rng.uniform(-0.2, 0.0)),
                                 rng.normal(0, 30, 2)))
    kps = np.concatenate([rng.uniform(0, 1280, (n_dets, 17, 2)), np.ones((n_dets, 17, 1))], axis=-1)
    if n_tracks and n_dets:
        kps[0, :, :2] = tracks[0].xy + rng.normal(0, 2, (17, 2))  # one of them near a track
    return tracks, kps, np.ones((n_dets, 17), bool)


def test_the_trackers_usual_frame_shortcuts_are_its_general_forms():
    """Pair costs and following with every joint seen (``all_seen``) are the general forms' numbers, to the bit;
    a track whose keypoints are not all known, or a prediction not finite, takes the general way."""
    rng = np.random.default_rng(2408)
    p = kpm.PeopleTrackParams()
    for case in range(400):
        tracks, kps, seen = tracks_and_detections(rng, int(rng.integers(1, 4)), int(rng.integers(1, 4)))
        if case % 5 == 0:
            tracks[-1].xy[rng.integers(17)] = np.nan
        if case % 11 == 0:
            tracks[0].velocity_pxps = np.array([np.inf, 0.0])
        t_s = float(rng.choice([0.0, 1 / 30, 2.0]))
        items = list(enumerate(tracks))
        assert kpm._pair_costs(items, kps, seen, t_s, p, True) == kpm._pair_costs(items, kps, seen, t_s, p), case
        tracker = kpm.PersonTracker(p)
        fast = [dataclasses.replace(tr, xy=tr.xy.copy()) for tr in tracks[:len(kps)]]
        slow = [dataclasses.replace(tr, xy=tr.xy.copy()) for tr in tracks[:len(kps)]]
        sizes = [100.0] * len(fast)
        tracker._follow_all(fast, kps[:len(fast)], seen[:len(fast)], sizes, t_s, True)
        tracker._follow_all(slow, kps[:len(slow)], seen[:len(slow)], sizes, t_s)
        for a, b in zip(fast, slow):
            assert same(a.xy, b.xy) and same(a.velocity_pxps, b.velocity_pxps) and a.t_s == b.t_s, case


def test_the_shared_masks_are_read_only():
    assert not NO_JOINTS.any() and ALL_JOINTS.all() and NO_JOINTS.shape == ALL_JOINTS.shape == (17,)
    for mask in (NO_JOINTS, ALL_JOINTS):
        with pytest.raises(ValueError):
            mask[0] = not mask[0]
