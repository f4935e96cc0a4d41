"""Motions of a simulated worker: joint trajectories (T, 17, 3) in the robot frame.

Every generator returns a :class:`Motion` sampled at ``rate_hz`` (30 Hz by default): the
posture angles (T, 15) of :mod:`firmware_sim.people.human`, the pelvis floor position (T, 2),
the heading (T,), a label per frame, and the joints (T, 17, 3) in metres in the robot
frame (``y`` up, floor at ``y = -0.914``; :mod:`edge_runtime.core.skeleton`).

The generators
--------------
* :func:`walk` -- from waypoint to waypoint at a speed of 0.5-2.0 m/s (one speed, or one
  per leg of the path), with optional rounded corners (``corner_radius_m``), accelerating
  and braking at ``accel_mps2``. A gait cycle drives the legs (hip and knee flexion after
  the normal sagittal gait curves), arm swing opposite to the legs, trunk twist and sway.
  Stride frequency rises with speed (0.55 + 0.45 v Hz at 1.75 m; shorter people step
  faster). "Walk from A to B at v m/s" is ``walk(body, [A, B], v)``; a curving path is
  ``walk(body, [A, C, B], v, corner_radius_m=1.0)``.
* :func:`stand` -- standing with postural sway.
* :func:`work_at` -- standing at a point and working with the hands at a height and
  reach: the posture is solved by two-link inverse kinematics in the sagittal plane, the
  trunk leans only when the arms cannot reach; the hands move between nearby targets and
  the head looks down at the work-piece.
* :func:`look_down` -- :func:`work_at` with a low, close work-piece (strong neck flexion).
* :func:`bend` -- bending forward at the hips to pick something from low down, and back.
* :func:`squat` -- squatting down, holding, and standing up.
* :func:`turn` -- turning on the spot by stepping.
* :func:`concat` -- joins motions, blending the posture across each seam.
* :func:`random_activity` -- a random working session chaining the above (the lifter's data).
* :func:`random_limbs` -- any of the above with its arms, trunk, neck and legs taken, part of the
  time, along smooth random trajectories through their whole range of motion (the lifter's
  pose-space augmentation: joint configurations no scripted motion holds).

Single postures (for posture scoring) come from :class:`firmware_sim.people.human.Posture` and
:func:`firmware_sim.people.human.joints`; :func:`work_posture` gives the posture that puts the
hands at a work point.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from edge_runtime.core.skeleton import BASE_HEIGHT_M
from firmware_sim.people.human import (
    N_ANGLES,
    ROM_DEG,
    Body,
    angle_column,
    heading_towards,
    joints_from_angles,
    prepare_angles,
)

DEFAULT_RATE_HZ = 30.0
SPEED_RANGE_MPS = (0.5, 2.0)      # the walking speeds the gait model covers
_C = angle_column


@dataclass(frozen=True)
class Motion:
    """A sampled trajectory of one body. Arrays share their first dimension T."""

    body: Body
    rate_hz: float
    angles_deg: np.ndarray         #: (T, 15) posture angles, :data:`firmware_sim.people.human.VECTOR_FIELDS`
    pelvis_xz_m: np.ndarray        #: (T, 2) pelvis floor position (robot x, z)
    heading_rad: np.ndarray        #: (T,) facing direction, 0 = +z
    labels: np.ndarray             #: (T,) activity name per frame
    joints_m: np.ndarray = field(repr=False)   #: (T, 17, 3) robot-frame joints

    def __len__(self) -> int:
        return len(self.angles_deg)

    @property
    def t_s(self) -> np.ndarray:
        """(T,) time of each frame from the start, seconds."""
        return np.arange(len(self)) / self.rate_hz

    @property
    def speed_mps(self) -> np.ndarray:
        """(T,) ground speed of the pelvis, m/s (gait sway included)."""
        if len(self) < 2:
            return np.zeros(len(self))
        v = np.linalg.norm(np.gradient(self.pelvis_xz_m, axis=0), axis=1) * self.rate_hz
        return v

    @property
    def end(self) -> tuple[np.ndarray, float]:
        """(pelvis_xz_m, heading_rad) of the last frame: where the next motion starts."""
        return self.pelvis_xz_m[-1].copy(), float(self.heading_rad[-1])


def make_motion(body: Body, rate_hz: float, angles_deg, pelvis_xz_m, heading_rad, label) -> Motion:
    """Build a :class:`Motion` (computes the joints; placement may be scalar or per frame)."""
    a = np.asarray(angles_deg, float)
    T = len(a)
    xz = np.array(np.broadcast_to(np.asarray(pelvis_xz_m, float), (T, 2)))
    hd = np.array(np.broadcast_to(np.asarray(heading_rad, float), (T,)))
    labels = np.array(np.broadcast_to(np.asarray(label, dtype=object), (T,)))
    return Motion(body, float(rate_hz), a, xz, hd, labels, joints_from_angles(body, a, xz, hd))


# --- building blocks ---------------------------------------------------------------------------
def min_jerk(x: np.ndarray) -> np.ndarray:
    """The minimum-jerk profile 10x^3 - 15x^4 + 6x^5 on [0, 1] (clipped outside)."""
    x = np.clip(x, 0.0, 1.0)
    return x ** 3 * (10 - 15 * x + 6 * x * x)


def keyframes(times_s: Sequence[float], vectors: np.ndarray, rate_hz: float) -> np.ndarray:
    """Minimum-jerk interpolation of key vectors (K, D) at increasing ``times_s`` -> (T, D), T = end * rate."""
    times = np.asarray(times_s, float)
    vec = np.asarray(vectors, float)
    t = np.arange(int(round(times[-1] * rate_hz))) / rate_hz
    k = np.clip(np.searchsorted(times, t, side="right") - 1, 0, len(times) - 2)
    span = np.maximum(times[k + 1] - times[k], 1e-9)
    w = min_jerk((t - times[k]) / span)[:, None]
    return vec[k] * (1 - w) + vec[k + 1] * w


def sway(rng: np.random.Generator, n: int, rate_hz: float, sd: np.ndarray, tau_s: float = 1.0) -> np.ndarray:
    """(n, D) smooth random wander (Ornstein-Uhlenbeck, stationary sd ``sd`` (D,), time constant tau_s)."""
    sd = np.asarray(sd, float)
    a = math.exp(-1.0 / (tau_s * rate_hz))
    e = rng.normal(size=(n, sd.size)) * sd * math.sqrt(1 - a * a)
    out = np.empty((n, sd.size))
    x = rng.normal(size=sd.size) * sd
    for i in range(n):
        x = a * x + e[i]
        out[i] = x
    return out


def _sway_sd(trunk=1.0, neck=2.5, arms=3.0, legs=0.8) -> np.ndarray:
    """Per-angle sway amplitudes (degrees) in VECTOR_FIELDS order."""
    sd = np.array([trunk, trunk * 0.6, trunk, neck, neck * 2] + [arms] * 6 + [legs] * 4)
    return sd


def _relaxed(rng: np.random.Generator | None = None) -> np.ndarray:
    """A relaxed standing posture vector: knees soft, elbows a little bent, arms a little out."""
    a = np.zeros(N_ANGLES)
    a[[_C("elbow_flexion_deg.left"), _C("elbow_flexion_deg.right")]] = 12.0
    a[[_C("shoulder_abduction_deg.left"), _C("shoulder_abduction_deg.right")]] = 6.0
    a[[_C("knee_flexion_deg.left"), _C("knee_flexion_deg.right")]] = 3.0
    a[[_C("hip_flexion_deg.left"), _C("hip_flexion_deg.right")]] = 2.0
    a[_C("neck_flexion_deg")] = 5.0
    if rng is not None:
        a += rng.normal(0, 1, N_ANGLES) * _sway_sd(2, 4, 4, 1)
    return a


def _n(duration_s: float, rate_hz: float) -> int:
    n = int(round(duration_s * rate_hz))
    if n < 1:
        raise ValueError(f"duration_s: {duration_s!r} s at {rate_hz} Hz gives no frame")
    return n


# --- walking -----------------------------------------------------------------------------------
def _wrap(x):
    return (x + 0.5) % 1.0 - 0.5


def gait_angles(phase: np.ndarray, amp: np.ndarray, style: dict | None = None) -> np.ndarray:
    """(T, 15) posture angles of walking at gait ``phase`` (cycles, left heel strike at integers)
    with amplitude ``amp`` (T,) (1 = normal walking at 1.4 m/s, 0 = standing)."""
    s = {"arm_swing": 1.0, "stride": 1.0, "lean_deg": 3.0, "neck_deg": 8.0} | (style or {})
    a = _relaxed()[None].repeat(len(phase), 0)
    for side, ph in (("left", phase), ("right", phase + 0.5)):
        ca = np.cos(2 * np.pi * ph)
        st = amp * s["stride"]
        a[:, _C(f"hip_flexion_deg.{side}")] = 17.5 * st * ca + 7.5 * st
        knee = 15 * np.exp(-0.5 * (_wrap(ph - 0.15) / 0.07) ** 2) + 60 * np.exp(-0.5 * (_wrap(ph - 0.72) / 0.11) ** 2)
        a[:, _C(f"knee_flexion_deg.{side}")] = 3 + st * knee
        sw = amp * s["arm_swing"]
        a[:, _C(f"shoulder_flexion_deg.{side}")] = 3 - 16 * sw * ca
        a[:, _C(f"elbow_flexion_deg.{side}")] = 12 + 15 * sw * (1 - ca) / 2
    c = np.cos(2 * np.pi * phase)
    a[:, _C("trunk_flexion_deg")] = s["lean_deg"] * amp
    a[:, _C("trunk_twist_deg")] = 5 * amp * c
    a[:, _C("trunk_lateral_deg")] = 2 * amp * np.sin(2 * np.pi * phase)
    a[:, _C("neck_flexion_deg")] = s["neck_deg"]
    return a


def stride_frequency_hz(speed_mps, height_m: float):
    """Gait cycles per second at a walking speed (0.55 + 0.45 v at 1.75 m, scaled by sqrt(1.75 / H))."""
    return (0.55 + 0.45 * np.asarray(speed_mps)) * math.sqrt(1.75 / height_m)


def _rounded_path(points: np.ndarray, corner_radius_m: float, step_m: float = 0.01) -> np.ndarray:
    """Densely sampled polyline through ``points`` (K, 2), corners replaced by quadratic Bezier arcs."""
    pts = [points[0]]
    for i in range(1, len(points) - 1):
        a, b, c = points[i - 1], points[i], points[i + 1]
        r = min(corner_radius_m, 0.5 * np.linalg.norm(b - a), 0.5 * np.linalg.norm(c - b))
        if r <= 0:
            pts.append(b)
            continue
        p0 = b + (a - b) / np.linalg.norm(a - b) * r
        p2 = b + (c - b) / np.linalg.norm(c - b) * r
        u = np.linspace(0, 1, 16)[:, None]
        pts.extend((1 - u) ** 2 * p0 + 2 * u * (1 - u) * b + u ** 2 * p2)
    pts.append(points[-1])
    pts = np.array(pts)
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    keep = np.concatenate([[True], seg > 1e-9])
    pts = pts[keep]
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    fine = np.arange(0.0, s[-1], step_m)
    fine = np.append(fine, s[-1])
    return np.stack([np.interp(fine, s, pts[:, 0]), np.interp(fine, s, pts[:, 1])], 1)


def walk(body: Body, waypoints_xz_m, speed_mps: float | Sequence[float] = 1.4, rate_hz: float = DEFAULT_RATE_HZ,
         corner_radius_m: float = 0.0, accel_mps2: float = 1.0, start_speed_mps: float = 0.0,
         stop_at_end: bool = True, style: dict | None = None, rng: np.random.Generator | None = None) -> Motion:
    """Walk along waypoints (K >= 2, floor x, z in metres) at ``speed_mps`` (one value, or one per leg).

    Speed changes at ``accel_mps2``; the walker starts at ``start_speed_mps`` and (``stop_at_end``)
    brakes to a stop at the last waypoint. Corners are rounded with ``corner_radius_m`` (0: sharp
    corners, turned at a limited rate). The heading follows the path tangent. ``style``: optional
    ``arm_swing``, ``stride``, ``lean_deg``, ``neck_deg`` (see :func:`gait_angles`); ``rng`` adds sway."""
    pts = np.asarray(waypoints_xz_m, float)
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 2 or not np.all(np.isfinite(pts)):
        raise ValueError(f"waypoints_xz_m: expected (K >= 2, 2) finite points, got shape {pts.shape}")
    speeds = np.broadcast_to(np.asarray(speed_mps, float), (len(pts) - 1,))
    if np.any(speeds < SPEED_RANGE_MPS[0] - 1e-9) or np.any(speeds > SPEED_RANGE_MPS[1] + 1e-9):
        raise ValueError(f"speed_mps: expected {SPEED_RANGE_MPS[0]}-{SPEED_RANGE_MPS[1]} m/s, got {speed_mps!r}")
    path = _rounded_path(pts, corner_radius_m)
    s_path = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(path, axis=0), axis=1))])
    length = s_path[-1]
    # target speed along the path: the leg each path sample belongs to
    s_way = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    s_way *= length / max(s_way[-1], 1e-9)
    dt = 1.0 / rate_hz
    s, v, out_s, out_v = 0.0, float(start_speed_mps), [], []
    for _ in range(int(10 * length / SPEED_RANGE_MPS[0] * rate_hz) + 10 * int(rate_hz)):
        out_s.append(s)
        out_v.append(v)
        if s >= length:
            break
        leg = min(np.searchsorted(s_way, s, side="right") - 1, len(speeds) - 1)
        target = speeds[leg]
        if stop_at_end:
            target = min(target, math.sqrt(2 * accel_mps2 * max(length - s, 0.0)))
        v += float(np.clip(target - v, -accel_mps2 * dt, accel_mps2 * dt))
        v = max(v, 0.15)              # never stall before the end
        s = min(s + v * dt, length)
    s_t, v_t = np.array(out_s), np.array(out_v)
    if stop_at_end:
        v_t[-1] = 0.0
    xz = np.stack([np.interp(s_t, s_path, path[:, 0]), np.interp(s_t, s_path, path[:, 1])], 1)
    # heading: path tangent, turned at most 270 deg/s
    ahead = np.stack([np.interp(np.minimum(s_t + 0.05, length), s_path, path[:, k]) for k in (0, 1)], 1)
    behind = np.stack([np.interp(np.maximum(s_t - 0.05, 0), s_path, path[:, k]) for k in (0, 1)], 1)
    d = ahead - behind
    raw = np.unwrap(np.arctan2(d[:, 0], d[:, 1]))
    heading = np.empty_like(raw)
    heading[0] = raw[0]
    max_step = math.radians(270.0) * dt
    for i in range(1, len(raw)):
        heading[i] = heading[i - 1] + np.clip(raw[i] - heading[i - 1], -max_step, max_step)
    phase = np.cumsum(stride_frequency_hz(v_t, body.height_m) * dt)
    amp = np.clip(v_t / 1.4, 0.0, 1.5) ** 0.8
    angles = gait_angles(phase, amp, style)
    if rng is not None:
        angles += sway(rng, len(angles), rate_hz, _sway_sd(0.7, 2.0, 1.5, 0.3), tau_s=0.6)
    # lateral pelvis sway at the step frequency
    side = np.stack([np.cos(heading), -np.sin(heading)], 1)    # the walker's left, in (x, z)
    xz = xz + side * (0.02 * amp * np.sin(2 * np.pi * phase))[:, None]
    return make_motion(body, rate_hz, angles, xz, heading, "walk")


def turn(body: Body, at_xz_m, from_heading_rad: float, to_heading_rad: float, duration_s: float = 1.5,
         rate_hz: float = DEFAULT_RATE_HZ) -> Motion:
    """Turn on the spot (small steps) from one heading to another, taking the short way round."""
    n = _n(duration_s, rate_hz)
    delta = (to_heading_rad - from_heading_rad + math.pi) % (2 * math.pi) - math.pi
    x = np.arange(n) / max(n - 1, 1)
    heading = from_heading_rad + delta * min_jerk(x)
    phase = np.arange(n) / rate_hz * stride_frequency_hz(1.0, body.height_m)
    amp = 0.35 * np.sin(np.pi * x)
    return make_motion(body, rate_hz, gait_angles(phase, amp), at_xz_m, heading, "turn")


# --- standing and working ----------------------------------------------------------------------
def stand(body: Body, at_xz_m, heading_rad: float, duration_s: float, rate_hz: float = DEFAULT_RATE_HZ,
          rng: np.random.Generator | None = None) -> Motion:
    """Stand at a point with postural sway (``rng``; none: perfectly still)."""
    n = _n(duration_s, rate_hz)
    a = _relaxed(rng)[None].repeat(n, 0)
    if rng is not None:
        a += sway(rng, n, rate_hz, _sway_sd(), tau_s=1.5)
    return make_motion(body, rate_hz, a, at_xz_m, heading_rad, "stand")


def _arm_ik(shoulder_yz, target_yz, l1, l2) -> tuple[float, float, bool]:
    """Sagittal two-link IK: (direction of the upper arm from straight down, deg; elbow flexion, deg; reachable)."""
    d = np.asarray(target_yz, float) - np.asarray(shoulder_yz, float)
    r = float(np.hypot(*d))
    ok = r <= 0.97 * (l1 + l2)
    r = min(max(r, abs(l1 - l2) + 1e-6), 0.97 * (l1 + l2))
    elbow = math.pi - math.acos(np.clip((l1 * l1 + l2 * l2 - r * r) / (2 * l1 * l2), -1, 1))
    to_target = math.atan2(d[1], -d[0])            # angle from straight down toward forward
    inner = math.acos(np.clip((l1 * l1 + r * r - l2 * l2) / (2 * l1 * r), -1, 1))
    return math.degrees(to_target - inner), math.degrees(elbow), ok


def work_posture(body: Body, work_height_m: float, reach_m: float, base: np.ndarray | None = None) -> np.ndarray:
    """Posture vector (15,) that puts both wrists at a work point ``work_height_m`` above the floor and
    ``reach_m`` in front of the pelvis (elbow down). The trunk leans (at most 60 deg, in 5 deg steps)
    only when the arms cannot reach from upright; the knees bend for very low points; the neck
    flexes so that the eyes look at the point (the eyes themselves take 15 deg)."""
    a = (_relaxed() if base is None else base).copy()
    hip_h = body.hip_height_m
    target = np.array([work_height_m - hip_h, reach_m])          # (up, forward) from the pelvis
    knee = 0.0
    if work_height_m < 0.45 * body.height_m:                     # low: bend the knees too
        knee = min(60.0, (0.45 * body.height_m - work_height_m) / body.height_m * 300)
        target[0] += body.thigh_m * (1 - math.cos(math.radians(knee / 2))) * 2
    for lean in np.arange(0.0, 61.0, 5.0):
        th = math.radians(lean)
        shoulder = np.array([body.trunk_m * math.cos(th), body.trunk_m * math.sin(th)])
        arm_dir, elbow, ok = _arm_ik(shoulder, target, body.upper_arm_m, body.forearm_m)
        if ok:
            break
    for side in ("left", "right"):
        a[_C(f"shoulder_flexion_deg.{side}")] = arm_dir + lean
        a[_C(f"elbow_flexion_deg.{side}")] = elbow
        a[_C(f"knee_flexion_deg.{side}")] = max(a[_C(f"knee_flexion_deg.{side}")], knee)
        a[_C(f"hip_flexion_deg.{side}")] = max(a[_C(f"hip_flexion_deg.{side}")], knee / 2)
        a[_C(f"shoulder_abduction_deg.{side}")] = 8.0
    a[_C("trunk_flexion_deg")] = lean
    eye = np.array([body.trunk_m * math.cos(th) + 0.1 * body.height_m, body.trunk_m * math.sin(th)])
    gaze = math.degrees(math.atan2(eye[0] - target[0], target[1] - eye[1]))   # below horizontal
    a[_C("neck_flexion_deg")] = float(np.clip(gaze - 15.0 - lean, -10.0, 60.0))
    return a


def work_at(body: Body, at_xz_m, heading_rad: float, duration_s: float, work_height_m: float | None = None,
            reach_m: float = 0.4, rate_hz: float = DEFAULT_RATE_HZ, rng: np.random.Generator | None = None,
            label: str = "work") -> Motion:
    """Stand at a point and work with both hands around a work point.

    ``work_height_m`` above the floor (default: elbow height, 0.63 H) and ``reach_m`` in front
    of the pelvis. Every 0.6-2 s the hands move (minimum jerk) to a new target within about
    +-12 cm of the work point, one hand at a time, and now and then reach further (x 1.4)."""
    rng = rng or np.random.default_rng(0)
    h = body.height_m * 0.63 if work_height_m is None else float(work_height_m)
    n = _n(duration_s, rate_hz)
    base = _relaxed(rng)
    times, keys, t = [0.0], [work_posture(body, h, reach_m, base)], 0.0
    while t < duration_s:
        t += rng.uniform(0.6, 2.0)
        far = rng.random() < 0.15
        key = work_posture(body, h + rng.normal(0, 0.06), reach_m * (1.4 if far else 1.0) + rng.normal(0, 0.06), base)
        # one hand at a time: keep the other where it was
        keep = "left" if rng.random() < 0.5 else "right"
        for n_ in ("shoulder_flexion_deg", "elbow_flexion_deg", "shoulder_abduction_deg"):
            key[_C(f"{n_}.{keep}")] = keys[-1][_C(f"{n_}.{keep}")]
        key[_C("trunk_twist_deg")] = rng.normal(0, 6)
        key[_C("neck_yaw_deg")] = rng.normal(0, 10)
        times.append(t)
        keys.append(key)
    a = keyframes(times, np.array(keys), rate_hz)[:n]
    a += sway(rng, n, rate_hz, _sway_sd(0.8, 2.0, 1.5, 0.5), tau_s=0.8)
    return make_motion(body, rate_hz, a, at_xz_m, heading_rad, label)


def look_down(body: Body, at_xz_m, heading_rad: float, duration_s: float, rate_hz: float = DEFAULT_RATE_HZ,
              rng: np.random.Generator | None = None) -> Motion:
    """Work on a low, close work-piece (0.80-0.95 m high, 0.30 m ahead), looking down at it."""
    rng = rng or np.random.default_rng(0)
    return work_at(body, at_xz_m, heading_rad, duration_s, work_height_m=rng.uniform(0.80, 0.95), reach_m=0.3,
                   rate_hz=rate_hz, rng=rng, label="look_down")


def _down_and_up(body, at_xz_m, heading_rad, low: np.ndarray, duration_s, hold_s, rate_hz, rng, label) -> Motion:
    """Upright -> ``low`` posture -> hold -> upright, minimum jerk, with sway."""
    up = _relaxed(rng)
    move = (duration_s - hold_s) / 2
    a = keyframes([0.0, move, move + hold_s, duration_s], np.stack([up, low, low, up]), rate_hz)
    if rng is not None:
        a += sway(rng, len(a), rate_hz, _sway_sd(1.0, 2.0, 2.0, 0.5), tau_s=0.8)
    return make_motion(body, rate_hz, a, at_xz_m, heading_rad, label)


def bend(body: Body, at_xz_m, heading_rad: float, depth_deg: float = 70.0, duration_s: float = 4.0,
         hold_s: float = 1.0, rate_hz: float = DEFAULT_RATE_HZ, rng: np.random.Generator | None = None) -> Motion:
    """Bend forward at the hips by ``depth_deg`` (knees a little bent, arms reaching down), hold, come back."""
    low = _relaxed(rng)
    low[_C("trunk_flexion_deg")] = depth_deg
    for side in ("left", "right"):
        low[_C(f"shoulder_flexion_deg.{side}")] = depth_deg + 10      # arms hang toward the floor
        low[_C(f"knee_flexion_deg.{side}")] = 15.0
        low[_C(f"hip_flexion_deg.{side}")] = 5.0
    low[_C("neck_flexion_deg")] = -10.0
    return _down_and_up(body, at_xz_m, heading_rad, low, duration_s, hold_s, rate_hz, rng, "bend")


def squat(body: Body, at_xz_m, heading_rad: float, depth: float = 1.0, duration_s: float = 5.0,
          hold_s: float = 2.0, rate_hz: float = DEFAULT_RATE_HZ, rng: np.random.Generator | None = None) -> Motion:
    """Squat down (``depth`` 1 = full: hips 115 deg, knees 130 deg, trunk 40 deg), hold, stand up."""
    low = _relaxed(rng)
    low[_C("trunk_flexion_deg")] = 40.0 * depth
    for side in ("left", "right"):
        low[_C(f"hip_flexion_deg.{side}")] = 115.0 * depth
        low[_C(f"knee_flexion_deg.{side}")] = 130.0 * depth
        low[_C(f"shoulder_flexion_deg.{side}")] = 45.0 * depth
        low[_C(f"elbow_flexion_deg.{side}")] = 40.0
    low[_C("neck_flexion_deg")] = 10.0
    return _down_and_up(body, at_xz_m, heading_rad, low, duration_s, hold_s, rate_hz, rng, "squat")


# --- sequences ---------------------------------------------------------------------------------
def concat(motions: Sequence[Motion], blend_s: float = 0.4) -> Motion:
    """Join motions of one body and rate; each one's first ``blend_s`` fades in from the previous last posture.

    Placement is taken as given (start each motion at the previous one's :attr:`Motion.end`)."""
    if not motions:
        raise ValueError("concat: no motions")
    body, rate = motions[0].body, motions[0].rate_hz
    parts = [motions[0].angles_deg]
    for m in motions[1:]:
        if m.body != body or m.rate_hz != rate:
            raise ValueError("concat: motions of different bodies or rates")
        a = m.angles_deg.copy()
        k = min(len(a), int(round(blend_s * rate)))
        if k:
            w = min_jerk(np.arange(1, k + 1) / (k + 1))[:, None]
            a[:k] = w * a[:k] + (1 - w) * parts[-1][-1]
        parts.append(a)
    heading = np.unwrap(np.concatenate([m.heading_rad for m in motions]))
    return make_motion(body, rate, np.concatenate(parts), np.concatenate([m.pelvis_xz_m for m in motions]),
                       heading, np.concatenate([m.labels for m in motions]))


ACTIVITIES = ("walk", "stand", "work", "look_down", "bend", "squat", "turn")


def random_activity(body: Body, rng: np.random.Generator, duration_s: float, rate_hz: float = DEFAULT_RATE_HZ,
                    area_xz_m=((-2.0, 2.0), (0.6, 4.0)), work_points_xz_m=((0.0, 0.9), (0.8, 1.0), (-0.8, 1.0))
                    ) -> Motion:
    """A random working session of about ``duration_s``: walks between work points and random spots in the
    area (x range, z range; robot frame, metres) at 0.5-2.0 m/s (sometimes curving), and at each stop one or
    two of stand / work / look_down / bend / squat / turn, facing the robot base when at a work point."""
    (x0, x1), (z0, z1) = area_xz_m
    wp = [np.asarray(p, float) for p in work_points_xz_m]
    xz = np.array([rng.uniform(x0, x1), rng.uniform(z0, z1)])
    heading = rng.uniform(-math.pi, math.pi)
    parts: list[Motion] = []
    total = 0.0
    while total < duration_s:
        at_work = rng.random() < 0.6
        goal = wp[rng.integers(len(wp))] + rng.normal(0, 0.15, 2) if at_work else \
            np.array([rng.uniform(x0, x1), rng.uniform(z0, z1)])
        if np.linalg.norm(goal - xz) > 0.6:
            via = [xz]
            if rng.random() < 0.4:                       # a curving path through a random point
                mid = (xz + goal) / 2 + rng.normal(0, 0.8, 2)
                via.append(mid)
            via.append(goal)
            speeds = rng.uniform(*SPEED_RANGE_MPS, size=len(via) - 1)
            parts.append(walk(body, np.array(via), speeds, rate_hz, corner_radius_m=rng.uniform(0.3, 1.5),
                              rng=rng, start_speed_mps=0.0,
                              style={"arm_swing": rng.uniform(0.5, 1.4), "stride": rng.uniform(0.85, 1.15),
                                     "lean_deg": rng.uniform(0, 6), "neck_deg": rng.uniform(0, 15)}))
            xz, heading = parts[-1].end
        face = heading_towards(xz, (0.0, 0.0)) if at_work else heading
        if abs((face - heading + math.pi) % (2 * math.pi) - math.pi) > 0.3:
            parts.append(turn(body, xz, heading, face, rng.uniform(0.8, 2.0), rate_hz))
            heading = face
        kind = rng.choice(["stand", "work", "look_down", "bend", "squat"] if at_work else ["stand", "bend", "squat"],
                          p=[0.1, 0.45, 0.25, 0.1, 0.1] if at_work else [0.6, 0.2, 0.2])
        d = rng.uniform(2.0, 8.0)
        if kind == "stand":
            parts.append(stand(body, xz, heading, d, rate_hz, rng))
        elif kind == "work":
            parts.append(work_at(body, xz, heading, d, work_height_m=rng.uniform(0.75, 1.4),
                                 reach_m=rng.uniform(0.25, 0.6), rate_hz=rate_hz, rng=rng))
        elif kind == "look_down":
            parts.append(look_down(body, xz, heading, d, rate_hz, rng))
        elif kind == "bend":
            parts.append(bend(body, xz, heading, rng.uniform(30, 85), max(d, 3.0), rng.uniform(0.3, 2.0), rate_hz, rng))
        else:
            parts.append(squat(body, xz, heading, rng.uniform(0.5, 1.0), max(d, 3.5), rng.uniform(0.5, 2.5),
                               rate_hz, rng))
        total = sum(len(p) for p in parts) / rate_hz
    return concat(parts)


# --- pose-space augmentation -------------------------------------------------------------------
RANDOM_LIMB_GROUPS: dict[str, tuple[str, ...]] = {
    "trunk": ("trunk_flexion_deg", "trunk_lateral_deg", "trunk_twist_deg"),
    "neck": ("neck_flexion_deg", "neck_yaw_deg"),
    "left_arm": ("shoulder_flexion_deg.left", "shoulder_abduction_deg.left", "elbow_flexion_deg.left"),
    "right_arm": ("shoulder_flexion_deg.right", "shoulder_abduction_deg.right", "elbow_flexion_deg.right"),
    "left_leg": ("hip_flexion_deg.left", "knee_flexion_deg.left"),
    "right_leg": ("hip_flexion_deg.right", "knee_flexion_deg.right"),
}
"""The groups of posture angles :func:`random_limbs` takes over, each on its own schedule."""
SHOULDER_ELEVATION_SUM_MAX_DEG = 200.0
"""Forward and sideways raise together at most this much (their positive parts): the two angles compose
by rotations, and both near 180 deg would turn the forearm's plane further than a shoulder rotates."""
SHANK_FROM_VERTICAL_MAX_DEG = 80.0
"""|hip flexion - knee flexion| at most this much: the shank points downward, so the knee stays above its
ankle and hence above the floor (the body stands on its lower ankle)."""


def random_limb_key(rng: np.random.Generator, group: str) -> np.ndarray:
    """One random target posture of a :data:`RANDOM_LIMB_GROUPS` group (its angles, in the group's order):
    uniform within each angle's range of motion (:data:`firmware_sim.people.human.ROM_DEG`), shoulders
    within :data:`SHOULDER_ELEVATION_SUM_MAX_DEG`, legs within :data:`SHANK_FROM_VERTICAL_MAX_DEG`."""
    names = RANDOM_LIMB_GROUPS[group]
    lo = np.array([ROM_DEG[n.split(".")[0]][0] for n in names])
    hi = np.array([ROM_DEG[n.split(".")[0]][1] for n in names])
    if group.endswith("_leg"):
        hip = rng.uniform(lo[0], hi[0])
        knee = rng.uniform(max(lo[1], hip - SHANK_FROM_VERTICAL_MAX_DEG), min(hi[1], hip + SHANK_FROM_VERTICAL_MAX_DEG))
        return np.array([hip, knee])
    while True:   # rejection: about 72 % of the shoulder box is accepted
        key = rng.uniform(lo, hi)
        if not group.endswith("_arm") or max(key[0], 0) + max(key[1], 0) <= SHOULDER_ELEVATION_SUM_MAX_DEG:
            return key


def random_limbs(m: Motion, rng: np.random.Generator, p_active: float = 0.5, hold_s=(0.5, 2.0),
                 tries: int = 10) -> Motion:
    """``m`` with each :data:`RANDOM_LIMB_GROUPS` group blended, part of the time, into a smooth random
    trajectory through its range of motion; placement (pelvis path, heading), labels and body kept.

    Per group, every U(``hold_s``) seconds a new key: a random target posture (:func:`random_limb_key`)
    and a blend weight, 1 with probability ``p_active``, else 0; both are interpolated with minimum jerk
    (:func:`keyframes`), and the group's angles become ``(1 - w) scripted + w random``. The scripted and
    the random postures are both within the ranges of motion and the joint-coupling limits above, and so
    is every blend of the two. A draw that puts a joint below the floor (a hand through it, about one
    frame in a thousand) is drawn again, up to ``tries`` times; then ``m`` is returned unchanged."""
    if not 0.0 <= p_active <= 1.0:
        raise ValueError(f"p_active: expected 0-1, got {p_active!r}")
    floor = m.joints_m[..., 1].min() if len(m) else 0.0
    floor = min(floor, -BASE_HEIGHT_M)
    for _ in range(tries):
        a = _random_limb_angles(m, rng, p_active, hold_s)
        joints = joints_from_angles(m.body, a, m.pelvis_xz_m, m.heading_rad)
        if joints[..., 1].min() >= floor:
            return Motion(m.body, m.rate_hz, a, m.pelvis_xz_m, m.heading_rad, m.labels, joints)
    return m


def _random_limb_angles(m: Motion, rng: np.random.Generator, p_active: float, hold_s) -> np.ndarray:
    """:func:`random_limbs`' angles (T, 15), clamped to the ranges of motion."""
    n = len(m)
    duration = n / m.rate_hz
    a = m.angles_deg.copy()
    for group, names in RANDOM_LIMB_GROUPS.items():
        times = [0.0]
        while times[-1] < duration:
            times.append(times[-1] + rng.uniform(*hold_s))
        keys = [np.append(random_limb_key(rng, group), float(rng.random() < p_active)) for _ in times]
        track = keyframes(times, np.array(keys), m.rate_hz)
        track = np.concatenate([track, np.repeat(track[-1:], max(0, n - len(track)), 0)])[:n]
        cols = [angle_column(c) for c in names]
        w = track[:, -1:]
        a[:, cols] = (1.0 - w) * a[:, cols] + w * track[:, :-1]
    return prepare_angles(a)       # the scripted motions' sway may leave a range by a degree; the joints clamp it
