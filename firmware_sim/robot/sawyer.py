"""The simulated Sawyer arm: kinematic chain, inverse kinematics, limited motion, collision spheres.

Kinematics are the public Sawyer description (Rethink Robotics,
``sawyer_description/urdf/sawyer_base.urdf.xacro``, Apache-2.0), transcribed below.
Each joint's ``origin`` is the fixed transform from the parent link to the joint frame
(translation in m, then roll-pitch-yaw in rad applied as Rz(yaw)·Ry(pitch)·Rx(roll));
every arm joint rotates about its local z axis.

========  =============================  ==================================  ==========  ==========  ===========
joint     origin xyz (m)                 origin rpy (rad)                    lower (rad) upper (rad) vmax (rad/s)
========  =============================  ==================================  ==========  ==========  ===========
right_j0  0, 0, 0.08                     0, 0, 0                             -3.0503     3.0503      1.74
right_j1  0.081, 0.05, 0.237             -1.5708, 1.5708, 0                  -3.8095     2.2736      1.328
right_j2  0, -0.14, 0.1425               1.5708, 0, 0                        -3.0426     3.0426      1.957
right_j3  0, -0.042, 0.26                -1.5708, 0, 0                       -3.0439     3.0439      1.957
right_j4  0, -0.125, -0.1265             1.5708, 0, 0                        -2.9761     2.9761      3.485
right_j5  0, 0.031, 0.275                -1.5708, 0, 0                       -2.9761     2.9761      3.485
right_j6  0, -0.11, 0.1053               -1.5708, -0.17453, 3.1416           -4.7124     4.7124      4.545
hand      0, 0, 0.0245 (fixed)           0, 0, 1.570796                      --          --          --
========  =============================  ==================================  ==========  ==========  ===========

Frames. The URDF base frame (``right_arm_base_link``) is z-up with the arm's forward
direction +x. Everything this module exposes is in the project's **robot frame**
(``edge_runtime/core/skeleton.py``): origin on top of the base, y up, the work side +z,
obtained by the cyclic permutation robot (x, y, z) = urdf (y, z, x). The floor is
``y = -0.914`` m (the pedestal puts the base top 0.914 m above it).

Tool direction. The tool points along the hand frame's z axis (out of the flange).
It is given as **pitch** and **yaw** in the robot frame::

    d = (cos(pitch)·sin(yaw), sin(pitch), cos(pitch)·cos(yaw))

so pitch 0, yaw 0 points the tool horizontally toward +z (the work side), pitch
+pi/2 points it straight up, -pi/2 straight down, and yaw turns it about the up axis
(right-handed: yaw +pi/2 points it toward +x). Roll about the tool axis is free.

Motion. :meth:`SawyerArm.step` moves the joints along a straight line in joint space
toward the goal of the last accepted target, within every joint's velocity and
acceleration limit and the Cartesian speed limit of the end effector, and brakes so
that it stops at the goal and never passes a joint limit. Without a goal the arm
decelerates to rest. A target that cannot be reached within 1 mm / 1 deg inside the
joint limits, or that lies below the floor clearance, is refused: :class:`Unreachable`.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy.optimize import least_squares

JOINT_NAMES = ("right_j0", "right_j1", "right_j2", "right_j3", "right_j4", "right_j5", "right_j6")
N_JOINTS = 7

# (xyz m, rpy rad) of each joint origin, then the fixed hand; from the table above
_ORIGINS = (
    ((0.0, 0.0, 0.08), (0.0, 0.0, 0.0)),
    ((0.081, 0.05, 0.237), (-1.5708, 1.5708, 0.0)),
    ((0.0, -0.14, 0.1425), (1.5708, 0.0, 0.0)),
    ((0.0, -0.042, 0.26), (-1.5708, 0.0, 0.0)),
    ((0.0, -0.125, -0.1265), (1.5708, 0.0, 0.0)),
    ((0.0, 0.031, 0.275), (-1.5708, 0.0, 0.0)),
    ((0.0, -0.11, 0.1053), (-1.5708, -0.17453, 3.1416)),
)
_HAND_ORIGIN = ((0.0, 0.0, 0.0245), (0.0, 0.0, 1.570796))

LOWER_RAD = np.array([-3.0503, -3.8095, -3.0426, -3.0439, -2.9761, -2.9761, -4.7124])
UPPER_RAD = np.array([3.0503, 2.2736, 3.0426, 3.0439, 2.9761, 2.9761, 4.7124])
MAX_VEL_RADPS = np.array([1.74, 1.328, 1.957, 1.957, 3.485, 3.485, 4.545])

BASE_HEIGHT_M = 0.914
"""Top of the Sawyer base above the floor on the standard pedestal (mesh offset 0.91488 m)."""
FLOOR_Y_M = -BASE_HEIGHT_M
REACH_M = 1.26
"""Published reach, used only for a quick refusal of targets far out of reach."""

# robot (x, y, z) = urdf (y, z, x): rows pick the URDF components
URDF_TO_ROBOT = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])

COLLISION_RADII_M = (0.08, 0.07, 0.06, 0.06, 0.055, 0.05, 0.045, 0.035)
"""Collision radius around the segment that starts at link l0..l6 and at the hand (m):
0.045-0.08 m for l0..l6 and the hand's 0.035 m, as in the description's collision
geometry (simplified to spheres along each segment)."""


SELF_COLLISION_SEGMENT_GAP = 3
"""Spheres of segments this many links apart or more must not overlap (closer ones share a joint)."""


def _rot_rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                              math.cos(yaw), math.sin(yaw))
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1.0]])
    ry = np.array([[cp, 0, sp], [0, 1.0, 0], [-sp, 0, cp]])
    rx = np.array([[1.0, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


def _transform(xyz, rpy) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = _rot_rpy(*rpy)
    t[:3, 3] = xyz
    return t


_ORIGIN_T = tuple(_transform(*o) for o in _ORIGINS)
_HAND_T = _transform(*_HAND_ORIGIN)


def direction_from_pitch_yaw(pitch_rad: float, yaw_rad: float) -> np.ndarray:
    """Unit tool direction in the robot frame (see the module docstring)."""
    cp = math.cos(pitch_rad)
    return np.array([cp * math.sin(yaw_rad), math.sin(pitch_rad), cp * math.cos(yaw_rad)])


def pitch_yaw_from_direction(d) -> tuple[float, float]:
    """(pitch, yaw) in rad of a tool direction in the robot frame; yaw is 0 when vertical."""
    x, y, z = (float(v) for v in np.asarray(d, dtype=float) / np.linalg.norm(d))
    horiz = math.hypot(x, z)
    yaw = math.atan2(x, z) if horiz > 1e-9 else 0.0
    return math.atan2(y, horiz), yaw


def angle_between_rad(a, b) -> float:
    """Angle between two direction vectors (rad), robust near 0 and pi."""
    a = np.asarray(a, float)
    b = np.asarray(b, float)
    return math.atan2(np.linalg.norm(np.cross(a, b)), float(np.dot(a, b)))


@dataclass(frozen=True)
class Pose:
    """End-effector pose in the robot frame."""

    position_m: np.ndarray
    """Hand origin (3,), m."""
    direction: np.ndarray
    """Unit tool direction (3,)."""

    @property
    def pitch_yaw_rad(self) -> tuple[float, float]:
        return pitch_yaw_from_direction(self.direction)


def forward_kinematics(q_rad) -> list[np.ndarray]:
    """4x4 transforms in the URDF base frame of joint frames j0..j6 (after rotation) and the hand."""
    frames = []
    t = np.eye(4)
    for origin, qi in zip(_ORIGIN_T, q_rad):
        c, s = math.cos(qi), math.sin(qi)
        rot = np.array([[c, -s, 0, 0], [s, c, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])
        t = t @ origin @ rot
        frames.append(t)
    frames.append(t @ _HAND_T)
    return frames


def end_effector_pose(q_rad) -> Pose:
    """Hand position and tool direction in the robot frame for joint angles ``q_rad`` (7,)."""
    hand = forward_kinematics(q_rad)[-1]
    return Pose(URDF_TO_ROBOT @ hand[:3, 3], URDF_TO_ROBOT @ hand[:3, 2])


def _cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross products of the rows of ``a`` (n,3) with ``b`` (n,3) or (3,), as columns (3,n).
    (np.cross is several times slower on small arrays.)"""
    return np.array([a[:, 1] * b[..., 2] - a[:, 2] * b[..., 1],
                     a[:, 2] * b[..., 0] - a[:, 0] * b[..., 2],
                     a[:, 0] * b[..., 1] - a[:, 1] * b[..., 0]])


def jacobian(q_rad) -> tuple[Pose, np.ndarray, np.ndarray]:
    """(pose, J_position (3,7) in m/rad, J_direction (3,7) in 1/rad), robot frame."""
    frames = np.asarray(forward_kinematics(q_rad))
    p = frames[-1, :3, 3]
    d = frames[-1, :3, 2]
    axes = frames[:N_JOINTS, :3, 2]
    jp = _cross_rows(axes, p - frames[:N_JOINTS, :3, 3])
    jd = _cross_rows(axes, d)
    r = URDF_TO_ROBOT
    return Pose(r @ p, r @ d), r @ jp, r @ jd


@dataclass(frozen=True)
class ArmConfig:
    """Limits and tolerances of the simulated arm."""

    max_vel_radps: tuple = tuple(MAX_VEL_RADPS)
    """Per-joint speed limits (rad/s), from the description."""
    max_acc_radps2: tuple = tuple(float(v) for v in MAX_VEL_RADPS / 0.25)
    """Per-joint acceleration limits (rad/s^2). The description publishes none; assumed: full
    speed in 0.25 s (so a stop from full speed takes at most 0.25 s)."""
    joint_speed_ratio: float = 1.0
    """Scales ``max_vel_radps`` (the Intera SDK's default is 0.7 for planned motions)."""
    max_cartesian_speed_mps: float = 0.6
    """End-effector linear speed limit (Intera SDK default 0.6 m/s)."""
    position_tolerance_m: float = 0.0005
    """IK acceptance: hand position error (m). The product promise is 1 mm."""
    direction_tolerance_rad: float = math.radians(0.5)
    """IK acceptance: tool direction error (rad). The product promise is 1 deg."""
    limit_margin_rad: float = 0.002
    """IK goals keep this far inside every joint limit (rad)."""
    floor_clearance_m: float = 0.05
    """Targets (and every collision sphere of the goal posture) stay this far above the floor (m)."""
    pedestal_radius_m: float = 0.2
    """Below the base top (y < 0) the pedestal column fills this radius around the y axis (m):
    targets and collision spheres of the goal posture stay outside it."""
    ik_restarts: int = 6
    """Seeds tried after the current posture: the postures of a fixed table (1200 random postures
    clear of the floor and pedestal) whose hand poses lie nearest the target."""
    ik_seed_evaluations: int = 30
    """Residual evaluations allowed from each table seed (the current posture gets 100)."""
    settle_tolerance_rad: float = 1e-5
    """Joint error below which a slow arm snaps onto its goal (rad)."""


HOME_RAD = np.array([0.0, -1.18, 0.0, 2.18, 0.0, 0.57, 3.3161])
"""The posture the simulated arm boots in: hand 0.45 m in front of the base, tool pointing down."""


class Unreachable(ValueError):
    """A target the arm cannot reach within tolerance inside its joint limits."""


@dataclass
class StepRecord:
    """What one :meth:`SawyerArm.step` did (for checks of the limits)."""

    dt_s: float
    q_rad: np.ndarray
    qd_radps: np.ndarray
    ee_speed_mps: float


@dataclass
class SawyerArm:
    """Joint state, goal and limited motion of one Sawyer arm (robot frame, SI units)."""

    config: ArmConfig = field(default_factory=ArmConfig)
    q_rad: np.ndarray = field(default_factory=lambda: HOME_RAD.copy())
    qd_radps: np.ndarray = field(default_factory=lambda: np.zeros(N_JOINTS))
    goal_rad: np.ndarray | None = None
    """Joint goal of the accepted target; None: decelerate to rest and hold."""

    def __post_init__(self):
        c = self.config
        self.q_rad = np.asarray(self.q_rad, float).copy()
        self.qd_radps = np.asarray(self.qd_radps, float).copy()
        self._vmax_full = np.asarray(c.max_vel_radps, float) * c.joint_speed_ratio
        self._vmax = self._vmax_full
        self.speed_limit_mps = c.max_cartesian_speed_mps
        """The hand's speed limit now (m/s): the configured one, or lower after a speed override."""
        self._amax = np.asarray(c.max_acc_radps2, float)
        self._lo = LOWER_RAD + c.limit_margin_rad
        self._hi = UPPER_RAD - c.limit_margin_rad

    # -- state ---------------------------------------------------------------------------
    def pose(self) -> Pose:
        return end_effector_pose(self.q_rad)

    def ee_velocity_mps(self) -> np.ndarray:
        _, jp, _ = jacobian(self.q_rad)
        return jp @ self.qd_radps

    @property
    def moving(self) -> bool:
        return bool(np.any(self.qd_radps != 0.0))

    @property
    def at_goal(self) -> bool:
        return self.goal_rad is not None and not self.moving and bool(np.all(self.q_rad == self.goal_rad))

    def collision_spheres(self) -> tuple[np.ndarray, np.ndarray]:
        """(centres (N,3) m in the robot frame, radii (N,) m) covering the links and the hand.

        Spheres sit along each segment between consecutive joint frames (base top to j0,
        j0 to j1, ..., j6 to the hand, and the hand to 10 cm beyond it along the tool),
        no further apart than their radius, so the chain of spheres has no gaps.
        """
        return collision_spheres(self.q_rad)

    # -- targets -------------------------------------------------------------------------
    def solve_ik(self, position_m, pitch_rad: float, yaw_rad: float) -> np.ndarray:
        """Joint angles (7,) that put the hand at ``position_m`` with the tool along (pitch, yaw).

        Bounded least squares (scipy's dogbox solver with the analytic Jacobian) from the
        current posture; if that misses, from the ``ik_restarts`` postures of a fixed seed table
        whose hand poses lie nearest the target, keeping -- among the solutions within tolerance
        that keep the arm clear of the floor, the pedestal and itself -- the one nearest the
        current posture in joint space (largest joint change smallest). Raises :class:`Unreachable`.
        """
        c = self.config
        p = np.asarray(position_m, dtype=float).reshape(-1)
        if p.shape != (3,) or not np.all(np.isfinite(p)) or not (math.isfinite(pitch_rad) and math.isfinite(yaw_rad)):
            raise Unreachable("target must be 3 finite coordinates (m) and finite pitch/yaw (rad)")
        if p[1] < FLOOR_Y_M + c.floor_clearance_m:
            raise Unreachable(f"target y = {p[1]:.3f} m is below the floor clearance "
                              f"({FLOOR_Y_M + c.floor_clearance_m:.3f} m)")
        if not _outside_pedestal(p[None], np.zeros(1), c.pedestal_radius_m)[0]:
            raise Unreachable(f"target ({p[0]:.3f}, {p[1]:.3f}, {p[2]:.3f}) m is inside the pedestal")
        shoulder = URDF_TO_ROBOT @ forward_kinematics(np.zeros(N_JOINTS))[1][:3, 3]
        if np.linalg.norm(p - shoulder) > REACH_M:
            raise Unreachable(f"target is {np.linalg.norm(p - shoulder):.3f} m from the shoulder, beyond the reach")
        d = direction_from_pitch_yaw(pitch_rad, yaw_rad)
        w = 0.3  # m per unit of direction error: balances mm against degrees

        def residual(q):
            pose = end_effector_pose(q)
            return np.concatenate([pose.position_m - p, w * (pose.direction - d)])

        def jac(q):
            _, jp, jd = jacobian(q)
            return np.vstack([jp, w * jd])

        def solve(q0, budget):
            q = least_squares(residual, q0, jac=jac, bounds=(self._lo, self._hi), method="dogbox",
                              xtol=1e-10, ftol=1e-10, gtol=1e-10, max_nfev=budget).x
            pose = end_effector_pose(q)
            ok = (np.linalg.norm(pose.position_m - p) <= c.position_tolerance_m
                  and angle_between_rad(pose.direction, d) <= c.direction_tolerance_rad
                  and posture_is_clear(q, c))
            return q if ok else None

        here = np.clip(self.q_rad, self._lo, self._hi)
        q = solve(here, 100)
        if q is not None:
            return q
        # From the seed table, the solution nearest the current posture in joint space: the
        # controller interpolates joints, so a far branch would swing the hand through the cell.
        found = [q for q in (solve(q0, c.ik_seed_evaluations) for q0 in _nearest_seeds(p, d, c.ik_restarts, w))
                 if q is not None]
        if not found:
            raise Unreachable("no joint solution within tolerance inside the joint limits")
        return min(found, key=lambda q: float(np.max(np.abs(q - here))))


    def set_target(self, position_m, pitch_rad: float, yaw_rad: float) -> np.ndarray:
        """Accept a Cartesian target (or raise :class:`Unreachable`); returns the joint goal."""
        goal = self.solve_ik(position_m, pitch_rad, yaw_rad)
        self.goal_rad = goal
        return goal

    def clear_target(self) -> None:
        """Forget the goal: the arm decelerates to rest within its limits and holds there."""
        self.goal_rad = None

    def set_speed_limit(self, limit_mps: float) -> None:
        """Speed override (ISO/TS 15066 speed and separation monitoring): the hand's speed limit
        becomes ``limit_mps`` (never above the configured one) and every joint's speed limit is
        scaled by the same factor, so a motion in joint space slows down as much as the hand.
        The arm decelerates to the new limit within its acceleration limits."""
        top = self.config.max_cartesian_speed_mps
        self.speed_limit_mps = min(max(float(limit_mps), 0.0), top)
        self._vmax = self._vmax_full * (self.speed_limit_mps / top)

    # -- motion --------------------------------------------------------------------------
    def step(self, dt_s: float) -> StepRecord:
        """Advance ``dt_s`` seconds toward the goal (or to rest) within every limit."""
        if dt_s <= 0:
            return StepRecord(0.0, self.q_rad.copy(), self.qd_radps.copy(), 0.0)
        v = self.qd_radps
        amax = self._amax
        if self.goal_rad is None:
            v_des = np.zeros(N_JOINTS)
        else:
            v_des = self._toward_goal(dt_s)
        v_des = self._limit_braking(v_des, dt_s)
        dv = np.clip(v_des - v, -amax * dt_s, amax * dt_s)
        v_new = self._cartesian_cap(v, v + dv, dt_s)
        q_new = self.q_rad + v_new * dt_s
        if self.goal_rad is not None:
            # close enough and slow enough to stop within one step: settle exactly on the goal
            err = self.goal_rad - q_new
            if np.all(np.abs(err) <= self.config.settle_tolerance_rad) and np.all(np.abs(v) <= amax * dt_s):
                q_new, v_new = self.goal_rad.copy(), np.zeros(N_JOINTS)
        elif np.all(np.abs(v_new) <= 1e-12):
            v_new = np.zeros(N_JOINTS)
        self.q_rad, self.qd_radps = q_new, v_new
        _, jp, _ = jacobian(q_new)
        return StepRecord(dt_s, q_new.copy(), v_new.copy(), float(np.linalg.norm(jp @ v_new)))

    def _toward_goal(self, dt_s: float) -> np.ndarray:
        """Joint velocity along the straight joint-space line to the goal, braking to stop on it."""
        e = self.goal_rad - self.q_rad
        dist = float(np.linalg.norm(e))
        if dist < 1e-12:
            return np.zeros(N_JOINTS)
        u = e / dist
        au = np.abs(u)
        nz = au > 1e-12
        if self.speed_limit_mps <= 0.0:  # held still by a zero speed override
            return np.zeros(N_JOINTS)
        s_vel = float(np.min(self._vmax[nz] / au[nz]))
        a_s = float(np.min(self._amax[nz] / au[nz]))
        s = min(s_vel, _braking_speed(dist, a_s, dt_s))
        _, jp, _ = jacobian(self.q_rad)
        c = float(np.linalg.norm(jp @ u))  # m of hand travel per rad along u
        if c > 1e-9:
            s = min(s, self.speed_limit_mps / c)
        return s * u

    def _cartesian_cap(self, v: np.ndarray, v_new: np.ndarray, dt_s: float) -> np.ndarray:
        """Scale ``v_new`` down to the Cartesian speed limit, as far as the acceleration limits allow.

        The goal velocity already respects the limit; this catches the transients when the
        accelerations lag it (a new target in another direction, a posture whose lever grows).
        """
        limit = max(self.speed_limit_mps, 1e-6)
        # smallest alpha with |alpha * v_new - v| <= amax * dt on every joint (alpha = 1 is feasible)
        moving = np.abs(v_new) > 1e-12
        lower = (np.sign(v_new[moving]) * v[moving] - self._amax[moving] * dt_s) / np.abs(v_new[moving])
        alpha_min = float(np.max(lower, initial=0.0))
        alpha = 1.0
        for _ in range(3):  # the speed is measured at the posture the step ends in
            _, jp, _ = jacobian(self.q_rad + alpha * v_new * dt_s)
            speed = float(np.linalg.norm(jp @ v_new)) * alpha
            if speed <= limit * (1.0 - 1e-9):
                break
            alpha = max(alpha_min, alpha * limit / speed * (1.0 - 1e-6))
        return alpha * v_new

    def _limit_braking(self, v_des: np.ndarray, dt_s: float) -> np.ndarray:
        """Cap each joint's speed toward a limit so that it can still stop before it."""
        up = _braking_speed_vec(np.maximum(UPPER_RAD - self.q_rad, 0.0), self._amax, dt_s)
        down = _braking_speed_vec(np.maximum(self.q_rad - LOWER_RAD, 0.0), self._amax, dt_s)
        return np.clip(v_des, -down, up)


def posture_is_clear(q_rad, config: ArmConfig) -> bool:
    """Posture ``q_rad`` keeps every collision sphere above the floor clearance, outside the
    pedestal, and clear of the spheres of segments three or more links away (self-collision)."""
    centres, radii, segments = _spheres_by_segment(q_rad)
    if not (np.all(centres[:, 1] - radii >= FLOOR_Y_M + config.floor_clearance_m)
            and np.all(_outside_pedestal(centres, radii, config.pedestal_radius_m))):
        return False
    dist = np.linalg.norm(centres[:, None, :] - centres[None, :, :], axis=2)
    distant = np.abs(segments[:, None] - segments[None, :]) >= SELF_COLLISION_SEGMENT_GAP
    return not np.any(distant & (dist < radii[:, None] + radii[None, :]))


_SEED_TABLE: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None


def _seed_table() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(postures (n,7), hand positions (n,3), tool directions (n,3)): a fixed, deterministic table
    of postures inside the joint limits and clear of the floor and pedestal, built once."""
    global _SEED_TABLE
    if _SEED_TABLE is None:
        c = ArmConfig()
        lo, hi = LOWER_RAD + c.limit_margin_rad, UPPER_RAD - c.limit_margin_rad
        qs, ps, ds = [], [], []
        for q in np.random.default_rng(12345).uniform(lo, hi, size=(1200, N_JOINTS)):
            if posture_is_clear(q, c):
                pose = end_effector_pose(q)
                qs.append(q)
                ps.append(pose.position_m)
                ds.append(pose.direction)
        _SEED_TABLE = (np.array(qs), np.array(ps), np.array(ds))
    return _SEED_TABLE


def warm_up() -> None:
    """Build the IK seed table now (about a second), so that the first target is answered quickly."""
    _seed_table()


def _nearest_seeds(position_m: np.ndarray, direction: np.ndarray, k: int, w: float) -> np.ndarray:
    """The ``k`` table postures whose hand pose is nearest (position m + w * direction)."""
    qs, ps, ds = _seed_table()
    cost = np.linalg.norm(ps - position_m, axis=1) + w * np.linalg.norm(ds - direction, axis=1)
    return qs[np.argsort(cost)[:k]]


def _braking_speed(dist: float, acc: float, dt: float) -> float:
    """Largest speed that, decelerating at ``acc`` in steps of ``dt``, stops within ``dist``."""
    return acc * dt * (math.sqrt(0.25 + 2.0 * dist / (acc * dt * dt)) - 0.5)


def _braking_speed_vec(dist: np.ndarray, acc: np.ndarray, dt: float) -> np.ndarray:
    return acc * dt * (np.sqrt(0.25 + 2.0 * dist / (acc * dt * dt)) - 0.5)


def _outside_pedestal(centres: np.ndarray, radii: np.ndarray, pedestal_radius_m: float) -> np.ndarray:
    """Per sphere: True when it does not reach into the pedestal column (y < 0, |(x, z)| < radius)."""
    horiz = np.hypot(centres[:, 0], centres[:, 2])
    return (centres[:, 1] + radii > 0.0) | (horiz - radii >= pedestal_radius_m)


def collision_spheres(q_rad) -> tuple[np.ndarray, np.ndarray]:
    """Collision spheres of posture ``q_rad``: (centres (N,3) m, robot frame; radii (N,) m)."""
    centres, radii, _ = _spheres_by_segment(q_rad)
    return centres, radii


def _spheres_by_segment(q_rad) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(centres (N,3) robot frame, radii (N,), segment index (N,)) along base-j0-...-j6-hand-tool tip."""
    frames = forward_kinematics(q_rad)
    hand = frames[-1]
    points = [np.zeros(3)] + [f[:3, 3] for f in frames]
    points.append(hand[:3, 3] + 0.10 * hand[:3, 2])  # a gripper/tool of 10 cm
    centres, radii, segments = [], [], []
    for k in range(len(points) - 1):
        r = COLLISION_RADII_M[min(k, len(COLLISION_RADII_M) - 1)]
        a, b = points[k], points[k + 1]
        n = max(1, int(math.ceil(np.linalg.norm(b - a) / r)))
        for t in np.linspace(0.0, 1.0, n + 1)[(0 if k == 0 else 1):]:
            centres.append(a + t * (b - a))
            radii.append(r)
            segments.append(k)
    return np.asarray(centres) @ URDF_TO_ROBOT.T, np.asarray(radii), np.asarray(segments)
