"""The whole-body geometry's fast forms (edge_runtime.robot.hazard) pinned to the textbook forms they replaced
(session 15, per-frame CPU): the same floating-point results to the bit on random inputs, so no decision changes."""
import math

import numpy as np
import pytest
from support.robot import anchored_worker

from edge_runtime.robot.hazard import (
    _base_rotations,
    arm_capsules,
    arm_points_m,
    body_spheres,
    effector_capsule,
    plan_escape_turn,
    point_clearance_m,
    separation_m,
    separation_per_shift_m,
)


def textbook_clearance(points_m, capsules):
    """point_clearance_m as it was through session 14."""
    a, b, r = capsules
    ab = b - a
    ap = np.asarray(points_m, float)[:, None, :] - a[None]
    den = np.maximum((ab * ab).sum(-1), 1e-12)
    t = np.clip((ap * ab[None]).sum(-1) / den, 0.0, 1.0)
    return (np.linalg.norm(ap - t[..., None] * ab[None], axis=-1) - r[None]).min(axis=1)


def textbook_plan(capsules, people, j0_rad, step_deg, min_gain_m, dip_m, max_turn_deg, reach_m=math.inf):
    """plan_escape_turn's choice as it was through session 14, one candidate turn and one person at a time
    (everyone turned by -a with the rotation matrix, einsum as then)."""
    def separations(turn):
        moved = np.einsum("kij,nj->kni", _base_rotations([-turn]), np.concatenate([c for c, _ in people]))[0]
        out, k = [], 0
        for c, r in people:
            out.append(float((textbook_clearance(moved[k:k + len(c)], capsules) - r).min()))
            k += len(c)
        return np.array(out)

    if not people:
        return None
    now = separations(0.0)
    best = None
    for sign in (1.0, -1.0):
        room = math.radians(max_turn_deg) if j0_rad is None else min(math.radians(max_turn_deg),
                                                                       math.radians(170.0) - sign * j0_rad)
        closest_so_far = np.full(len(people), np.inf)
        for k in range(1, int(math.floor(room / math.radians(step_deg) + 1e-9)) + 1):
            turn = sign * math.radians(step_deg) * k
            d = separations(turn)
            closest_so_far = np.minimum(closest_so_far, d)
            if (closest_so_far < np.minimum(now, reach_m) - dip_m).any():
                break  # the sweep passes nearer someone than he is now
            candidate = (float(d.min()), float(closest_so_far.min()), turn)
            if candidate[0] >= now.min() + min_gain_m and (best is None or candidate[:2] > best[:2]):
                best = candidate
    return None if best is None else best[2]


def random_q(rng):
    return rng.uniform(-2.9, 2.9, 7) * rng.choice([0.3, 1.0])


def random_capsules(rng):
    kind = rng.integers(3)
    if kind == 0:
        return effector_capsule(rng.uniform(-0.8, 0.8, 3))
    caps = arm_capsules(random_q(rng))
    if kind == 2:  # seen from above, as ray_separation_m uses them
        flat = np.array([1.0, 0.0, 1.0])
        caps = (caps[0] * flat, caps[1] * flat, caps[2])
    return caps


def random_person(rng):
    b = rng.uniform(-math.pi, math.pi)
    d = rng.uniform(0.4, 2.5)
    p = anchored_worker((d * math.sin(b), d * math.cos(b)), heading=rng.uniform(-math.pi, math.pi))
    return p + rng.normal(0.0, 0.05, p.shape)


def test_point_clearance_is_the_textbook_one_to_the_bit():
    rng = np.random.default_rng(20261126)
    for _ in range(400):
        caps = random_capsules(rng)
        n = int(rng.choice([1, 2, 17, 25, 50, 300, 1800]))
        pts = rng.normal(0.0, rng.choice([0.3, 1.0, 3.0]), (n, 3))
        if rng.random() < 0.2:  # points on the capsules' axes and ends: t clipped at 0 and 1, distances near 0
            k = rng.integers(len(caps[0]), size=n)
            pts = caps[0][k] + rng.choice([0.0, 0.5, 1.0, 1.3, -0.2], n)[:, None] * (caps[1][k] - caps[0][k])
        got, want = point_clearance_m(pts, caps), textbook_clearance(pts, caps)
        assert got.shape == want.shape and np.array_equal(got, want)
        assert got.dtype == want.dtype


def test_separations_are_the_textbook_ones_to_the_bit():
    rng = np.random.default_rng(7)
    for _ in range(200):
        caps = random_capsules(rng)
        centres, radii = body_spheres(random_person(rng))
        v = np.array([rng.normal(0, 1.0), 0.0, rng.normal(0, 1.0)])
        shifts = (0.0, 0.5)
        moved = (centres[None] + np.asarray(shifts)[:, None, None] * v[None, None]).reshape(-1, 3)
        want = (textbook_clearance(moved, caps) - np.tile(radii, 2)).reshape(2, -1).min(axis=1)
        assert np.array_equal(separation_per_shift_m(centres, radii, v, shifts, caps), want)
        assert separation_m(centres, radii, caps) == float((textbook_clearance(centres, caps) - radii).min())


def test_the_escape_plan_is_the_textbook_one_on_random_scenes():
    rng = np.random.default_rng(15)
    found = 0
    for _ in range(150):
        q = random_q(rng) if rng.random() < 0.8 else None
        caps = arm_capsules(q) if q is not None else effector_capsule(rng.uniform(-0.6, 0.6, 3))
        people = []
        for _ in range(int(rng.integers(1, 4))):
            c, r = body_spheres(random_person(rng))
            people.append((c, r + (rng.uniform(0, 0.4) if rng.random() < 0.3 else 0.0)))  # some lost: grown
        args = (None if q is None else float(q[0]), float(rng.choice([1.0, 2.0, 5.0, 10.0])), float(rng.choice([0.0, 0.05])),
                float(rng.choice([0.0, 0.02, 0.1])), float(rng.choice([30.0, 90.0, 180.0])),
                float(rng.choice([0.85, math.inf])))
        want = textbook_plan(caps, people, *args)
        assert plan_escape_turn(caps, people, *args) == want
        found += want is not None
    assert found >= 20  # the scenes turn the arm often enough to compare the choices, not just "None"


def test_the_escape_plan_breaks_ties_as_before():
    # a person straight in front of an arm pointing at him: turning either way gains the same (mirror image)
    caps = arm_capsules(np.array([0.0, -0.3, 0.0, 2.2, 0.0, 0.6, 0.0]))
    hand = arm_points_m(np.array([0.0, -0.3, 0.0, 2.2, 0.0, 0.6, 0.0]))[-2]
    b = math.atan2(hand[0], hand[2])
    him = anchored_worker((0.9 * math.sin(b), 0.9 * math.cos(b)), heading=b + math.pi)
    people = [body_spheres(him)]
    for j0 in (None, 0.0, 1.0, -2.5):
        assert plan_escape_turn(caps, people, j0, 5.0, 0.05, 0.02, 180.0) == textbook_plan(
            caps, people, j0, 5.0, 0.05, 0.02, 180.0)


def test_arm_capsules_are_kept_per_joint_state_and_read_only():
    rng = np.random.default_rng(3)
    for _ in range(30):
        q = random_q(rng)
        p = arm_points_m(q)
        a, b, r = arm_capsules(q)
        assert np.array_equal(a, p[:-1]) and np.array_equal(b, p[1:])
        assert arm_capsules(list(q))[0] is a  # the same joint angles: the same arrays
        with pytest.raises(ValueError):
            a[0, 0] = 1.0  # shared: nobody may change them
    assert not np.shares_memory(arm_points_m(q), a)  # arm_points_m itself gives a fresh array
