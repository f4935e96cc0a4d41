"""Worker motions (firmware_sim/people/motions.py): paths, speeds, gait, working postures, seams."""
import math

import numpy as np
import pytest

from edge_runtime.core import skeleton as sk
from firmware_sim.people import motions as mo
from firmware_sim.people.human import Body, bone_lengths

BODY = Body.from_height(1.72, "M")
FLOOR = -sk.BASE_HEIGHT_M


def _feet_on_floor(m):
    lowest = m.joints_m[:, [sk.L_ANKLE, sk.R_ANKLE], 1].min(axis=1) - FLOOR
    return np.allclose(lowest, BODY.ankle_height_m, atol=1e-9)


def test_walk_from_a_to_b_at_the_requested_speed():
    a, b = np.array([-1.0, 5.0]), np.array([2.0, 1.0])
    m = mo.walk(BODY, [a, b], 1.2)
    assert np.allclose(m.pelvis_xz_m[0], a, atol=0.03) and np.allclose(m.pelvis_xz_m[-1], b, atol=0.03)
    # along-path speed from the heading direction: cruises at 1.2 m/s, starts and ends slow
    v = np.linalg.norm(np.diff(m.pelvis_xz_m, axis=0), axis=1) * m.rate_hz
    cruise = v[len(v) // 3: 2 * len(v) // 3]
    assert np.median(cruise) == pytest.approx(1.2, abs=0.08)
    assert v[:3].max() < 0.5 and v[-3:].max() < 0.5
    direction = (b - a) / np.linalg.norm(b - a)
    fwd = np.stack([np.sin(m.heading_rad), np.cos(m.heading_rad)], 1)
    assert np.all(fwd @ direction > 0.99)
    assert _feet_on_floor(m)
    assert np.allclose(bone_lengths(m.joints_m), bone_lengths(m.joints_m[0]))
    assert m.joints_m.shape == (len(m), 17, 3) and set(m.labels) == {"walk"}


def test_speed_changes_per_leg_and_faster_walking_takes_longer_strides():
    m = mo.walk(BODY, [(0, 0), (0, 6), (0, 12)], [0.6, 1.8], accel_mps2=1.0)
    z = m.pelvis_xz_m[:, 1]
    v = np.gradient(z) * m.rate_hz
    assert np.median(v[(z > 2) & (z < 5)]) == pytest.approx(0.6, abs=0.06)
    assert np.median(v[(z > 8.5) & (z < 10.5)]) == pytest.approx(1.8, abs=0.12)

    def hip_range(lo, hi):
        h = m.angles_deg[(z > lo) & (z < hi), mo.angle_column("hip_flexion_deg.left")]
        return h.max() - h.min()
    assert hip_range(8.5, 10.5) > 1.5 * hip_range(2, 5)
    assert mo.stride_frequency_hz(1.8, 1.72) > mo.stride_frequency_hz(0.6, 1.72)
    with pytest.raises(ValueError, match="speed_mps"):
        mo.walk(BODY, [(0, 0), (0, 3)], 3.5)
    with pytest.raises(ValueError, match="waypoints"):
        mo.walk(BODY, [(0, 0)], 1.0)


def test_curving_walk_turns_smoothly_and_arms_swing_against_the_legs():
    m = mo.walk(BODY, [(0, 0), (3, 3), (6, 0)], 1.4, corner_radius_m=1.5)
    straight = np.abs(m.pelvis_xz_m[:, 1] - 3.0)
    assert straight.min() > 0.4                       # the corner at (3, 3) was cut
    dh = np.abs(np.diff(m.heading_rad))
    assert dh.max() <= math.radians(270) / m.rate_hz + 1e-9
    assert m.heading_rad[-1] - m.heading_rad[0] == pytest.approx(math.pi / 2, abs=0.05)   # 45 -> 135 deg
    sharp = mo.walk(BODY, [(0, 0), (3, 3), (6, 0)], 1.4)
    assert np.abs(sharp.pelvis_xz_m[:, 1] - 3.0).min() < 0.05
    # arm swing: the left wrist is forward when the left ankle is back
    straight_walk = mo.walk(BODY, [(0, 0), (0, 8)], 1.4)
    rel = straight_walk.joints_m[:, :, 2] - straight_walk.joints_m[:, [sk.HIP], 2]
    mid = slice(len(rel) // 4, 3 * len(rel) // 4)
    assert np.corrcoef(rel[mid, sk.L_WRIST], rel[mid, sk.L_ANKLE])[0, 1] < -0.5


def test_work_and_look_down_put_the_hands_at_the_work_point_and_the_eyes_on_it():
    rng = np.random.default_rng(3)
    m = mo.work_at(BODY, (0.5, 1.5), math.pi, 6.0, work_height_m=1.0, reach_m=0.35, rng=rng)
    assert np.ptp(m.pelvis_xz_m, axis=0).max() == 0.0 and _feet_on_floor(m)
    wrists = m.joints_m[:, [sk.L_WRIST, sk.R_WRIST]]
    assert np.median(wrists[..., 1] - FLOOR) == pytest.approx(1.0, abs=0.1)
    # facing -z (heading pi), the work point is 0.35 m toward -z from the pelvis
    assert np.median(wrists[..., 2]) == pytest.approx(1.5 - 0.35, abs=0.12)
    low = mo.look_down(BODY, (0, 1), 0.0, 4.0, rng=rng)
    neck = mo.angle_column("neck_flexion_deg")
    assert np.median(low.angles_deg[:, neck]) > np.median(m.angles_deg[:, neck]) > 5.0
    still = mo.stand(BODY, (0, 2), 0.0, 3.0)
    assert np.allclose(still.joints_m, still.joints_m[0])


def test_bend_and_squat_lower_the_body_and_come_back_up():
    rng = np.random.default_rng(4)
    b = mo.bend(BODY, (0, 2), 0.0, depth_deg=80, duration_s=4.0, hold_s=1.0, rng=rng)
    head = b.joints_m[:, sk.HEAD, 1] - FLOOR
    assert head[len(head) // 2] < 0.75 * head[0] and head[-1] > 0.95 * head[0]
    s = mo.squat(BODY, (0, 2), 0.0, depth=1.0, duration_s=5.0, hold_s=2.0, rng=rng)
    pelvis = s.joints_m[:, sk.HIP, 1] - FLOOR
    assert pelvis[len(pelvis) // 2] < 0.65 * BODY.hip_height_m
    assert _feet_on_floor(s)


def test_turn_takes_the_short_way_and_concat_blends_the_seams():
    t = mo.turn(BODY, (1, 1), math.radians(170), math.radians(-170), 1.0)
    assert t.heading_rad[-1] - t.heading_rad[0] == pytest.approx(math.radians(20))
    rng = np.random.default_rng(5)
    w = mo.walk(BODY, [(0, 3), (0, 1)], 1.5, rng=rng)
    xz, h = w.end
    parts = [w, mo.squat(BODY, xz, h, rng=rng), mo.work_at(BODY, xz, h, 3.0, rng=rng)]
    seq = mo.concat(parts)
    assert len(seq) == sum(len(p) for p in parts)
    step = np.linalg.norm(np.diff(seq.joints_m, axis=0), axis=2).max(axis=1)
    seams = np.cumsum([len(p) for p in parts[:-1]]) - 1
    for k in seams:                             # no joint jumps more than 5 cm in 1/30 s at a seam
        assert step[k - 2: k + 3].max() < 0.05
    assert list(dict.fromkeys(seq.labels)) == ["walk", "squat", "work"]


def test_random_activity_is_reproducible_and_long_enough():
    a = mo.random_activity(BODY, np.random.default_rng(7), 60.0)
    b = mo.random_activity(BODY, np.random.default_rng(7), 60.0)
    c = mo.random_activity(BODY, np.random.default_rng(8), 60.0)
    assert np.array_equal(a.joints_m, b.joints_m) and len(a) >= 60 * 30
    assert len(a) != len(c) or not np.array_equal(a.joints_m, c.joints_m)
    assert "walk" in set(a.labels) and np.isfinite(a.joints_m).all()


TRAINED_KINDS = ("walk", "run", "turn", "stop_and_go", "bend", "crouch", "work")   # the lifter's, carry and reach out


def _scripted_session(seed: int) -> mo.Motion:
    from firmware_sim.scenarios.recording import random_camera, session

    rng = np.random.default_rng(seed)
    return session(BODY, random_camera(rng), rng, 60.0, kinds=TRAINED_KINDS)


def test_random_limbs_stay_within_the_ranges_of_motion_on_a_body_that_stands():
    from firmware_sim.people.human import rom_violations

    scripted = _scripted_session(3)
    m = mo.random_limbs(scripted, np.random.default_rng(4))
    a = m.angles_deg
    assert rom_violations(a) == []
    for side in ("left", "right"):
        raise_sum = (np.maximum(a[:, mo.angle_column(f"shoulder_flexion_deg.{side}")], 0)
                     + np.maximum(a[:, mo.angle_column(f"shoulder_abduction_deg.{side}")], 0))
        assert raise_sum.max() <= mo.SHOULDER_ELEVATION_SUM_MAX_DEG + 1e-9
        shank = a[:, mo.angle_column(f"hip_flexion_deg.{side}")] - a[:, mo.angle_column(f"knee_flexion_deg.{side}")]
        assert np.abs(shank).max() <= mo.SHANK_FROM_VERTICAL_MAX_DEG + 1e-9
    # the same body on the same path: bones, the lower ankle on the floor, nothing below it, labels kept
    assert np.allclose(bone_lengths(m.joints_m), bone_lengths(scripted.joints_m[0]))
    assert _feet_on_floor(m) and m.joints_m[..., 1].min() >= FLOOR
    assert np.array_equal(m.pelvis_xz_m, scripted.pelvis_xz_m) and np.array_equal(m.heading_rad, scripted.heading_rad)
    assert list(m.labels) == list(scripted.labels)
    # smooth: no angle jumps from one frame to the next (minimum-jerk keys at least 0.5 s apart)
    step = np.abs(np.diff(a, axis=0))
    assert np.percentile(step, 99) < 15.0 and step.max() < 60.0
    assert np.array_equal(mo.random_limbs(scripted, np.random.default_rng(4)).joints_m, m.joints_m)


def test_random_limbs_reach_poses_the_scripted_motions_never_hold():
    scripted = _scripted_session(5)
    m = mo.random_limbs(scripted, np.random.default_rng(6))
    s, a = scripted.angles_deg, m.angles_deg
    for name in ("shoulder_abduction_deg.left", "shoulder_flexion_deg.right", "trunk_lateral_deg",
                 "trunk_twist_deg", "hip_flexion_deg.right"):
        lo_a, hi_a = np.percentile(a[:, mo.angle_column(name)], [1, 99])
        lo_s, hi_s = np.percentile(s[:, mo.angle_column(name)], [1, 99])
        assert hi_a - lo_a > hi_s - lo_s + 40.0, name
    # arms raised sideways above the shoulder: never in the scripted types, often with random limbs
    ab = mo.angle_column("shoulder_abduction_deg.left")
    assert s[:, ab].max() < 45.0 and (a[:, ab] > 90.0).mean() > 0.05
    # each group part of the time only (p_active 0.5): its angles leave the scripted ones in some frames, not all
    for group, names in mo.RANDOM_LIMB_GROUPS.items():
        cols = [mo.angle_column(n) for n in names]
        moved = (np.abs(a[:, cols] - s[:, cols]) > 5.0).any(axis=1)
        assert 0.25 < moved.mean() < 0.95, group
    # with nothing active the scripted motion comes back
    still = mo.random_limbs(scripted, np.random.default_rng(6), p_active=0.0)
    assert np.allclose(still.joints_m, scripted.joints_m)
    with pytest.raises(ValueError, match="p_active"):
        mo.random_limbs(scripted, np.random.default_rng(6), p_active=1.5)
