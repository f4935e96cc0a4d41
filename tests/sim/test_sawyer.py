"""The simulated Sawyer arm: kinematics, inverse kinematics, limited motion, collision spheres."""
from __future__ import annotations

import math

import numpy as np
import pytest

from firmware_sim.robot.sawyer import (
    FLOOR_Y_M,
    HOME_RAD,
    LOWER_RAD,
    UPPER_RAD,
    ArmConfig,
    SawyerArm,
    Unreachable,
    angle_between_rad,
    collision_spheres,
    direction_from_pitch_yaw,
    end_effector_pose,
    forward_kinematics,
    jacobian,
    pitch_yaw_from_direction,
    posture_is_clear,
)

DT = 0.01


def random_reachable(arm: SawyerArm, rng, n: int) -> list[tuple[np.ndarray, float, float]]:
    """Targets made from random joint angles that keep the arm clear of the floor and pedestal."""
    out = []
    while len(out) < n:
        q = rng.uniform(LOWER_RAD, UPPER_RAD)
        if posture_is_clear(q, arm.config):
            pose = end_effector_pose(q)
            out.append((pose.position_m, *pose.pitch_yaw_rad))
    return out


def run_to_rest(arm: SawyerArm, max_steps: int = 3000) -> list:
    recs = []
    for _ in range(max_steps):
        recs.append(arm.step(DT))
        if not arm.moving and (arm.goal_rad is None or arm.at_goal):
            break
    return recs


def test_robot_frame_is_the_cyclic_permutation_of_the_urdf_base():
    q = np.zeros(7)
    hand = forward_kinematics(q)[-1]
    pose = end_effector_pose(q)
    urdf_p = hand[:3, 3]
    assert np.allclose(pose.position_m, [urdf_p[1], urdf_p[2], urdf_p[0]])
    # the stretched-out arm reaches forward: +x in the URDF, +z (work side) in the robot frame
    assert pose.position_m[2] > 0.9 and abs(pose.position_m[1]) < 0.5
    assert np.linalg.det(np.array([[0, 1, 0], [0, 0, 1], [1, 0, 0]])) == 1  # right-handed


def test_jacobian_matches_finite_differences():
    q = HOME_RAD + np.array([0.3, -0.2, 0.5, -0.4, 0.7, 0.2, -0.6])
    pose, jp, jd = jacobian(q)
    eps = 1e-6
    for i in range(7):
        dq = np.zeros(7)
        dq[i] = eps
        p2 = end_effector_pose(q + dq)
        assert np.allclose((p2.position_m - pose.position_m) / eps, jp[:, i], atol=1e-5)
        assert np.allclose((p2.direction - pose.direction) / eps, jd[:, i], atol=1e-5)


@pytest.mark.parametrize("pitch,yaw", [(0.0, 0.0), (0.4, -2.5), (-1.2, 3.0), (1.0, 0.7)])
def test_pitch_yaw_round_trip(pitch, yaw):
    d = direction_from_pitch_yaw(pitch, yaw)
    assert abs(np.linalg.norm(d) - 1) < 1e-12
    assert np.allclose(pitch_yaw_from_direction(d), (pitch, yaw))
    assert direction_from_pitch_yaw(0.0, math.pi / 2)[0] == pytest.approx(1.0)  # yaw +90 deg points to +x


def test_ik_reproduces_random_reachable_targets():
    rng = np.random.default_rng(7)
    arm = SawyerArm()
    targets = random_reachable(arm, rng, 30)
    solved = 0
    for p, pitch, yaw in targets:
        try:
            q = arm.solve_ik(p, pitch, yaw)
        except Unreachable:
            continue
        solved += 1
        pose = end_effector_pose(q)
        assert np.linalg.norm(pose.position_m - p) <= 1e-3
        assert math.degrees(angle_between_rad(pose.direction, direction_from_pitch_yaw(pitch, yaw))) <= 1.0
        assert np.all(q >= LOWER_RAD) and np.all(q <= UPPER_RAD)
    assert solved >= 0.95 * len(targets)


@pytest.mark.parametrize("target", [
    ((0.0, 0.3, 1.6), 0.0, 0.0),          # beyond the reach
    ((0.5, -0.9, 0.5), -1.5, 0.0),        # below the floor clearance
    ((0.0, -0.5, 0.05), 0.0, 0.0),        # inside the pedestal
    ((float("nan"), 0.2, 0.5), 0.0, 0.0),  # not a number
    ((0.0, 1.25, 0.0), -math.pi / 2, 0.0),  # at the top of the reach but pointing down: no posture does it
])
def test_out_of_reach_targets_are_refused_and_nothing_moves(target):
    arm = SawyerArm()
    arm.set_target((0.5, 0.2, 0.5), 0.0, 0.0)
    goal = arm.goal_rad.copy()
    q = arm.q_rad.copy()
    with pytest.raises(Unreachable):
        arm.set_target(*target)
    assert np.array_equal(arm.goal_rad, goal) and np.array_equal(arm.q_rad, q)


def check_trajectory(arm: SawyerArm, qs: np.ndarray) -> None:
    v = np.diff(qs, axis=0) / DT
    a = np.diff(v, axis=0) / DT
    vmax = np.asarray(arm.config.max_vel_radps)
    amax = np.asarray(arm.config.max_acc_radps2)
    assert np.all(np.abs(v) <= vmax * (1 + 1e-9))
    assert np.all(np.abs(a) <= amax * (1 + 1e-6))
    assert np.all(qs >= LOWER_RAD) and np.all(qs <= UPPER_RAD)


def test_stepped_motion_respects_velocity_acceleration_and_cartesian_limits():
    rng = np.random.default_rng(3)
    arm = SawyerArm()
    reached = 0
    for p, pitch, yaw in random_reachable(arm, rng, 8):
        try:
            arm.set_target(p, pitch, yaw)
        except Unreachable:
            continue
        qs = [arm.q_rad.copy()]
        recs = run_to_rest(arm)
        qs += [r.q_rad for r in recs]
        check_trajectory(arm, np.array(qs))
        # from rest, the hand never goes faster than the Cartesian limit
        hand = np.array([end_effector_pose(q).position_m for q in qs])
        assert np.max(np.linalg.norm(np.diff(hand, axis=0), axis=1) / DT) <= arm.config.max_cartesian_speed_mps * 1.005
        assert max(r.ee_speed_mps for r in recs) <= arm.config.max_cartesian_speed_mps * (1 + 1e-6)
        reached += arm.at_goal
        assert not arm.at_goal or np.linalg.norm(arm.pose().position_m - p) <= 1e-3
    assert reached >= 6


def test_retargeting_mid_motion_keeps_the_joint_limits():
    rng = np.random.default_rng(11)
    arm = SawyerArm()
    qs = [arm.q_rad.copy()]
    for p, pitch, yaw in random_reachable(arm, rng, 10):
        try:
            arm.set_target(p, pitch, yaw)
        except Unreachable:
            continue
        for _ in range(int(rng.integers(20, 120))):  # a new target arrives while the arm moves
            qs.append(arm.step(DT).q_rad)
    check_trajectory(arm, np.array(qs))


def test_stop_decelerates_to_rest_within_the_limits():
    arm = SawyerArm(ArmConfig())
    arm.set_target((0.6, 0.1, -0.4), 0.0, math.pi)
    qs = [arm.q_rad.copy()]
    for _ in range(40):
        qs.append(arm.step(DT).q_rad)
    speed_before = float(np.max(np.abs(arm.qd_radps)))
    assert speed_before > 0.3
    arm.clear_target()
    recs = run_to_rest(arm, 200)
    qs += [r.q_rad for r in recs]
    check_trajectory(arm, np.array(qs))
    assert not arm.moving
    worst = float(np.max(np.asarray(arm.config.max_vel_radps) / np.asarray(arm.config.max_acc_radps2)))
    assert len(recs) * DT <= worst + 2 * DT


def test_collision_spheres_cover_the_chain_and_follow_the_joints():
    arm = SawyerArm()
    centres, radii = arm.collision_spheres()
    assert centres.shape == (len(radii), 3) and len(radii) > 10
    assert radii.min() == pytest.approx(0.035) and radii.max() == pytest.approx(0.08)
    assert np.all((radii >= 0.035) & (radii <= 0.08))
    gaps = np.linalg.norm(np.diff(centres, axis=0), axis=1)
    assert np.all(gaps <= radii[:-1] + radii[1:])  # consecutive spheres overlap: no hole in the chain
    hand = arm.pose().position_m
    assert np.min(np.linalg.norm(centres - hand, axis=1)) < 1e-9
    assert np.all(centres[:, 1] - radii >= FLOOR_Y_M)
    q2 = arm.q_rad + np.array([0.5, 0, 0, 0, 0, 0, 0])
    c2, _ = collision_spheres(q2)
    assert np.linalg.norm(c2[-1] - centres[-1]) > 0.05


def test_a_speed_limit_slows_every_motion_and_zero_holds_the_arm():
    arm = SawyerArm()
    arm.set_speed_limit(0.15)
    arm.set_target((0.3, 0.2, 0.7), 0.0, 0.0)
    recs = run_to_rest(arm)
    assert arm.at_goal and max(r.ee_speed_mps for r in recs) <= 0.15 * (1 + 1e-6)
    assert len(recs) * DT > np.linalg.norm(np.subtract((0.3, 0.2, 0.7), end_effector_pose(HOME_RAD).position_m)) / 0.15
    arm.set_speed_limit(5.0)                                   # never above the arm's own limit
    assert arm.speed_limit_mps == arm.config.max_cartesian_speed_mps
    arm.set_speed_limit(0.0)
    q = arm.q_rad.copy()
    arm.set_target((0.0, 0.3, 0.6), 0.0, 0.0)
    run_to_rest(arm, 100)
    assert np.allclose(arm.q_rad, q)


@pytest.mark.parametrize("share", [1.0, 0.6, 0.3, 0.1])
def test_the_runtimes_stopping_model_covers_the_arm_at_every_speed(share):
    """The runtime's speed-dependent T_s(v_r) and S_s = v_r T_s / 2 ([zones] stop_time_scales,
    hazard.ZoneParams.stop_time_s, shipped since session 14; ISO/TS 15066 speed and separation
    monitoring) are at least what the arm needs to stop from a speed override of ``share`` x full
    speed while it does the cell's task (between its waypoints, where the runtime scales its speed): time
    to rest, and how far any of its collision spheres travels meanwhile."""
    from firmware_sim.scenarios.hrc_world import box_config, hard_scenarios, task_start_posture

    zones, loop = box_config().zones, box_config().robot_loop
    v_r = share * zones.iso_robot_speed_mps
    t_s = zones.stop_time_s(v_r)
    task = hard_scenarios(1, 0)[0].task_m
    rng = np.random.default_rng(int(share * 10))
    for k in range(12):
        arm = SawyerArm(q_rad=task_start_posture(task[k % len(task)], loop.task_pitch_rad, loop.task_yaw_rad))
        arm.set_speed_limit(v_r)
        arm.set_target(task[(k + 1) % len(task)], loop.task_pitch_rad, loop.task_yaw_rad)
        for _ in range(int(rng.uniform(0.1, 0.8) / 0.001)):       # at speed, part way there
            arm.step(0.001)
        before, _ = arm.collision_spheres()
        arm.clear_target()
        steps = 0
        while arm.moving:
            arm.step(0.001)
            steps += 1
        after, _ = arm.collision_spheres()
        assert steps * 0.001 <= t_s + 0.001
        assert float(np.max(np.linalg.norm(after - before, axis=1))) <= 0.5 * v_r * t_s + 1e-4


def test_a_retraction_tucks_the_arm_in_from_anywhere_in_the_task():
    """The runtime's Eq. 6 retraction (hazard.eq6_retraction within the shipped ``[robot_loop]
    retract_*_radius_m``), from the hard suite's task postures, away from a worker 1.3 m from the base at any
    bearing, walking toward the hand: the simulated Sawyer reaches it, and there no link or tool is further than
    0.7 m from the base's axis. With the hand pulled in only to 0.7 m (until session 20) the tool stood up to
    0.89 m out, where workers passing 1.1-1.3 m from the base swung a hand into it (reports/hrc/s20_contact/)."""
    from edge_runtime.robot.hazard import HeadEstimate, eq6_retraction
    from firmware_sim.scenarios.hrc_world import box_config, hard_scenarios, task_start_posture

    zones, loop = box_config().zones, box_config().robot_loop
    task = hard_scenarios(1, 0)[0].task_m
    for k, start in enumerate(task):
        for bearing_deg in range(-180, 180, 60):
            b = math.radians(bearing_deg)
            head = np.array([1.3 * math.sin(b), 0.8, 1.3 * math.cos(b)])
            arm = SawyerArm(q_rad=task_start_posture(start, loop.task_pitch_rad, loop.task_yaw_rad))
            hand = arm.pose().position_m
            est = HeadEstimate(0.0, head, 1.4 * (hand - head) * [1, 0, 1] / np.linalg.norm((hand - head)[[0, 2]]), head)
            r = eq6_retraction(hand, est, zones, loop.retract_limits, loop.task_yaw_rad)
            arm.set_target(r.position_m, loop.task_pitch_rad, r.yaw_rad)       # raises Unreachable if it is not
            run_to_rest(arm)
            centres, radii = arm.collision_spheres()
            assert arm.at_goal, (k, bearing_deg)
            assert float((np.hypot(centres[:, 0], centres[:, 2]) + radii).max()) <= 0.7, (k, bearing_deg)
