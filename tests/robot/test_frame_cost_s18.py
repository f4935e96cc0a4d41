"""Session 18's per-frame CPU cuts in the decision half of a frame (edge_runtime.robot.hazard, loop) pinned to the
forms they replaced: the same floating-point results to the bit on random and edge inputs, so no decision and no
logged figure changes; and a frame's log, made when first read, says what that frame believed."""
import copy
import math
import pickle
from dataclasses import asdict

import numpy as np
import pytest
from robot.test_frame_cost_s16 import same, same_or_nan, with_edges
from robot.test_hazard_vectorised import random_capsules, random_person
from support.robot import FakeLink, anchored_worker

from edge_runtime.core.skeleton import HEAD, JOINTS
from edge_runtime.robot import hazard as hz
from edge_runtime.robot.hazard import ZoneParams
from edge_runtime.robot.loop import FrameRecord, LoopParams, MotionKind, RobotLoop

pytestmark = pytest.mark.filterwarnings("ignore::RuntimeWarning")  # inf - inf and the like, in old and new alike


def test_ground_is_the_tuple_index_it_replaced():
    rng = np.random.default_rng(1801)
    for shape in ((3,), (1, 3), (25, 3), (4, 5, 3), (0, 3)):
        v = with_edges(rng, rng.normal(0, 1, shape), 0.2)
        assert same(hz.ground(v), v[..., (0, 2)]), shape
    for v in ((1.0, 2.0, 3.0), [4, 5, 6], np.arange(3, dtype=np.float32)):
        assert same(hz.ground(v), np.asarray(v, float)[..., (0, 2)])


def test_everyones_spheres_at_once_are_each_persons_own():
    rng = np.random.default_rng(1802)
    for case in range(300):
        persons = [random_person(rng) for _ in range(int(rng.integers(1, 5)))]
        if case % 3 == 0:
            persons = [with_edges(rng, p, 0.02) for p in persons]  # NaN and inf joints: each person's own cover
        if case % 7 == 0:
            persons.append(rng.normal(0, 1, 3))  # a lone head
        got = hz.body_spheres_of(persons)
        assert len(got) == len(persons)
        for p, (c, r) in zip(persons, got):
            try:
                want_c, want_r = hz.body_spheres(p)
            except ValueError:  # no joint known at all: so for everyone at once
                break
            assert same(c, want_c) and same(r, want_r), case
            assert not (c.flags.writeable or r.flags.writeable)  # kept and shared
        else:
            continue
        with pytest.raises(ValueError):
            hz.body_spheres_of(persons)


def test_everyones_separation_in_one_call_is_each_persons_own():
    rng = np.random.default_rng(1803)
    for case in range(300):
        caps = random_capsules(rng)
        people = [hz.body_spheres(random_person(rng)) for _ in range(int(rng.integers(1, 5)))]
        if case % 4 == 0:
            people.append((rng.normal(0, 1, (1, 3)), np.array([0.12])))  # a head alone: fewer spheres
        if case % 3 == 0:
            people = [(with_edges(rng, c, 0.05), r) for c, r in people]
        got = hz.people_separations_m(people, caps)
        assert same_or_nan(got, [hz.separation_m(c, r, caps) for c, r in people]), case


def old_people(loop, keys, persons, eff):
    """RobotLoop._people as session 17 left it: one person at a time."""
    out = []
    for key, joints in zip(keys, persons):
        gap = np.linalg.norm(joints - eff, axis=1)
        j = int(np.nanargmin(gap)) if np.isfinite(gap).any() else 0
        est = loop.monitor.estimates.get(key)
        out.append({"id": key.item() if isinstance(key, np.generic) else key,
                    "head_robot_m": [round(x, 4) for x in np.asarray(joints[HEAD], float).reshape(3).tolist()],
                    "predicted_head_m": None if est is None else [round(x, 4) for x in est.predicted_m.tolist()],
                    "nearest_joint": JOINTS[j], "nearest_point_m": [round(x, 4) for x in joints[j].tolist()],
                    "nearest_distance_m": round(float(gap[j]), 4)})
    return out


def test_the_log_of_everyone_at_once_is_each_persons_own():
    rng = np.random.default_rng(1804)
    loop = RobotLoop(FakeLink(), zones=ZoneParams())
    for case in range(300):
        persons = np.array([random_person(rng) for _ in range(int(rng.integers(1, 5)))])
        if case % 3 == 0:
            persons = with_edges(rng, persons, 0.1)
        if case % 11 == 0:
            persons[0] = np.nan  # nothing of him finite: joint 0, as nanargmin's guard had it
        keys = list(np.arange(len(persons))) if case % 2 else [f"p{k}" for k in range(len(persons))]
        eff = rng.normal(0, 0.5, 3)
        assert repr(loop._people(keys, persons, eff)) == repr(old_people(loop, keys, persons, eff)), case


def test_a_frames_log_read_later_says_what_that_frame_believed():
    """Made when first read (most runs read none), from copies of the frame's joints, effector and head estimates:
    read after later frames it is what reading it at once gave; asdict (the robot command's --log) has it."""
    clock = [0.0]

    def run(read_at_once: bool) -> list:
        link = FakeLink()
        loop = RobotLoop(link, zones=ZoneParams(), clock=lambda: clock[0])
        records = []
        for k in range(40):
            clock[0] = k / 30
            rec = loop.feed_joints(anchored_worker((0.3 + 0.05 * k, 1.6 - 0.02 * k), heading=math.pi))
            records.append(rec.people if read_at_once else rec)
            link.advance(1 / 30)
        return records, loop

    at_once, _ = run(True)
    later, loop = run(False)
    for k, rec in enumerate(later):
        assert rec.people == at_once[k] and len(at_once[k]) == 1, k
        assert asdict(rec)["people"] == at_once[k]
    unread = loop.feed_joints(anchored_worker((0.5, 1.2), heading=math.pi))
    copied = pickle.loads(pickle.dumps(unread))  # made before pickling (a closure cannot be pickled)
    assert copied.people == unread.people and len(copied.people) == 1 and copy.deepcopy(unread) == unread
    empty = loop.feed_joints(None)
    assert empty.people == [] and asdict(empty)["people"] == []
    assert FrameRecord(0.0, None, "NORMAL", "clear", math.inf, None) == FrameRecord(0.0, None, "NORMAL", "clear",
                                                                                   math.inf, None, lambda: [])
    with pytest.raises(AttributeError):
        empty.nothing  # noqa: B018 - only ``people`` is made on reading


def old_backfires(loop) -> bool:
    """RobotLoop._retract_backfires as session 17 left it: each person's separation alone."""
    r, q0, q, z = loop._retract, loop._retract_q0, loop._last_q, loop.zones
    if r is None or r.kind is not MotionKind.RETRACT or q0 is None or q is None:
        return False
    reach = z.body_retract_distance_m + z.retract_lead_s * z.lost_person_speed_mps
    for centres, radii in loop.monitor.people_spheres():
        now = hz.separation_m(centres, radii, hz.arm_capsules(q))
        if now < reach and now < hz.separation_m(centres, radii, hz.arm_capsules(q0)) - loop.params.retract_backfire_m:
            return True
    return False


def test_the_backfire_check_of_everyone_at_once_is_each_persons_own():
    rng = np.random.default_rng(1805)
    loop = RobotLoop(FakeLink(), zones=ZoneParams(), params=LoopParams())
    fired = 0
    for case in range(400):
        persons = np.array([random_person(rng) for _ in range(int(rng.integers(1, 4)))])
        q_frame = rng.uniform(-2, 2, 7)
        loop.monitor.observe(case / 30, dict(enumerate(persons)), rng.normal(0, 0.5, 3), q_frame)
        loop._retract = loop._radial_retract()
        loop._last_q = q_frame if case % 2 else rng.uniform(-2.5, 2.5, 7)  # the frame's arm: its separations
        loop._retract_q0 = loop._last_q + rng.normal(0, rng.choice([0.01, 0.3, 1.0]), 7)
        want = old_backfires(loop)
        assert loop._retract_backfires() == want, case
        assert loop._retract_backfires() == want, case  # remembered
        fired += want
    assert 20 < fired < 380  # both answers were tried


def test_the_frames_separations_are_the_backfire_checks_own():
    """The monitor's separation of each person at his frame (his spheres moved by 0 s) is what people_separations_m
    gives for the same capsules, to the bit, on random walks (people coming and going, lost ones too), and for
    any other capsules it is computed."""
    rng = np.random.default_rng(1806)
    mon = hz.HazardMonitor()
    seeded = 0
    for k in range(300):
        q = rng.uniform(-2, 2, 7)
        people = {w: random_person(rng) for w in range(4) if rng.random() < 0.7}
        mon.observe(k / 30, people, rng.normal(0, 0.5, 3), q)
        spheres = mon.people_spheres()
        if not spheres:
            continue
        for caps in (hz.arm_capsules(q), hz.arm_capsules(rng.uniform(-2, 2, 7))):
            assert same(mon.people_separations_m(caps), hz.people_separations_m(spheres, caps)), k
        seeded += all(s.clear_of is not None and s.clear_of[0] is hz.arm_capsules(q) for s in mon._seen.values())
    assert 30 < seeded < 300
