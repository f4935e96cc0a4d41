"""Head tracking, the two-level zones of Eq. 4-5, the state machine, the retraction (Eq. 6, its
radius and height limits, the fallback toward the base and the tool's turn), and whole-body
separation with speed and separation monitoring of edge_runtime.robot.hazard."""
import math
from dataclasses import replace

import numpy as np
import pytest
from support.robot import EFF, FPS, HEAD_Y, anchored_worker, head_at

from edge_runtime.core.skeleton import HEAD
from edge_runtime.robot.hazard import (
    ARM_LINK_RADII_M,
    JOINT_REACH_M,
    MIRROR,
    RAY_KEYPOINT_ERROR_M,
    REQUIRED_JOINTS,
    HazardMonitor,
    HeadEstimate,
    HeadTracker,
    PersonRays,
    RetractLimits,
    State,
    TrackerParams,
    ZoneParams,
    arm_capsules,
    arm_points_m,
    body_spheres,
    effector_capsule,
    eq6_retraction,
    limit_turn,
    plan_escape_turn,
    radial_retraction,
    ray_separation_m,
    retract_direction,
    separation_m,
    step_outside_radius,
    tool_yaw_toward_base,
    turned_capsules,
    turned_retraction,
)

DISSERTATION = ZoneParams(retract_time_s=1.0, separation="head")  # the dissertation's head-to-effector zones
"""The dissertation's zones (T_retract = 1 s: R2 = 1 m, R1 = 3 m), which these tests' geometry uses;
the shipped default is the simulated Sawyer's 2 s (tests/sim/test_hrc.py validates it)."""


def ready(zones=DISSERTATION):
    """A monitor past its start-up fault: poses of a far worker have flowed for dwell_s."""
    mon = HazardMonitor(zones)
    n = int((zones.dwell_s + 0.2) * FPS)
    run(mon, [head_at(20.0)] * n, t0=-10.0)
    assert mon.state == State.NORMAL
    return mon


def run(mon, heads, t0=0.0, fps=FPS):
    """Feed one head per frame; return the states."""
    out = []
    for i, h in enumerate(heads):
        out.append(mon.observe(t0 + i / fps, {0: h}, EFF).state)
    return out


def test_zone_radii_follow_eq4_and_eq5_from_their_parameters():
    z = DISSERTATION
    assert z.r2_m == pytest.approx(1.4 * (1.0 - 0.5) + 0.3) and z.r2_m == pytest.approx(1.0)
    assert z.r1_m == pytest.approx(3.0)
    faster = ZoneParams(worker_speed_mps=2.0, retract_time_s=1.5, margin2_m=0.5, margin1_m=1.0)
    assert faster.r2_m == pytest.approx(2.0 * 1.0 + 0.5) and faster.r1_m == pytest.approx(3.5)
    iso = ZoneParams(sizing="iso15066", retract_time_s=1.0)
    sp = 1.6 * (0.15 + 0.3) + 0.6 * 0.15 + 0.09 + 0.85 + 0.1 + 0.01
    assert iso.protective_distance_m == pytest.approx(sp) and iso.r1_m == pytest.approx(sp)
    assert iso.r2_m == pytest.approx(1.0)
    # S_p can never shrink the stop zone below the retraction zone
    assert ZoneParams(sizing="iso15066", iso_intrusion_m=0.0, iso_human_speed_mps=0.1).r1_m == pytest.approx(2.4)
    with pytest.raises(ValueError, match="sizing"):
        ZoneParams(sizing="big")


def test_walking_straight_at_the_effector_triggers_level1_then_level2_at_the_predicted_distances():
    speed = 1.2
    mon = ready()
    dists = [6.0 - speed * i / FPS for i in range(int(5.5 * FPS))]
    states = run(mon, [head_at(d) for d in dists])
    first = {s: dists[states.index(s)] for s in (State.LEVEL1, State.LEVEL2)}
    lead = speed * 0.5  # Eq. 3: the predicted head is 0.6 m ahead of the real one
    assert 3.0 + lead - 0.1 <= first[State.LEVEL1] <= 3.0 + lead + 1 / FPS * speed + 0.05
    assert 1.0 + lead - 0.1 <= first[State.LEVEL2] <= 1.0 + lead + 1 / FPS * speed + 0.05
    assert states.index(State.LEVEL1) < states.index(State.LEVEL2)
    # monotone: approaching never de-escalates
    assert all(b >= a for a, b in zip(states, states[1:]))


def test_noise_alone_never_makes_the_state_chatter():
    rng = np.random.default_rng(1)
    for dist, expected in ((2.5, State.LEVEL1), (3.0, None), (1.0, None), (4.5, State.NORMAL)):
        mon = ready()
        heads = [head_at(dist) + rng.normal(0, 0.03, 3) for _ in range(int(60 * FPS))]
        states = run(mon, heads)
        changes = sum(a != b for a, b in zip(states, states[1:]))
        if expected is not None:
            assert changes == 0 and states[-1] == expected, (dist, changes)
        else:
            # on a zone boundary the noise may push the worker in once; the hysteresis and
            # dwell keep it there instead of flickering
            assert changes <= 1, (dist, changes)


def test_least_squares_velocity_rejects_keypoint_noise():
    rng = np.random.default_rng(2)
    n = int(30 * FPS)
    truth_v = np.array([0.8, 0.0, -0.5])
    pos = np.array([1.0, HEAD_Y, 4.0]) + np.outer(np.arange(n) / FPS, truth_v)
    noisy = pos + rng.normal(0, 0.03, pos.shape)
    tr = HeadTracker(TrackerParams(), predict_s=0.5)
    est = [tr.update(i / FPS, p) for i, p in enumerate(noisy)]
    v_ls = np.array([e.velocity_mps for e in est[30:]])
    v_fd = np.diff(noisy, axis=0)[30:] * FPS
    err_ls = np.linalg.norm(v_ls - truth_v, axis=1)
    err_fd = np.linalg.norm(v_fd - truth_v, axis=1)
    print(f"velocity error rms: least squares {np.sqrt(np.mean(err_ls ** 2)):.3f} m/s, "
          f"finite difference {np.sqrt(np.mean(err_fd ** 2)):.3f} m/s")
    assert np.sqrt(np.mean(err_ls ** 2)) < 0.25
    assert np.sqrt(np.mean(err_ls ** 2)) < np.sqrt(np.mean(err_fd ** 2)) / 4
    pred_err = np.linalg.norm([e.predicted_m - (p + 0.5 * truth_v) for e, p in zip(est[30:], pos[30:])], axis=1)
    assert np.median(pred_err) < 0.1


def test_a_new_track_shorter_than_min_span_has_no_velocity():
    # a head whose depth jumps about by 0.3 m at 30 Hz: three frames span 0.07 s and read as metres per second
    heads = [[1.0, HEAD_Y, 4.0 + dz] for dz in (0.0, -0.15, -0.3, -0.2, -0.35, -0.25, -0.4, -0.3, -0.45, -0.35)]
    off, on = TrackerParams(min_span_s=0.0), TrackerParams()             # before session 22, and shipped (0.3 s)
    assert on.min_span_s > 0.2
    fits = {}
    for name, p in (("off", off), ("on", on)):
        tr = HeadTracker(p, 0.5)
        fits[name] = [tr.update(i / FPS, h) for i, h in enumerate(heads)]
    assert np.linalg.norm(fits["off"][2].velocity_mps) > 2.0          # 3 frames: a fit, and a fast one
    span_s = [i / FPS for i in range(len(heads))]
    for est, t in zip(fits["on"], span_s):
        if t < on.min_span_s - 1e-9:                                    # not long enough: standing, where he is
            assert not est.velocity_mps.any() and np.array_equal(est.predicted_m, est.position_m)
        else:                                                           # then the same fit as without it
            ref = fits["off"][span_s.index(t)]
            assert np.array_equal(est.velocity_mps, ref.velocity_mps)


def test_leaving_needs_the_exit_radius_and_the_dwell_time():
    z = DISSERTATION
    mon = ready(z)
    run(mon, [head_at(2.0)] * 30)
    assert mon.state == State.LEVEL1
    # just outside R1 but inside the exit radius: stays in level 1 however long
    assert set(run(mon, [head_at(3.1)] * 120, t0=1.0)) == {State.LEVEL1}
    # beyond the exit radius: level 1 until the dwell time has passed
    t0 = 5.0
    states = run(mon, [head_at(3.5)] * 60, t0=t0)
    k = states.index(State.NORMAL)
    assert k / FPS == pytest.approx(z.dwell_s, abs=1.5 / FPS)
    assert mon.reason == "clear"


def test_level2_steps_down_through_level1():
    mon = ready()
    run(mon, [head_at(0.5)] * 30)
    assert mon.state == State.LEVEL2
    states = run(mon, [head_at(5.0)] * 90, t0=1.0)
    seq = [s for i, s in enumerate(states) if i == 0 or states[i - 1] != s]
    assert seq == [State.LEVEL2, State.LEVEL1, State.NORMAL]


def test_stale_pose_stops_within_one_cycle_after_200_ms():
    mon = HazardMonitor(DISSERTATION)
    assert mon.check(0.0).state == State.FAULT and mon.reason == "no_pose_yet"
    run(mon, [head_at(5.0)] * 60)  # 2 s of a far worker: the start-up fault has cleared
    t_last = 59 / FPS
    assert mon.state == State.NORMAL
    cycle = 0.01
    t = t_last
    while mon.check(t).state == State.NORMAL:
        t += cycle
    assert mon.reason == "pose_stale" and 0.2 < t - t_last <= 0.2 + cycle + 1e-9
    assert mon.stale_events == 1
    # frames again: the fault clears only after the dwell time of valid frames
    states = run(mon, [head_at(5.0)] * 45, t0=t + 0.01)
    assert states[0] == State.FAULT and states.index(State.NORMAL) / FPS == pytest.approx(1.0, abs=1.5 / FPS)


def test_invalid_lifter_output_stops_with_its_own_reason():
    mon = ready()
    run(mon, [head_at(5.0)] * 60)
    d = mon.invalid(2.0, "too few keypoints")
    assert d.state == State.FAULT and d.reason == "pose_invalid: too few keypoints" and d.changed


def test_a_fault_during_a_retraction_lets_the_retraction_finish():
    mon = ready()
    run(mon, [head_at(0.5)] * 30)
    d = mon.check(30 / FPS + 0.3)
    assert d.state == State.LEVEL2 and "pose_stale" in d.reason


def test_a_worker_lost_inside_the_zone_holds_the_arm():
    z = DISSERTATION
    mon = ready(z)
    run(mon, [head_at(2.0)] * 30)
    t = 1.0
    for i in range(int(z.lost_hold_s * FPS) - 1):
        d = mon.observe(t + i / FPS, {}, EFF)
        assert d.state == State.LEVEL1 and d.reason == "worker_lost"
    # after the hold and the dwell of an empty scene the arm may work again
    for i in range(int((z.dwell_s + 0.5) * FPS)):
        d = mon.observe(t + z.lost_hold_s + i / FPS, {}, EFF)
    assert d.state == State.NORMAL
    # nobody ever seen near: an empty scene is simply clear
    mon2 = ready(z)
    run(mon2, [head_at(6.0)] * 60)
    assert mon2.observe(3.0, {}, EFF).state == State.NORMAL


def test_the_nearest_of_several_workers_decides():
    mon = ready()
    for i in range(60):
        d = mon.observe(i / FPS, {7: head_at(6.0), 3: head_at(2.0, (1.0, 0.2))}, EFF)
    assert d.state == State.LEVEL1 and d.worker == 3 and d.distance_m == pytest.approx(2.0, abs=0.05)


# -- retraction (Eq. 6) ----------------------------------------------------------------------


def standing(head_m) -> HeadEstimate:
    head = np.asarray(head_m, float)
    return HeadEstimate(0.0, head, np.zeros(3), head)


def test_retract_direction_is_eq6_and_the_tool_turns_to_the_base():
    tr = HeadTracker(TrackerParams(), 0.5)
    # a worker walking along -x, passing in front (+z side) of the effector
    for i in range(20):
        est = tr.update(i / FPS, [1.0 - 1.0 * i / FPS, HEAD_Y, EFF[2] + 0.8])
    L = retract_direction(EFF, est)
    away = np.array([0.0, -1.0])  # from the head (at +z) to the effector: -z (head is nearly straight ahead)
    path = np.array([-1.0, 0.0])
    g = L[[0, 2]]
    assert L[1] == 0.0
    c = EFF[[0, 2]] - est.position_m[[0, 2]]
    expect = 0.3 * c / np.linalg.norm(c) + 0.2 * path
    assert np.allclose(g, expect, atol=0.02)
    assert g[1] < 0 and g[0] < 0 and np.dot(g, away) > 0
    # a standing worker: only the step away from him
    still = HeadTracker(TrackerParams(), 0.5)
    for i in range(10):
        est = still.update(i / FPS, head_at(0.8))
    assert np.allclose(retract_direction(EFF, est)[[0, 2]], [0.0, -0.3], atol=1e-6)
    # yaw: from (1, y, 0) the base is along -x; from (0, y, 1) along -z
    assert tool_yaw_toward_base([1.0, 0.1, 0.0]) == pytest.approx(-math.pi / 2)
    assert abs(tool_yaw_toward_base([0.0, 0.1, 1.0])) == pytest.approx(math.pi)


def test_the_step_stops_at_the_radius_and_is_whole_when_it_never_reaches_it():
    start, step = np.array([0.0, 0.8]), np.array([0.0, -1.0])
    assert step_outside_radius(start, step, 0.3) == pytest.approx(0.5)  # 0.8 -> 0.3 m from the axis
    assert step_outside_radius(start, step, 0.9) == 0.0                  # already inside: do not move
    assert step_outside_radius(start, np.array([0.2, 0.0]), 0.3) == 1.0   # sideways, stays outside
    assert step_outside_radius(start, np.zeros(2), 0.3) == 1.0
    assert step_outside_radius(start, np.array([0.0, 0.4]), 0.3) == 1.0   # outward


def test_the_tool_turns_at_most_max_turn_the_short_way():
    assert limit_turn(2.0, None, 45.0) == 2.0  # where the tool points is unknown: all the way
    assert limit_turn(0.3, 0.0, 45.0) == pytest.approx(0.3)
    assert limit_turn(-2.8, 0.0, 45.0) == pytest.approx(-math.pi / 4)
    # from 170 deg to -170 deg is 20 deg across +-180, not 340 deg back
    assert limit_turn(math.radians(-170), math.radians(170), 45.0) == pytest.approx(math.radians(190))


def test_eq6_target_from_a_head_on_worker_stays_outside_the_base_radius():
    limits = RetractLimits(min_radius_m=0.3, max_radius_m=0.7)
    r = eq6_retraction(EFF, standing(head_at(0.8)), ZoneParams(), limits, tool_yaw_rad=None)
    # 0.3 m away from the head (-z), shortened to stop 0.3 m from the axis: z 0.8 -> 0.5
    np.testing.assert_allclose(r.position_m, [0.0, 0.14, 0.5], atol=1e-9)
    assert abs(r.yaw_rad) == pytest.approx(math.pi)  # the tool points at the base (-z)
    # from 0.4 m out only 0.1 m is left before the radius
    near = eq6_retraction([0.0, 0.14, 0.4], standing([0.0, HEAD_Y, 1.2]), ZoneParams(), limits, None)
    np.testing.assert_allclose(near.position_m, [0.0, 0.14, 0.3], atol=1e-9)


def test_eq6_target_is_pulled_in_to_the_max_radius_and_kept_above_the_min_height():
    limits = RetractLimits(min_radius_m=0.3, max_radius_m=0.7, min_height_m=-0.3)
    eff = np.array([1.0, -0.6, 0.0])  # 1 m out to +x, low
    r = eq6_retraction(eff, standing([0.2, HEAD_Y, 0.0]), ZoneParams(), limits, tool_yaw_rad=None)
    # 0.3 m further out (+x, away from the head), then pulled in to 0.7 m; height raised to -0.3 m
    np.testing.assert_allclose(r.position_m, [0.7, -0.3, 0.0], atol=1e-9)
    assert r.yaw_rad == pytest.approx(-math.pi / 2)


def test_a_repeat_retraction_keeps_the_held_yaw_and_a_first_one_turns_from_the_tool():
    limits = RetractLimits(max_turn_deg=45.0)
    head = standing(head_at(0.8))
    first = eq6_retraction(EFF, head, ZoneParams(), limits, tool_yaw_rad=0.0)
    assert abs(first.yaw_rad) == pytest.approx(math.pi / 4)  # toward the base (pi), 45 deg at most
    again = eq6_retraction(first.position_m, head, ZoneParams(), limits, tool_yaw_rad=0.1, held_yaw_rad=0.7)
    assert again.yaw_rad == 0.7


def test_the_fallback_goes_straight_toward_the_base_but_not_inside_the_min_radius():
    limits = RetractLimits(min_radius_m=0.3, max_radius_m=0.7)
    r = radial_retraction([0.3, 0.2, 0.4], ZoneParams(), limits, tool_yaw_rad=None)  # 0.5 m out
    np.testing.assert_allclose(r.position_m, [0.18, 0.2, 0.24], atol=1e-9)       # 0.3 m out, same bearing
    far = radial_retraction([1.2, 0.2, 0.0], ZoneParams(), limits, None)           # beyond the max radius:
    np.testing.assert_allclose(far.position_m, [0.3, 0.2, 0.0], atol=1e-9)          # 0.7 - 0.5 m step -> 0.3 m
    mid = radial_retraction([0.0, 0.2, 0.9], ZoneParams(), RetractLimits(min_radius_m=0.1, max_radius_m=0.7), None)
    np.testing.assert_allclose(mid.position_m, [0.0, 0.2, 0.2], atol=1e-9)          # 0.7 - 0.5 = 0.2 m out
    on_axis = radial_retraction([0.0, 0.2, 0.0], ZoneParams(), limits, None)
    np.testing.assert_allclose(on_axis.position_m, [0.0, 0.2, 0.0])


# -- whole-body separation and speed and separation monitoring --------------------------------

WHOLE_BODY = ZoneParams()
FULL_SPEED_TS = ZoneParams(stop_time_scales=False)
"""The full-speed stopping time at every speed (shipped before session 14): S_p 1.13-1.31 m."""
"""The shipped default: whole-body separation with speed scaling."""


def test_the_runtimes_arm_table_is_the_simulators_kinematics():
    from firmware_sim.robot import sawyer

    rng = np.random.default_rng(5)
    for _ in range(20):
        q = rng.uniform(sawyer.LOWER_RAD, sawyer.UPPER_RAD)
        frames = sawyer.forward_kinematics(q)
        hand = frames[-1]
        sim = np.array([np.zeros(3), *(f[:3, 3] for f in frames), hand[:3, 3] + 0.10 * hand[:3, 2]])
        assert np.abs(arm_points_m(q) - sim @ sawyer.URDF_TO_ROBOT.T).max() < 1e-4  # the URDF's 4-digit angles
        # every collision sphere the simulator judges with lies inside one of the runtime's capsules
        centres, radii = sawyer.collision_spheres(q)
        a, b, r = arm_capsules(q)
        inside = [separation_m(c[None], np.zeros(1), (a, b, r - rad)) for c, rad in zip(centres, radii)]
        assert max(inside) <= 1e-4


def test_separation_is_measured_between_surfaces():
    caps = (np.array([[0.0, 0.0, 0.0]]), np.array([[0.0, 0.0, 1.0]]), np.array([0.05]))
    assert separation_m(np.array([[0.5, 0.0, 0.5]]), np.array([0.1]), caps) == pytest.approx(0.35)
    assert separation_m(np.array([[0.0, 0.0, 1.5]]), np.array([0.1]), caps) == pytest.approx(0.35)  # past the end
    centres, radii = body_spheres(np.zeros((17, 3)))
    assert len(centres) == 17 + 8 and radii.max() == pytest.approx(0.15)
    assert separation_m(centres + [0.0, 0.0, -1.0], radii, caps) == pytest.approx(1.0 - 0.05 - 0.15)


def test_allowed_speed_inverts_the_protective_distance():
    z = WHOLE_BODY
    for v in (0.0, 0.2, z.iso_robot_speed_mps):
        assert z.allowed_speed_mps(z.body_protective_distance_m(v)) == pytest.approx(v)
    assert z.allowed_speed_mps(0.0) == 0.0 and z.allowed_speed_mps(50.0) == z.iso_robot_speed_mps
    # S_p = v_h (T_r + T_s) + v_r (T_r + T_s / 2) + C + Z_d + Z_r, and a faster human needs more
    sp = 1.6 * 0.45 + 0.6 * 0.3 + 0.1 + 0.3 + 0.01
    assert z.body_protective_distance_m(0.6) == pytest.approx(sp)
    assert z.body_protective_distance_m(0.6, 2.0) == pytest.approx(sp + 0.4 * 0.45)


def body_facing_arm(sep_z_m, reach=False):
    """A standing worker's robot-frame joints on the +z side of the effector EFF, his body about
    ``sep_z_m`` beyond it; ``reach``: his right wrist held out 0.6 m toward the arm."""
    from firmware_sim.people import human

    j = human.joints(human.Body.from_height(1.75), human.Posture(), pelvis_xz_m=(EFF[0], EFF[2] + sep_z_m),
                     heading_rad=math.pi)
    if reach:
        j[16] = j[14] + [0.0, 0.0, -0.6]
    return j


def ready_body(zones, sep_z_m=8.0):
    mon = HazardMonitor(zones)
    for i in range(int((zones.dwell_s + 0.2) * FPS)):
        mon.observe(-10.0 + i / FPS, {0: body_facing_arm(sep_z_m)}, EFF)
    assert mon.state == State.NORMAL
    return mon


def settle(mon, body, t0=0.0, seconds=1.0):
    for i in range(int(seconds * FPS)):
        d = mon.observe(t0 + i / FPS, {0: body}, EFF)
    return d


def settled_at(z, seps):
    """(speed scales, states) the arm settles to with a worker standing at each of ``seps``."""
    scales, states = [], []
    for sep in seps:
        d = settle(ready_body(z), body_facing_arm(sep))
        scales.append(d.speed_scale)
        states.append(d.state)
    return scales, states


def test_a_standing_worker_slows_the_arm_then_stops_it_and_stop_only_only_stops():
    z = FULL_SPEED_TS
    scales, states = settled_at(z, (4.0, 1.55, 1.45, 1.35, 1.2, 1.1, 1.0))
    assert scales[0] == 1.0 and states[0] == State.NORMAL
    working = [s for s, st in zip(scales, states) if st == State.NORMAL]
    assert all(a > b for a, b in zip(working, working[1:])) and len(working) >= 3   # slower as he is closer
    assert 0.0 < working[-1] < 0.5
    assert states[-2] == State.LEVEL1                                  # within S_p of the slowest speed
    assert State.LEVEL2 not in states[:-1]                             # standing beyond reach: no retraction
    assert states[-1] == State.LEVEL2                                  # standing within reach_retract_m: retract
    only = replace(FULL_SPEED_TS, speed_scaling=False)
    d = settle(ready_body(only), body_facing_arm(1.45))
    assert d.state == State.LEVEL1 and d.speed_scale == 1.0            # where the scaled arm still works


def test_with_the_speed_dependent_stopping_time_a_slow_arm_works_on_until_the_worker_is_within_reach():
    z = WHOLE_BODY                                                     # shipped: T_s shrinks with the arm's speed
    assert z.body_protective_distance_m(z.min_speed_fraction * z.iso_robot_speed_mps) < z.reach_retract_m
    seps = (4.0, 1.55, 1.45, 1.35, 1.2, 1.1, 1.0, 0.9)
    scales, states = settled_at(z, seps)
    last = max(i for i, st in enumerate(states) if st == State.NORMAL)
    assert states[:last + 1] == [State.NORMAL] * (last + 1) and states[last + 1:] and \
        set(states[last + 1:]) == {State.LEVEL2}                      # never a stop: slow, then retract
    assert all(a > b for a, b in zip(scales[:last + 1], scales[1:last + 1])) and 0.0 < scales[last] < 0.5
    assert separation_of(body_facing_arm(seps[last])) > z.reach_retract_m
    assert separation_of(body_facing_arm(seps[last + 1])) <= z.reach_retract_m
    assert settled_at(FULL_SPEED_TS, seps)[1][last] == State.LEVEL1       # where the full-speed T_s stops it


def test_the_stopping_time_shrinks_with_the_arms_speed():
    z = WHOLE_BODY
    assert z.stop_time_s(z.iso_robot_speed_mps) == z.iso_stop_time_s and z.stop_time_s(0.0) == 0.0
    # at 10 % speed: S_p = 1.6 (0.15 + 0.03) + 0.06 (0.15 + 0.015) + 0.41 = 0.708 m; at full 1.31 m
    assert z.body_protective_distance_m(0.06) == pytest.approx(1.6 * 0.18 + 0.06 * 0.165 + 0.41)
    assert z.body_protective_distance_m(0.6) == pytest.approx(1.31)
    fixed = FULL_SPEED_TS
    assert fixed.body_protective_distance_m(0.06) == pytest.approx(1.6 * 0.45 + 0.06 * 0.3 + 0.41)
    for v in (0.0, 0.06, 0.3, 0.6):  # the quadratic S_p is inverted too
        assert z.allowed_speed_mps(z.body_protective_distance_m(v)) == pytest.approx(v)


def test_a_worker_who_keeps_coming_makes_the_arm_retract():
    z = WHOLE_BODY
    mon = ready_body(z)
    decisions = [mon.observe(i / FPS, {0: body_facing_arm(6.0 - 1.4 * i / FPS)}, EFF)    # 1.4 m/s from 6 m out
                 for i in range(int(4.0 * FPS))]
    states = [d.state for d in decisions]
    first = states.index(State.LEVEL2)
    assert first > 0 and State.LEVEL1 not in states[:first]           # he keeps coming: no stop first
    # 0.6 m + 1.4 m/s x 0.9 s of his whole-body separation (predicted 0.5 s ahead)
    assert decisions[first].distance_m == pytest.approx(z.body_retract_distance_m + 1.4 * z.retract_lead_s, abs=0.1)


def test_whole_body_sees_a_hand_the_head_zones_miss():
    far_head = body_facing_arm(1.9, reach=True)                        # his head 1.9 m out, a hand 0.6 m closer
    d = settle(ready_body(WHOLE_BODY), far_head)
    assert d.state == State.NORMAL and d.speed_scale < 1.0             # slowed for the hand
    head = ZoneParams(separation="head", sizing="iso15066", iso_intrusion_m=0.0)
    assert settle(ready(head), far_head).speed_scale == 1.0


def test_the_arm_links_count_not_just_the_effector():
    # a hand beside the arm's elbow (joint j3), 0.45 m from it but 0.7 m from the end effector
    q = np.array([0.0, -1.0, 0.0, 1.0, 0.0, 0.0, 0.0])
    pts = arm_points_m(q)
    hand = pts[4] + [0.45, 0.0, 0.0]
    caps = arm_capsules(q)
    one = (hand[None], np.zeros(1))
    assert separation_m(*one, caps) == pytest.approx(0.45 - ARM_LINK_RADII_M[3], abs=0.03)
    assert separation_m(*one, effector_capsule(pts[-2])) > separation_m(*one, caps) + 0.15


# -- people the camera loses: the reachable-set rule (whole body) -------------------------------

def lose(mon, t0, frames, unseen=None, others=None):
    """``frames`` frames from ``t0`` in which person 0 is not lifted (absent, or with ``unseen``
    the reason his lift is invalid); ``others``: people still seen. The decisions."""
    out = []
    for i in range(frames):
        out.append(mon.observe(t0 + i / FPS, dict(others or {}), EFF, unseen=unseen))
    return out


def separation_of(body):
    return separation_m(*body_spheres(body), effector_capsule(EFF))


def random_body(rng, near_m=(0.3, 3.0)):
    """A random person (height, posture, place, heading) around the effector EFF, robot frame."""
    from firmware_sim.people import human

    bearing, dist = rng.uniform(-1.5, 1.5), rng.uniform(*near_m)
    posture = human.Posture(trunk_flexion_deg=rng.uniform(0, 40),   # leaning and reaching toward the arm
                            shoulder_flexion_deg=tuple(rng.uniform(0, 110, 2)),
                            knee_flexion_deg=tuple(rng.uniform(0, 30, 2))) if rng.random() < 0.5 else \
        human.Posture(hip_flexion_deg=(rng.uniform(0, 45), 0.0), knee_flexion_deg=(rng.uniform(0, 60), 0.0))
    return human.joints(human.Body.from_height(rng.uniform(1.5, 2.0)), posture,
                        pelvis_xz_m=(EFF[0] + dist * math.sin(bearing), EFF[2] + dist * math.cos(bearing)),
                        heading_rad=math.atan2(-math.sin(bearing), -math.cos(bearing)) + rng.uniform(-1, 1))


def test_a_body_with_joints_missing_is_never_placed_farther_than_he_is():
    """1-3 limb joints not known (NaN: the lifter's missing ones), and in two cases of three also a
    left-right swap of two joints he shows or a stray one (a keypoint 2.5-5 m off: another person, the
    background): the spheres that stand for him never clear the arm by more than his true body does."""
    rng = np.random.default_rng(11)
    optional = [j for j in range(17) if j not in REQUIRED_JOINTS]
    pairs = [(j, MIRROR[j]) for j in range(17) if MIRROR[j] > j]
    looser = []
    for _ in range(400):
        body = random_body(rng)
        q = rng.uniform(-1.5, 1.5, 7)
        caps = arm_capsules(q) if rng.random() < 0.7 else effector_capsule(EFF)
        truth = separation_m(*body_spheres(body), caps)
        given = body.copy()
        hide = rng.choice(optional, size=int(rng.integers(1, 4)), replace=False)
        given[hide] = np.nan
        case = rng.random()
        if case < 1 / 3:
            a, b = pairs[rng.integers(len(pairs))]
            given[[a, b]] = given[[b, a]]
        elif case < 2 / 3:
            shown = [j for j in range(1, 17) if np.isfinite(given[j]).all()]
            u = rng.normal(size=3)
            given[rng.choice(shown)] += rng.uniform(2.5, 5.0) * u / np.linalg.norm(u)
        bound = separation_m(*body_spheres(given), caps)
        assert bound <= truth + 1e-9
        if case >= 2 / 3:
            looser.append(truth - bound)
    # a bound, not a stop for everyone: with joints hidden alone, half the time within a forearm of the truth
    assert np.median(looser) < 0.35


def test_a_walker_missing_a_wrist_far_from_the_arm_keeps_it_working_and_near_it_slows_or_stops_it():
    far = body_facing_arm(4.0)
    far[16] = np.nan
    near = body_facing_arm(1.2)

    def far_then_near(z):
        mon = ready_body(z, 4.0)
        decisions = [mon.observe(1.0 + i / FPS, {0: far}, EFF) for i in range(10)]
        assert all(d.state == State.NORMAL and d.speed_scale == 1.0 for d in decisions)
        return mon.observe(2.0, {0: near}, EFF)

    d = far_then_near(WHOLE_BODY)
    assert d.state != State.NORMAL or d.speed_scale < 0.5           # shipped: a slow arm (T_s scales with it)
    assert far_then_near(FULL_SPEED_TS).state != State.NORMAL       # the full-speed T_s: stopped
    # his hidden wrist may be up to a forearm from his elbow: the bound is the elbow's, less that reach
    near[16] = np.nan
    spheres = body_spheres(near)
    assert separation_m(*spheres, effector_capsule(EFF)) <= separation_of(body_facing_arm(1.2)) + 1e-9
    assert np.isfinite(spheres[0]).all()


def test_a_person_lost_far_from_the_arm_does_not_stop_it():
    z = WHOLE_BODY
    mon = ready_body(z, 4.0)
    settle(mon, body_facing_arm(4.0))
    for t0, unseen in ((1.0, None), (3.0, {0: "missing_joints: hip"})):     # hidden, or lifted invalidly
        decisions = lose(mon, t0, 5, unseen)
        assert all(d.state == State.NORMAL for d in decisions)
        settle(mon, body_facing_arm(4.0), t0=t0 + 0.2)
    # someone else in view does not change that
    other = {1: body_facing_arm(6.0)}
    assert all(d.state == State.NORMAL for d in lose(mon, 5.0, 5, {0: "missing_joints: hip"}, other))


def halted_for_lost(d, z) -> bool:
    """The halt a lost person who could be near makes: a retraction away from where he was last seen
    (``lost_reach_retracts``, shipped) or, without it, a stop (``person_lost``)."""
    if z.lost_reach_retracts:
        return d.state == State.LEVEL2 and d.reason == "level2_retract"
    return d.state == State.LEVEL1 and d.reason.startswith("person_lost")


def test_a_person_lost_near_the_arm_slows_it_at_once_and_stops_it_with_the_full_speed_stopping_time():
    shipped = ready_body(WHOLE_BODY, 1.42)
    seen = settle(shipped, body_facing_arm(1.42))
    lost = lose(shipped, 1.0, 2, {0: "missing_joints: left_hip"})[-1]
    assert lost.state != State.NORMAL or lost.speed_scale < seen.speed_scale   # his reachable set, not his last pose
    z = FULL_SPEED_TS
    body = body_facing_arm(1.42)                                     # the arm crawls for him but works
    mon = ready_body(z, 1.42)
    assert settle(mon, body).state == State.NORMAL
    d = lose(mon, 1.0, 2, {0: "missing_joints: left_hip"})[-1]
    assert halted_for_lost(d, z)
    # he is seen again a step back (beyond the exit hysteresis): the arm works again, judged on him
    assert settle(mon, body_facing_arm(1.7), t0=2.0, seconds=z.dwell_s + 0.5).state == State.NORMAL


def test_a_person_never_lifted_validly_stops_the_arm():
    z = WHOLE_BODY
    mon = ready_body(z, 6.0)
    d = mon.observe(1.0, {0: body_facing_arm(6.0)}, EFF, unseen={1: "missing_joints: right_ankle"})
    assert d.state == State.FAULT and d.reason.startswith("person_unseen: person 1")


@pytest.mark.parametrize("retracts", [True, False])
def test_a_lost_person_stops_the_arm_once_his_reachable_set_gets_within_the_protective_distance(retracts):
    z = replace(WHOLE_BODY, lost_reach_retracts=retracts)
    body = body_facing_arm(3.0)
    mon = ready_body(z, 3.0)
    settle(mon, body)
    # how long he can be out of sight before, at the worst-case speed, he could be within S_p
    slack = separation_of(body) - z.body_protective_distance_m(z.min_speed_fraction * z.iso_robot_speed_mps,
                                                                z.lost_person_speed_mps)
    bound_s = slack / z.lost_person_speed_mps
    assert 0.1 < bound_s < z.lost_hold_s
    decisions = lose(mon, 1.0, int((bound_s + 0.3) * FPS))
    t = [1.0 + i / FPS for i in range(len(decisions))]
    before = [d for d, ti in zip(decisions, t) if ti - (1.0 - 1 / FPS) < bound_s - 0.05]
    after = [d for d, ti in zip(decisions, t) if ti - (1.0 - 1 / FPS) > bound_s + 0.05]
    assert before and all(d.state == State.NORMAL for d in before)
    assert after and all(halted_for_lost(d, z) for d in after)
    assert before[-1].speed_scale < 1.0                              # slowing down while the set grows


def test_a_lost_person_is_forgotten_after_the_hold_and_the_scene_clears():
    z = WHOLE_BODY
    mon = ready_body(z, 1.42)
    settle(mon, body_facing_arm(1.42))
    held = lose(mon, 1.0, int((z.lost_hold_s - 0.2) * FPS))
    assert halted_for_lost(held[-1], z)
    d = lose(mon, 1.0 + z.lost_hold_s, int((z.dwell_s + 0.5) * FPS))[-1]
    assert d.state == State.NORMAL and d.speed_scale == 1.0


def test_head_zones_treat_a_person_lifted_invalidly_as_an_invalid_frame():
    mon = ready()
    d = mon.observe(1.0, {0: head_at(6.0)}, EFF, unseen={1: "missing_joints: head"})
    assert d.state == State.FAULT and d.reason.startswith("pose_invalid: person 1")


# -- people seen in 2D but not lifted: bounded by their keypoints' rays (whole body) -------------

CAMERA_M = np.array([0.0, 1.6, 8.0])
"""A camera 2.5 m above the floor, 8 m out on the +z side, behind the workers facing the arm."""
FLOOR_Y = -0.914


def rays_of(body, camera_m=CAMERA_M, hide=()):
    """PersonRays of a body's joints seen from ``camera_m`` (the joints in ``hide`` not seen)."""
    d = np.asarray(body, float) - camera_m
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    d[list(hide)] = np.nan
    return PersonRays(np.asarray(camera_m, float), d, FLOOR_Y)


@pytest.mark.parametrize("keypoint_error_m", [0.0, RAY_KEYPOINT_ERROR_M])
def test_the_ray_bound_never_exceeds_the_true_separation(keypoint_error_m):
    """Exact keypoints, and keypoints up to RAY_KEYPOINT_ERROR_M off their joints on the body (a real detector's
    error: the bound of main before session 12 was above the truth for 1 case in 10 of these)."""
    from firmware_sim.people import human

    rng = np.random.default_rng(3)
    caps = effector_capsule(EFF)
    checked = 0
    for _ in range(200):
        h = rng.uniform(1.5, 2.0)
        bearing, dist = rng.uniform(-1.2, 1.2), rng.uniform(1.2, 5.0)
        posture = human.Posture(trunk_flexion_deg=rng.uniform(0, 40),   # leaning and reaching toward the arm
                                shoulder_flexion_deg=tuple(rng.uniform(0, 110, 2)),
                                knee_flexion_deg=tuple(rng.uniform(0, 30, 2))) if rng.random() < 0.5 else \
            human.Posture(hip_flexion_deg=(rng.uniform(0, 45), 0.0), knee_flexion_deg=(rng.uniform(0, 60), 0.0))  # a step
        body = human.joints(human.Body.from_height(h), posture,
                            pelvis_xz_m=(EFF[0] + dist * math.sin(bearing), EFF[2] + dist * math.cos(bearing)),
                            heading_rad=math.atan2(-math.sin(bearing), -math.cos(bearing)) + rng.uniform(-1, 1))
        cam = np.array([rng.uniform(-4, 4), rng.uniform(0.1, 2.1), rng.uniform(4, 9)])
        hide = rng.choice(17, size=int(rng.integers(0, 5) if rng.random() < 0.6 else rng.integers(13, 17)),
                          replace=False)  # a few joints hidden, or all but one to four (at the picture's edge)
        off = rng.normal(size=body.shape)
        off *= keypoint_error_m * rng.uniform(0, 1, (17, 1)) ** (1 / 3) / np.linalg.norm(off, axis=1, keepdims=True)
        bound = ray_separation_m(rays_of(body + off, cam, hide), caps, WHOLE_BODY)
        if bound is not None:
            checked += 1
            assert bound[0] <= separation_of(body) + 1e-9
    assert checked > 150


LIFTED_STAND_DEPTH_SD = 0.05
"""How far (relative, 1 sd) the lifted depth of a calibration stand is off: what turns a rigid fit by the
4-6 degrees measured at a real detector's noise (reports/robot/head_error.md: median 4.4-5.3 deg)."""


def _fitted_camera(rng, method: str):
    """A camera 3-8 m from the markers and 1-3 m above the floor, looking at them, and the calibration the
    runtime fits for it from a worker on the markers whose lifted depth is off by LIFTED_STAND_DEPTH_SD per
    stand and each head and ankle 3 cm across its ray: (camera centre, robot -> camera rotation, calibration)."""
    from edge_runtime.robot.calibration import CalibrationParams, fit, targets
    from firmware_sim.devices.camera import Camera

    bearing, dist = rng.uniform(-1.2, 1.2), rng.uniform(3, 8)
    camera = Camera.look_at([0.3 + dist * math.sin(bearing), FLOOR_Y + rng.uniform(1.0, 3.0), 1.5 + dist * math.cos(bearing)],
                            target_m=[0.3, FLOOR_Y + 0.8, 1.5])
    params = CalibrationParams(method=method)
    heads, ankles = (camera.to_camera(p) for p in targets(params, rng.uniform(1.45, 1.85)))
    depth = 1 + LIFTED_STAND_DEPTH_SD * rng.standard_normal((3, 1))
    heads, ankles = ((p + 0.03 * rng.standard_normal(p.shape)) * depth for p in (heads, ankles))
    return camera.position_m, camera.R, fit(heads, ankles, params)


def body_near_arm(rng) -> tuple[np.ndarray, np.ndarray]:
    """A person whose pelvis is 0.6-4 m from the effector, facing anywhere, leaning up to 30 degrees, and
    his keypoints, each up to RAY_KEYPOINT_ERROR_M off its joint: (joints, keypoints), robot frame."""
    from firmware_sim.people import human

    bearing, dist = rng.uniform(-math.pi, math.pi), rng.uniform(0.6, 4.0)
    body = human.joints(human.Body.from_height(rng.uniform(1.5, 2.0)), human.Posture(trunk_flexion_deg=rng.uniform(0, 30)),
                        pelvis_xz_m=(EFF[0] + dist * math.sin(bearing), EFF[2] + dist * math.cos(bearing)),
                        heading_rad=rng.uniform(-math.pi, math.pi))
    off = rng.normal(size=body.shape)
    off *= RAY_KEYPOINT_ERROR_M * rng.uniform(0, 1, (17, 1)) ** (1 / 3) / np.linalg.norm(off, axis=1, keepdims=True)
    return body, body + off


def _over_truth_through_fitted_calibrations(method: str, seed: int) -> tuple[list[float], int]:
    """Ray bound minus true separation of people near the arm seen through 12 fitted calibrations."""
    rng = np.random.default_rng(seed)
    caps = effector_capsule(EFF)
    over, checked = [], 0
    for _ in range(12):
        cam, R, cal = _fitted_camera(rng, method)
        for _ in range(25):
            body, keypoints = body_near_arm(rng)
            seen_cam = (keypoints - cam) @ R.T
            if (seen_cam[:, 2] < 0.3).any():
                continue
            d = seen_cam @ cal.A.T                                   # the runtime's rays: through the fitted pose
            d /= np.linalg.norm(d, axis=1, keepdims=True)
            bound = ray_separation_m(PersonRays(cal.b.copy(), d, FLOOR_Y), caps, WHOLE_BODY)
            if bound is not None:
                checked += 1
                over.append(bound[0] - separation_of(body))
    return over, checked


def test_the_ray_bound_through_a_fitted_calibration():
    """The ray bound takes the calibrated camera as exact. The shipped pnp fit, made from the markers' rays,
    keeps it below the truth for people near the arm; rigid, which leans on the lifter's depths, turns the
    camera by degrees and puts some of them metres beyond (reports/robot/ray_bound_s13.md: through 30 fitted
    calibrations of head-error development placements, 34 of 1,177 bodies above the truth with rigid, up to
    4.6 m; 0 of 1,190 with pnp)."""
    rigid_over = []
    for seed in range(4):
        over, checked = _over_truth_through_fitted_calibrations("pnp", seed)
        assert checked > 200 and max(over) <= 1e-9, seed
        rigid_over.append(max(_over_truth_through_fitted_calibrations("rigid", seed)[0]))
    assert max(rigid_over) > 0.1  # the check can fail: the fit the product shipped before session 13 fails it


def test_anchored_rays_bound_a_person_within_his_body_extent_of_where_he_stands():
    caps = effector_capsule(EFF)
    body = body_facing_arm(4.0)
    sep = separation_of(body)
    d, point = ray_separation_m(rays_of(body), caps, WHOLE_BODY)
    # the region reaches toward the arm by at most the body extent, the ankle band's spread on the floor and the
    # keypoints' error (twice: the foot off its ray, the joint off its own)
    assert sep - WHOLE_BODY.ray_body_extent_m - 2 * RAY_KEYPOINT_ERROR_M - 0.4 < d < sep
    assert point is not None and point[2] > EFF[2]                     # where he stands: his side
    # ankles alone (the rest hidden): looser; no ankle seen: his hips and head bound him
    only_feet = [j for j in range(17) if j not in (3, 6)]
    d_feet, _ = ray_separation_m(rays_of(body, hide=only_feet), caps, WHOLE_BODY)
    assert sep - WHOLE_BODY.ray_body_extent_m - 2 * RAY_KEYPOINT_ERROR_M - 0.6 < d_feet <= d
    d_upper, _ = ray_separation_m(rays_of(body, hide=(3, 6)), caps, WHOLE_BODY)
    assert d_upper < sep
    # no ankle, hip, pelvis or head: any joint he shows is between the floor and a raised wrist, the rest within
    # its bones of it: a looser bound, still below the truth
    d_rest, _ = ray_separation_m(rays_of(body, hide=(0, 1, 3, 4, 6, 10)), caps, WHOLE_BODY)
    assert d_rest < sep
    only_wrist = [j for j in range(17) if j != 16]
    d_wrist, _ = ray_separation_m(rays_of(body, hide=only_wrist), caps, WHOLE_BODY)
    assert sep - 2 * JOINT_REACH_M[16].max() - 1.0 < d_wrist < d_rest
    # a ray that never meets the floor or the heights a joint can be at bounds nothing
    level = np.array([0.0, FLOOR_Y + WHOLE_BODY.ray_joint_heights_m[1] + 1.0, 8.0])   # a camera above every joint
    flat = rays_of(body, level, hide=only_wrist)
    flat.directions[16] = [0.0, 0.0, -1.0]
    assert ray_separation_m(flat, caps, WHOLE_BODY) is None


def test_a_person_never_lifted_far_along_his_rays_does_not_stop_the_arm():
    z = WHOLE_BODY
    mon = ready_body(z, 6.0)
    d = mon.observe(1.0, {0: body_facing_arm(6.0)}, EFF, unseen={1: "missing_joints: right_wrist"},
                    rays={1: rays_of(body_facing_arm(4.0), hide=(16,))})
    assert d.state == State.NORMAL
    # without the ray bound (or without rays) he stops it, as before
    mon = ready_body(replace(z, ray_bound=False), 6.0)
    d = mon.observe(1.0, {0: body_facing_arm(6.0)}, EFF, unseen={1: "missing_joints: right_wrist"},
                    rays={1: rays_of(body_facing_arm(4.0), hide=(16,))})
    assert d.state == State.FAULT and d.reason.startswith("person_unseen: person 1")


@pytest.mark.parametrize("z", [WHOLE_BODY, FULL_SPEED_TS], ids=["shipped", "full_speed_ts"])
def test_a_person_never_lifted_whose_ray_region_reaches_the_protective_distance_stops_the_arm(z):
    v_stop = z.min_speed_fraction * z.iso_robot_speed_mps
    seen = set()
    for sep in (1.5, 2.0, 2.5, 3.0, 3.2, 3.4, 3.6, 3.8, 4.0, 5.0):
        mon = ready_body(z, 6.0)
        rays = rays_of(body_facing_arm(sep))
        bound = ray_separation_m(rays, effector_capsule(EFF), z)[0]
        stops = z.allowed_speed_mps(bound, z.lost_person_speed_mps) < v_stop
        d = mon.observe(1.0, {0: body_facing_arm(6.0)}, EFF, unseen={1: "missing_joints: right_wrist"}, rays={1: rays})
        if not stops:
            assert d.state == State.NORMAL, sep
        elif bound > z.reach_retract_m:
            assert d.state == State.LEVEL1 and d.reason.startswith("person_unlifted: 1"), sep
        else:
            assert d.state == State.LEVEL2, sep
        seen.add(d.state)
    # every case met, far ones work on; with T_s scaling, S_p at the slowest speed (0.71 m) is within the
    # reach (0.85 m), so the arm never stops for him: it works slowly, then retracts
    assert seen == ({State.NORMAL, State.LEVEL2} if z.stop_time_scales else {State.NORMAL, State.LEVEL1, State.LEVEL2})
    # close enough to reach the arm by his rays alone: the arm retracts away from him
    mon = ready_body(z, 6.0)
    d = mon.observe(1.0, {0: body_facing_arm(6.0)}, EFF, unseen={1: "x"}, rays={1: rays_of(body_facing_arm(0.9))})
    assert d.state == State.LEVEL2 and d.worker == 1 and d.head.position_m[2] > EFF[2]


def test_a_ray_bound_shrinks_like_a_lost_persons_reachable_set_when_his_rays_stop_bounding_him():
    z = WHOLE_BODY
    mon = ready_body(z, 6.0)
    rays = rays_of(body_facing_arm(4.0))
    bound = ray_separation_m(rays, effector_capsule(EFF), z)[0]
    assert mon.observe(1.0, {}, EFF, unseen={1: "x"}, rays={1: rays}).state == State.NORMAL
    # then he is out of view (or shows no usable ankle or head): the bound shrinks at his and the arm's speed
    slack = bound - z.body_protective_distance_m(z.min_speed_fraction * z.iso_robot_speed_mps, z.lost_person_speed_mps)
    grow_s = slack / (z.lost_person_speed_mps + z.iso_robot_speed_mps)
    assert 0.05 < grow_s < z.lost_hold_s
    assert mon.observe(1.0 + grow_s - 0.04, {}, EFF, unseen={1: "x"}).state == State.NORMAL
    d = mon.observe(1.0 + grow_s + 0.04, {}, EFF)
    assert d.state == State.LEVEL1 and d.reason.startswith("person_unlifted: 1")


FOLDED_Q = np.array([0.0, -0.3, 0.0, 2.2, 0.0, 0.6, 0.0])
"""A retracted Sawyer: the hand 0.28 m from the base's axis, the elbow 0.49 m out."""


def test_a_turn_of_the_base_is_its_first_joint_alone():
    caps = arm_capsules(FOLDED_Q)
    for turn in (0.7, -2.1):
        q = FOLDED_Q + [turn, 0, 0, 0, 0, 0, 0]
        for got, want in zip(turned_capsules(caps, turn), arm_capsules(q)):
            assert np.allclose(got, want, atol=1e-12)
        hand = arm_points_m(FOLDED_Q)[-2]
        r = turned_retraction(hand, 0.2, turn)
        assert np.allclose(r.position_m, arm_points_m(q)[-2], atol=1e-12)   # where the hand goes: j0 turned
        assert r.yaw_rad == pytest.approx(0.2 + turn)                        # the tool turns with it


def spheres(people):
    """Each person's body spheres, as the planner takes them."""
    return [body_spheres(p) for p in people]


def sweep_m(caps, people, turn_rad, step_deg=0.25):
    """The separation (m) of each of ``people`` from the arm along its turn about the base, finely sampled:
    (samples, people)."""
    turns = np.linspace(0.0, turn_rad, int(abs(math.degrees(turn_rad)) / step_deg) + 2)
    return np.array([[separation_m(c, r, turned_capsules(caps, a)) for c, r in spheres(people)] for a in turns])


@pytest.mark.parametrize("second", [False, True], ids=["alone", "a_colleague_behind_the_base"])
def test_the_escape_turn_never_sweeps_through_a_worker_standing_at_the_arms_side(second):
    caps = arm_capsules(FOLDED_Q)
    hand_bearing = math.degrees(math.atan2(*arm_points_m(FOLDED_Q)[-2][[0, 2]]))
    turned = 0
    for bearing in range(-180, 180, 15):   # he stands beside the folded arm, all round it, within reach
        b = math.radians(hand_bearing + bearing)
        people = [anchored_worker((0.9 * math.sin(b), 0.9 * math.cos(b)), heading=b + math.pi)]
        if second:  # and another one 1.6 m out on the far side of the base from him
            people.append(anchored_worker((-1.6 * math.sin(b), -1.6 * math.cos(b)), heading=b))
        here = sweep_m(caps, people, 0.0)[0]
        turn = plan_escape_turn(caps, spheres(people), 0.0, 5.0, 0.05, 0.02, 180.0)
        if turn is None:
            continue
        turned += 1
        path = sweep_m(caps, people, turn)
        assert path[-1].min() >= here.min() + 0.05                       # clearer of everyone where it ends
        assert (path.min(axis=0) >= here - 0.02 - 0.01).all(), bearing  # nobody nearer on its way (0.01: sampling)
        assert abs(FOLDED_Q[0] + turn) <= math.radians(170.0) + 1e-9
    assert turned >= 8   # with him in front of the arm or beside it, it turns away


def test_the_escape_turn_goes_the_long_way_round_rather_than_across_him():
    # he stands at the side the arm would turn to first on the short way to the clearest end
    caps = arm_capsules(FOLDED_Q)
    hand = arm_points_m(FOLDED_Q)[-2]
    b = math.atan2(hand[0], hand[2]) + math.radians(70.0)
    him = anchored_worker((0.9 * math.sin(b), 0.9 * math.cos(b)), heading=b + math.pi)
    turn = plan_escape_turn(caps, spheres([him]), 0.0, 5.0, 0.05, 0.02, 180.0)
    assert turn is not None and turn < 0                                  # away from him
    assert sweep_m(caps, [him], math.radians(70.0)).min() < sweep_m(caps, [him], 0.0)[0, 0] - 0.1  # toward him: nearer
    # within the joint's range: from j0 at -168 deg the turn away from him has no room, and toward him it passes nearer
    assert plan_escape_turn(caps, spheres([him]), math.radians(-168.0), 5.0, 0.05, 0.02, 180.0) is None
    assert plan_escape_turn(caps, [], 0.0, 5.0, 0.05, 0.02, 180.0) is None  # nobody to escape from
    assert plan_escape_turn(caps, spheres([him]), 0.0, 5.0, 0.05, 0.02, 0.0) is None  # escape_deg 0: never


def test_the_escape_plan_counts_a_lost_person_by_how_far_he_can_have_come_and_none_known_by_rays_alone():
    z = WHOLE_BODY
    mon = ready_body(z, 6.0)   # worker 0, seen at 6 m until t = -10 + dwell
    t_seen = mon._last_pose_s
    (centres, radii), = mon.escape_people(sweep_m=0.65)
    assert np.allclose(radii, body_spheres(body_facing_arm(6.0))[1])  # seen in the last frame: his body as it is
    # a frame without him 0.5 s later: lost, each sphere grown by his reach since (lost_person_speed_mps at least)
    mon.observe(t_seen + 0.5, {}, EFF)
    (_, grown), = mon.escape_people(sweep_m=0.65)
    assert np.allclose(grown - radii, 0.5 * z.lost_person_speed_mps)
    # someone in view whom the lifter never lifted, bounded only by his keypoints' rays, within reach of the arm
    # or of where the turn carries it: no plan can be shown to clear him in a frame's time, so none is made
    for sep, sweep_m in ((2.5, 0.0), (3.4, 0.65)):
        rays = rays_of(body_facing_arm(sep))
        bound = ray_separation_m(rays, effector_capsule(EFF), z)[0]
        assert (bound <= z.reach_retract_m) == (sweep_m == 0.0) and bound <= z.reach_retract_m + sweep_m
        near = ready_body(z, 6.0)
        near.observe(near._last_pose_s + 0.1, {0: body_facing_arm(6.0)}, EFF, unseen={1: "x"}, rays={1: rays})
        assert near.escape_people(sweep_m) is None
        assert len(near.escape_people(0.0 if sweep_m else -1.0)) == 1     # beyond a shorter sweep he does not count
    # far beyond reach he does not stop the planning
    far = ready_body(z, 6.0)
    far.observe(far._last_pose_s + 0.1, {0: body_facing_arm(6.0)}, EFF, unseen={1: "x"},
                rays={1: rays_of(body_facing_arm(5.0))})
    assert len(far.escape_people(sweep_m=0.65)) == 1


def test_the_escape_turn_keeps_each_worker_as_clear_as_he_is_or_out_of_reach_not_only_the_nearest():
    caps = arm_capsules(FOLDED_Q)
    hand = arm_points_m(FOLDED_Q)[-2]
    b = math.atan2(hand[0], hand[2])
    him = anchored_worker((0.9 * math.sin(b), 0.9 * math.cos(b)), heading=b + math.pi)   # at the folded arm's front
    REACH_M = WHOLE_BODY.reach_retract_m  # noqa: N806
    checked = 0
    for side in range(30, 181, 10):   # a colleague further out, anywhere round the base
        for sign in (1, -1):
            c = b + sign * math.radians(side)
            colleague = anchored_worker((1.25 * math.sin(c), 1.25 * math.cos(c)), heading=c + math.pi)
            here = sweep_m(caps, [him, colleague], 0.0)[0]
            turn = plan_escape_turn(caps, spheres([him, colleague]), 0.0, 5.0, 0.05, 0.02, 180.0, REACH_M)
            if turn is None:
                continue
            checked += 1
            path = sweep_m(caps, [him, colleague], turn)
            # neither nearer on its way than he is or than reach_retract_m (0.01: the 5 deg sampling)
            assert (path.min(axis=0) >= np.minimum(here, REACH_M) - 0.02 - 0.01).all(), (side, sign)
    assert checked >= 10


def test_a_lost_person_in_view_within_reach_by_his_rays_makes_the_arm_retract_away_from_him():
    z = WHOLE_BODY
    mon = ready_body(z, 3.0)
    settle(mon, body_facing_arm(3.0))
    # his lift goes invalid while he walks up to the tool: 1.5 s later his rays show him within reach
    d = mon.observe(2.5, {}, EFF, unseen={0: "missing_joints: left_wrist"}, rays={0: rays_of(body_facing_arm(0.6))})
    assert d.state == State.LEVEL2 and d.worker == 0 and d.head.position_m[2] > EFF[2]



def test_a_lost_person_who_would_stop_the_arm_makes_it_retract_away_from_where_he_was_last_seen():
    body = body_facing_arm(1.42)
    for z, expect in ((replace(FULL_SPEED_TS, lost_reach_retracts=False), State.LEVEL1), (FULL_SPEED_TS, State.LEVEL2)):
        mon = ready_body(z, 1.42)
        assert settle(mon, body).state == State.NORMAL
        d = lose(mon, 1.0, 2)[-1]                                     # hidden, no rays: his reachable set stops it
        assert d.state == expect
        if expect == State.LEVEL2:                                    # away from his last head: it is beyond the tool
            assert d.worker == 0 and d.head.position_m[2] > EFF[2]
            assert np.array_equal(d.head.position_m, body[HEAD])
        else:
            assert d.reason.startswith("person_lost")
    # far out, his reachable set stops nothing, and it retracts nothing either
    z = WHOLE_BODY
    assert z.lost_reach_retracts                                       # shipped
    mon = ready_body(z, 4.0)
    settle(mon, body_facing_arm(4.0))
    assert all(d.state == State.NORMAL for d in lose(mon, 1.0, 5))


def test_a_lost_persons_ray_bound_beyond_what_his_track_allows_is_not_heard():
    z = FULL_SPEED_TS                        # where his reachable set 1.42 m out stops the arm at once
    mon = ready_body(z, 1.42)
    settle(mon, body_facing_arm(1.42))
    # his lift goes invalid and his keypoints put him 5 m out a frame later: he cannot have gone that far (a
    # keypoint on the wrong person, a miscalibrated ray); his reachable set, not that bound, stops the arm
    far = {0: rays_of(body_facing_arm(5.0))}
    d = mon.observe(1.0, {}, EFF, unseen={0: "missing_joints: left_hip"}, rays=far)
    assert halted_for_lost(d, z) and np.array_equal(d.head.position_m, body_facing_arm(1.42)[HEAD])
    assert mon.bounds_refused == 1
    # rays his track allows (he stands where he was last lifted) are heard: they keep him off the arm after his
    # reachable set alone would have stopped it (4.5 m out, that set reaches the protective distance in 1.5 s)
    mon2 = ready_body(z, 4.5)
    settle(mon2, body_facing_arm(4.5))
    same = {0: rays_of(body_facing_arm(4.5))}
    held = [mon2.observe(1.0 + i / FPS, {}, EFF, unseen={0: "missing_joints: left_hip"}, rays=same)
            for i in range(int((z.lost_hold_s - 0.1) * FPS))]
    assert mon2.bounds_refused == 0
    assert all(d.state == State.NORMAL for d in held)


@pytest.mark.parametrize("scaling", [True, False])
def test_after_a_retraction_speed_scaling_resumes_after_its_own_dwell_and_stop_only_after_dwell_s(scaling):
    """``scaled_dwell_s`` is the wait before a speed-scaled arm works again (it resumes at the speed the
    separation allows); stop-only, which resumes at full speed, keeps ``dwell_s``."""
    z = replace(WHOLE_BODY, speed_scaling=scaling, dwell_s=1.0, scaled_dwell_s=0.3)
    mon = ready_body(z, 3.0)
    assert settle(mon, body_facing_arm(0.3), seconds=0.5).state == State.LEVEL2      # within reach: retract
    t0 = 0.5
    for k in range(int(2.0 * FPS)):                                       # he steps back to 3 m
        if mon.observe(t0 + k / FPS, {0: body_facing_arm(3.0)}, EFF).state == State.NORMAL:
            break
    assert k / FPS == pytest.approx(z.scaled_dwell_s if scaling else z.dwell_s, abs=1.5 / FPS)
