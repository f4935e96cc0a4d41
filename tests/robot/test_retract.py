"""Retraction as pure functions (edge_runtime.robot.retract): Eq. 6, the radius and height
limits, the fallback toward the base and the tool's turn."""
import math

import numpy as np
import pytest
from support.robot import EFF, FPS, HEAD_Y, head_at

from edge_runtime.robot.hazard import HeadEstimate, HeadTracker, TrackerParams, ZoneParams
from edge_runtime.robot.retract import (
    RetractLimits,
    eq6_retraction,
    limit_turn,
    radial_retraction,
    retract_direction,
    step_outside_radius,
    tool_yaw_toward_base,
)


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
    mid = radial_retraction([0.0, 0.2, 0.9], ZoneParams(), RetractLimits(min_radius_m=0.1), None)
    np.testing.assert_allclose(mid.position_m, [0.0, 0.2, 0.2], atol=1e-9)          # 0.7 - 0.5 = 0.2 m out
    on_axis = radial_retraction([0.0, 0.2, 0.0], ZoneParams(), limits, None)
    np.testing.assert_allclose(on_axis.position_m, [0.0, 0.2, 0.0])
