"""Retraction (the dissertation's Eq. 6 and Sec. 3.2.4.4) as pure functions: where the hand
goes when a worker enters level 2, and which way the tool points.

Numbers and parameters in, a target out; :class:`edge_runtime.robot.loop.RobotLoop` decides
when to retract and sends what these return. Robot frame of :mod:`edge_runtime.core.skeleton`
(metres, ``y`` up, origin on top of the Sawyer base, yaw 0 along +z).

* **Eq. 6.** ``L = w1 * unit(P_eff - P_head) + w2 * unit(V_ground)``, on the ground
  (``w1 = 0.3 m`` away from the head, ``w2 = 0.2 m`` along the worker's walk; a standing
  worker contributes no second term). The target is ``P_eff + s * L``, with the step ``s``
  (0..1) shortened so that the hand never comes closer than ``min_radius_m`` to the base's
  axis (closer in, the Sawyer cannot hold its tool pointed at the base), then pulled in
  to ``max_radius_m`` (with its tool pointed at the base the Sawyer reaches 0.7-0.8 m).
* **The fallback.** When the controller refuses Eq. 6's target: straight toward the base's
  axis, as far as Eq. 6's step (``w1 + w2``) but not inside ``min_radius_m``.
* **Height.** No target below ``min_height_m``.
* **Tool.** Turned toward the base by at most ``max_turn_deg`` from where it points now
  (a large turn swings the joints, and with them the hand, through the cell); a repeat
  retraction keeps the first one's yaw.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from edge_runtime.robot.hazard import HeadEstimate, ZoneParams, ground


@dataclass(frozen=True)
class RetractLimits:
    """Where the Sawyer can retract to (from the loop's [robot_loop] parameters)."""

    min_radius_m: float = 0.3
    """Targets stop short of this ground distance from the base's axis (m)."""
    max_radius_m: float = 0.7
    """Targets further out from the base's axis are pulled in to it (m)."""
    min_height_m: float = -0.3
    """Targets are kept at or above this robot-frame height (m)."""
    max_turn_deg: float = 45.0
    """The tool turns toward the base by at most this much (deg)."""


@dataclass(frozen=True)
class Retraction:
    """A retraction target: the hand's position (m) and the tool's yaw (rad)."""

    position_m: np.ndarray
    yaw_rad: float


def _unit(v: np.ndarray) -> np.ndarray:
    n = float(np.linalg.norm(v))
    return v / n if n > 1e-9 else np.zeros_like(v)


def retract_direction(effector_m, est: HeadEstimate, params: ZoneParams = ZoneParams()) -> np.ndarray:
    """Eq. 6 in the robot frame: ``w1 unit(P_eff - P_head) + w2 unit(V_ground)``, on the
    ground (y = 0). A standing worker contributes no second term."""
    away = _unit(ground(effector_m) - ground(est.position_m))
    path = _unit(ground(est.velocity_mps)) if np.linalg.norm(ground(est.velocity_mps)) > 0.2 else np.zeros(2)
    L = params.retract_weight_away_m * away + params.retract_weight_path_m * path
    return np.array([L[0], 0.0, L[1]])


def tool_yaw_toward_base(position_m) -> float:
    """Yaw (rad) that points the tool at the robot base from ``position_m``: the heading of
    the ground vector toward the base's axis, measured from +z toward +x
    (yaw = atan2(dx, dz); 0 points the tool along +z, the work side)."""
    g = -ground(position_m)
    return float(math.atan2(g[0], g[1]))


def step_outside_radius(start_xz_m: np.ndarray, step_xz_m: np.ndarray, radius_m: float) -> float:
    """The largest fraction (0..1) of the ground step ``step_xz_m`` from ``start_xz_m`` that
    stays at least ``radius_m`` from the origin all the way (0 when it starts inside)."""
    a = float(step_xz_m @ step_xz_m)
    b = 2.0 * float(start_xz_m @ step_xz_m)
    c = float(start_xz_m @ start_xz_m) - radius_m * radius_m
    if c <= 0:
        return 0.0  # already inside: turn the tool, do not move
    disc = b * b - 4 * a * c
    if a == 0 or disc < 0:
        return 1.0
    first = (-b - math.sqrt(disc)) / (2 * a)
    return min(1.0, first) if first > 0 else 1.0


def limit_turn(yaw_rad: float, from_yaw_rad: float | None, max_turn_deg: float) -> float:
    """``yaw_rad``, or as far toward it from ``from_yaw_rad`` as ``max_turn_deg`` allows
    (the short way round); ``yaw_rad`` itself when where the tool points is unknown."""
    if from_yaw_rad is None:
        return yaw_rad
    turn = math.radians(max_turn_deg)
    return from_yaw_rad + max(-turn, min(turn, math.remainder(yaw_rad - from_yaw_rad, 2 * math.pi)))


def eq6_retraction(effector_m, head: HeadEstimate, zones: ZoneParams, limits: RetractLimits,
                   tool_yaw_rad: float | None, held_yaw_rad: float | None = None) -> Retraction:
    """Eq. 6's step from the effector, kept between ``min_radius_m`` and ``max_radius_m`` of
    the base's axis. ``tool_yaw_rad``: where the tool points now (None: unknown);
    ``held_yaw_rad``: the yaw of the retraction under way, kept by a repeat one."""
    eff = np.asarray(effector_m, float)
    L = retract_direction(eff, head, zones)
    target = eff + step_outside_radius(ground(eff), ground(L), limits.min_radius_m) * L
    r = float(np.linalg.norm(ground(target)))
    if r > limits.max_radius_m:
        target[[0, 2]] *= limits.max_radius_m / r
    return _retraction(target, limits, tool_yaw_rad, held_yaw_rad)


def radial_retraction(effector_m, zones: ZoneParams, limits: RetractLimits, tool_yaw_rad: float | None,
                      held_yaw_rad: float | None = None) -> Retraction:
    """The fallback: straight toward the base's axis (away from anyone in front of the arm),
    as far as Eq. 6's step but not inside ``min_radius_m``."""
    eff = np.asarray(effector_m, float)
    g = ground(eff)
    r = float(np.linalg.norm(g))
    step_m = zones.retract_weight_away_m + zones.retract_weight_path_m
    new_r = min(r, max(limits.min_radius_m, min(r, limits.max_radius_m) - step_m))
    target = eff.copy()
    target[[0, 2]] = g * (new_r / r) if r > 1e-9 else g
    return _retraction(target, limits, tool_yaw_rad, held_yaw_rad)


def _retraction(target_m: np.ndarray, limits: RetractLimits, tool_yaw_rad: float | None,
                held_yaw_rad: float | None) -> Retraction:
    """``target_m`` no lower than ``min_height_m``, the tool turned toward the base (or kept
    at ``held_yaw_rad``: turning again would swing the joints through the cell)."""
    target = np.array(target_m, float)
    target[1] = max(target[1], limits.min_height_m)
    if held_yaw_rad is not None:
        return Retraction(target, held_yaw_rad)
    return Retraction(target, limit_turn(tool_yaw_toward_base(target), tool_yaw_rad, limits.max_turn_deg))
