"""Session 16's per-frame CPU cuts (edge_runtime.robot.hazard, keypoints, loop) pinned to the forms they replaced:
the same floating-point results to the bit on random and edge inputs (NaN, +-inf, +-0), so no decision changes;
and the frame's log is made after its commands are on the link, from what the frame was judged with."""
import math
from collections import deque
from dataclasses import replace

import numpy as np
import pytest
from robot.test_hazard_vectorised import random_capsules, random_person, textbook_plan
from support.robot import FakeLink, anchored_worker

from edge_runtime.robot import hazard as hz
from edge_runtime.robot import keypoints as kpm
from edge_runtime.robot.hazard import HeadTracker, TrackerParams, ZoneParams
from edge_runtime.robot.loop import LoopParams, RobotLoop

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")  # inf - inf and the like, in old and new alike
EDGE = (np.nan, np.inf, -np.inf, 0.0, -0.0, 1e300, -1e-300)


def same(a, b):
    """Equal to the bit (NaN where NaN, the sign of zero too), shape and dtype included."""
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()


def same_or_nan(a, b):
    """Equal to the bit except a NaN's payload (NaN where NaN; which NaN a min of several returns is numpy's)."""
    a, b = np.asarray(a), np.asarray(b)
    nan = np.isnan(a)
    return same(nan, np.isnan(b)) and same(np.where(nan, 0.0, a), np.where(nan, 0.0, b))


def with_edges(rng, a, share=0.05):
    a = np.array(a, float)
    hit = rng.random(a.shape) < share
    a[hit] = rng.choice(EDGE, int(hit.sum()))
    return a


def session15_clearance(points_m, capsules):
    """point_clearance_m as session 15 left it: (N, K) arrays, the capsules along the rows."""
    p = np.asarray(points_m, float)
    a, b, r = capsules
    ab = b - a
    den = np.maximum((ab * ab).sum(-1), 1e-12)
    ap = [p[:, i][:, None] - a[:, i] for i in range(3)]
    t = ap[0] * ab[:, 0]
    t += ap[1] * ab[:, 1]
    t += ap[2] * ab[:, 2]
    t /= den
    np.clip(t, 0.0, 1.0, out=t)
    d = [ap[i] - t * ab[:, i] for i in range(3)]
    s = d[0] * d[0]
    s += d[1] * d[1]
    s += d[2] * d[2]
    return (np.sqrt(s) - r).min(axis=1)


def test_point_clearance_is_session_15s_on_random_and_edge_inputs():
    rng = np.random.default_rng(1601)
    for case in range(600):
        caps = random_capsules(rng)
        if case % 5 == 0:  # degenerate capsules: a point (zero length), radius 0
            a, b, r = (np.array(v) for v in caps)
            b[0], r[0] = a[0], 0.0
            caps = (a, b, r)
        n = int(rng.choice([1, 2, 25, 50, 400, 1800]))
        pts = rng.normal(0.0, rng.choice([0.3, 1.0, 3.0]), (n, 3))
        if case % 3 == 0:
            pts = with_edges(rng, pts)
        got, want = hz.point_clearance_m(pts, caps), session15_clearance(pts, caps)
        assert same_or_nan(got, want), case
        if not np.isnan(want).any():
            assert same(got, want), case


def test_capsule_terms_are_remembered_for_read_only_capsules_only():
    rng = np.random.default_rng(1602)
    q = rng.uniform(-2, 2, 7)
    caps = hz.arm_capsules(q)
    assert hz._capsule_terms(caps, 1) is hz._capsule_terms(hz.arm_capsules(q.copy()), 1)
    a, b, r = (np.array(v) for v in caps)  # writeable: changed in place, the next call sees the change
    pts = rng.normal(0, 1, (30, 3))
    before = hz.point_clearance_m(pts, (a, b, r))
    a += 0.3
    assert same(hz.point_clearance_m(pts, (a, b, r)), session15_clearance(pts, (a, b, r)))
    assert not same(hz.point_clearance_m(pts, (a, b, r)), before)


def test_separations_per_shift_are_session_15s_with_edge_velocities():
    rng = np.random.default_rng(1603)
    for case in range(300):
        caps = random_capsules(rng)
        centres, radii = hz.body_spheres(random_person(rng))
        v = with_edges(rng, [rng.normal(0, 1.0), 0.0, rng.normal(0, 1.0)], 0.2)
        shifts = (0.0, 0.5) if case % 4 else (0.0, -0.0, 0.25, 1e-9)
        moved = (centres[None] + np.asarray(shifts)[:, None, None] * v[None, None]).reshape(-1, 3)
        want = (session15_clearance(moved, caps) - np.tile(radii, len(shifts))).reshape(len(shifts), -1).min(axis=1)
        assert same_or_nan(hz.separation_per_shift_m(centres, radii, v, shifts, caps), want), case
        # several people in one call: each gets what he gets alone
        others = [(*hz.body_spheres(random_person(rng)), rng.normal(0, 1, 3)) for _ in range(int(rng.integers(0, 3)))]
        together = hz.separations_per_shift_m([*others, (centres, radii, v)], shifts, caps)
        assert same_or_nan(together[-1], want), case
        for (c, r, u), got in zip(others, together):
            assert same(got, hz.separation_per_shift_m(c, r, u, shifts, caps)), case


def test_the_escape_plan_is_the_textbook_one_with_odd_people():
    # people partly NaN (a joint not known), infinitely grown (lost long ago), at the base's axis, or one sphere
    rng = np.random.default_rng(1604)
    for case in range(60):
        q = rng.uniform(-2.9, 2.9, 7)
        caps = hz.arm_capsules(q)
        people = []
        for _ in range(int(rng.integers(1, 4))):
            c, r = hz.body_spheres(random_person(rng))
            c, r = c.copy(), r.copy()
            kind = rng.integers(5)
            if kind == 0:
                c[rng.integers(len(c))] = np.nan
            elif kind == 1:
                r = r + np.inf
            elif kind == 2:
                c[:, [0, 2]] = rng.choice([0.0, -0.0])
            elif kind == 3:
                c, r = c[:1], r[:1]
            people.append((c, r))
        args = (float(q[0]) if case % 3 else None, float(rng.choice([2.0, 5.0])), 0.05, 0.02,
                float(rng.choice([30.0, 180.0])), float(rng.choice([0.85, math.inf])))
        assert hz.plan_escape_turn(caps, people, *args) == textbook_plan(caps, people, *args), case


def session15_arm_points(q_rad):
    q = np.asarray(q_rad, float).reshape(7)
    t, pts = np.eye(4), [np.zeros(3)]
    for k, origin in enumerate(hz._ORIGIN_TRANSFORMS):
        t = t @ origin
        if k < 7:
            c, s = math.cos(q[k]), math.sin(q[k])
            t = t @ np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])
        pts.append(t[:3, 3].copy())
    pts.append(t[:3, 3] + hz.TOOL_LENGTH_M * t[:3, 2])
    return np.asarray(pts) @ hz._URDF_TO_ROBOT.T


def test_arm_points_are_session_15s():
    rng = np.random.default_rng(1605)
    for case in range(2000):
        q = rng.uniform(-3.2, 3.2, 7) * rng.choice([1e-8, 1.0, 100.0])
        if case % 4 == 0:
            q = with_edges(rng, q, 0.2)
        if np.isinf(q).any():  # math.cos(inf): a ValueError from both
            for f in (hz.arm_points_m, session15_arm_points):
                with pytest.raises(ValueError):
                    f(q)
            continue
        assert same_or_nan(hz.arm_points_m(q), session15_arm_points(q)), case
        if np.isfinite(q).all():
            assert same(hz.arm_points_m(q), session15_arm_points(q)), case


def session15_fit(ts, xs, t_s, p: TrackerParams, predict_s: float):
    """HeadTracker's estimate as session 15 left it (np.stack, the means taken twice, np.linalg.norm)."""
    if len(ts) < p.min_samples:
        return xs[-1], np.zeros(3)
    t = np.fromiter(ts, float) - t_s
    x = np.stack(xs)
    tc = t - t.mean()
    vel = tc @ (x - x.mean(axis=0)) / float(tc @ tc)
    pos = x.mean(axis=0) - t.mean() * vel
    speed = float(np.linalg.norm(vel))
    return pos, vel * (p.max_speed_mps / speed) if speed > p.max_speed_mps else vel


def test_the_head_fit_is_session_15s():
    rng = np.random.default_rng(1606)
    for case in range(400):
        p = TrackerParams(window_s=float(rng.choice([0.2, 0.5, 1.0])), min_samples=int(rng.integers(2, 5)),
                          min_span_s=0.0)  # session 15's fit had no span to wait for
        tracker, ts, xs = HeadTracker(p, 0.5), deque(), deque()
        t, head = float(rng.uniform(0, 100)), rng.normal(0, 2, 3)
        for _ in range(int(rng.integers(1, 40))):
            t += float(rng.choice([1 / 30, 1 / 30, 0.1, 0.0, 0.7]))
            head = head + rng.normal(0, rng.choice([0.01, 0.1, 2.0]), 3)
            seen = with_edges(rng, head, 0.03) if case % 3 == 0 else head
            est = tracker.update(t, seen)
            # the reference keeps the same window (its reset and trim are unchanged): fit it the old way
            ts, xs = deque(tracker._t), deque(tracker._x)
            pos, vel = session15_fit(ts, xs, t, p, 0.5)
            assert same_or_nan(est.position_m, pos) and same_or_nan(est.velocity_mps, vel), case
            assert same_or_nan(est.predicted_m, pos + 0.5 * vel), case


def session15_jumped(tracker: HeadTracker, t_s: float, head) -> bool:
    dt = t_s - tracker._t[-1]
    return bool(np.linalg.norm(np.asarray(head, float) - tracker._x[-1]) > tracker.p.jump_m + tracker.p.max_speed_mps * dt)


def test_the_head_trackers_jump_test_is_session_15s():
    rng = np.random.default_rng(1607)
    for case in range(2000):
        tracker = HeadTracker(TrackerParams(window_s=10.0))
        tracker.update(0.0, rng.normal(0, 1, 3))
        head = with_edges(rng, rng.normal(0, rng.choice([0.1, 1.0, 3.0]), 3), 0.1)
        dt = float(rng.choice([1 / 30, 0.3]))
        jumped = session15_jumped(tracker, dt, head)
        tracker.update(dt, head)
        assert (tracker.resets == 1) == jumped, case


def test_the_tracker_hands_out_people_as_dataclasses_replace_did():
    rng = np.random.default_rng(1608)
    tracker = kpm.PersonTracker()
    for k in range(60):
        people = [kpm.Person(np.column_stack([rng.uniform(0, 60, (17, 2)) + (300 * w + 3 * k, 200),
                                              rng.uniform(0.5, 1, 17)]), id=int(rng.choice([7, 8])))
                  for w in range(2)]
        out = tracker.update(k / 30, people)
        for person, got in zip(people, out):
            want = replace(person, id=got.id, source_id=person.id)
            assert type(got) is kpm.Person and got == want and got.keypoints is person.keypoints


def test_the_frames_log_is_made_after_its_commands_from_what_it_was_judged_with(monkeypatch):
    """FrameRecord.people comes after the frame's link calls (since session 18 when it is first read, once),
    measured from the effector the frame was judged with: before any state from the arm, the loop's fallback (its
    last commanded position) is the one before the frame's own command, as it was when the log was made first."""
    from edge_runtime.core.skeleton import HEAD

    order, judged = [], []
    link = FakeLink()
    link._state = replace(link._state, ee_position_m=np.full(3, np.nan))  # no effector: the loop's fallback
    for name in ("move_to", "retract", "stop", "set_alarm", "set_speed", "resume"):
        call = getattr(link, name)
        monkeypatch.setattr(link, name, lambda *a, _call=call, _name=name, **k: (order.append(_name), _call(*a, **k))[1])
    clock = [0.0]
    loop = RobotLoop(link, zones=ZoneParams(), params=LoopParams(task_waypoints_m=((0.5, 0.14, 0.5), (-0.5, 0.14, 0.5))),
                     clock=lambda: clock[0])
    people = loop._people
    monkeypatch.setattr(loop, "_people", lambda *a: (order.append("people"), people(*a))[1])
    observe = loop.monitor.observe
    monkeypatch.setattr(loop.monitor, "observe", lambda t, ppl, eff, *a: (judged.append(np.array(eff)),
                                                                          observe(t, ppl, eff, *a))[1])
    him = anchored_worker((0.5, 1.3), heading=math.pi)  # within reach of the first waypoint: a retraction
    commanded = moved = 0
    for k in range(60):
        clock[0] = k / 30
        del order[:]
        rec = loop.feed_joints(him)
        assert "people" not in order  # not made on the way from keypoints to command, nor after it unasked
        assert rec.people is rec.people  # read twice: made once
        assert order[-1] == "people" and order.count("people") == 1  # after every link call of the frame, once
        commanded += len(order) > 1
        moved += not np.array_equal(loop.effector_m(), judged[-1])  # this frame's command moved the fallback
        eff = judged[-1]
        for p in rec.people:
            gap = np.linalg.norm(him - eff, axis=1)
            assert p["nearest_distance_m"] == round(float(gap[int(np.nanargmin(gap))]), 4)
            assert p["head_robot_m"] == [round(float(v), 4) for v in him[HEAD]]
    assert commanded >= 1 and moved >= 1


def test_dot_of_two_4x4_matrices_is_matmuls():
    """arm_points_m's ndarray.dot for `@`: the same BLAS product, to the bit (random, huge, tiny, signed zeros)."""
    rng = np.random.default_rng(1609)
    for case in range(5000):
        a, b = (rng.normal(0, 1, (4, 4)) * rng.choice([1e-300, 1e-8, 1.0, 1e8, 1e300]) for _ in range(2))
        if case % 5 == 0:
            a = with_edges(rng, a, 0.2)
        assert same_or_nan(a.dot(b), a @ b), case
