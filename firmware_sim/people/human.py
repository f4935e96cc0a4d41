"""A simulated worker's body: the 17 Human3.6M joints from a height and a posture.

Everything robot-side starts from a worker's 3D joints: the camera simulator projects
them, the pose lifter is trained on them, the collision scenarios walk them around the
Sawyer and the posture optimiser scores them. This module is that body.

Skeleton
--------
The 17 joints, their order and parents are VideoPose3D's Human3.6M layout
(:mod:`edge_runtime.core.skeleton`): 0 hip (pelvis) ... 16 right wrist. Joint 9 is the nose
and joint 10 the top of the head (the crown), as in Human3.6M.

Segment lengths (Drillis & Contini, as fractions of the body height H)
----------------------------------------------------------------------
==================  =========  ==========================================================
length              fraction   notes
==================  =========  ==========================================================
upper arm           0.186 H    shoulder -> elbow
forearm             0.146 H    elbow -> wrist
hand                0.108 H    wrist -> fingertip (not a Human3.6M joint; for reach)
thigh               0.245 H    hip -> knee
shank               0.246 H    knee -> ankle
head                0.130 H    chin -> crown
shoulder width      0.259 H    between the shoulder joints (x 0.96 for "F")
hip width           0.191 H    between the hip joints (x 1.04 for "F")
trunk               0.288 H    pelvis -> thorax, = shoulder height 0.818 H - hip 0.530 H
neck                0.103 H    thorax -> nose (0.100 H up, 0.025 H forward when upright)
crown               0.085 H    nose -> crown (0.082 H up, 0.022 H back when upright)
==================  =========  ==========================================================

Standing upright (every angle 0) on the floor the heights above the floor are
therefore: shoulder (and thorax) 0.818 H, elbow 0.632 H (Drillis: 0.630 H),
wrist 0.486 H, hip 0.530 H, knee 0.285 H, ankle 0.039 H, nose 0.918 H, crown 1.000 H.
The sexes share the length fractions; "F" has 4 % narrower shoulders and 4 % wider
hips, a small, documented difference that gives the lifter's data some variety.

Frames
------
* Body frame (internal): origin at the pelvis, ``x`` to the person's LEFT, ``y`` up,
  ``z`` forward (right-handed).
* Robot frame (output): :mod:`edge_runtime.core.skeleton`'s -- ``y`` up, origin on top of the
  Sawyer base, the floor at ``y = -BASE_HEIGHT_M`` (-0.914 m). The body frame is turned
  about ``y`` by ``heading_rad`` and moved to ``pelvis_xz_m``: heading 0 faces ``+z``,
  and the facing direction is ``(sin heading, 0, cos heading)`` (heading +pi/2 faces ``+x``).

Posture angles (degrees; 0 everywhere = upright, arms hanging, knees straight)
------------------------------------------------------------------------------
=======================  ==============  =================================================
angle                    range (deg)     meaning
=======================  ==============  =================================================
trunk_flexion            -30 ... 90      pelvis->thorax tilted forward (negative: extension)
trunk_lateral            -35 ... 35      bent sideways, positive toward the person's RIGHT
trunk_twist              -45 ... 45      chest turned about the spine, positive to the LEFT
neck_flexion             -60 ... 70      head tilted forward relative to the trunk
neck_yaw                 -80 ... 80      head turned relative to the trunk, positive LEFT
shoulder_flexion         -60 ... 180     upper arm raised forward (negative: extension)
shoulder_abduction       -10 ... 180     upper arm raised sideways, away from the body
elbow_flexion              0 ... 150     0 = straight arm
hip_flexion              -30 ... 125     thigh raised forward (negative: extension)
knee_flexion               0 ... 150     0 = straight leg; the shank folds backward
=======================  ==============  =================================================

(Active ranges of motion of healthy adults, rounded, after the AAOS / Norkin & White
tables; the trunk is the whole thoraco-lumbar spine.) Angles outside a range are clamped
to it by default; ``strict=True`` refuses them with :class:`PostureError` instead.
Non-finite angles are always refused.

Composition: the trunk rotation is ``R_trunk = Rx(flexion) Rz(lateral) Ry(twist)`` in the
body frame (twist about the spine first, then the sideways bend, then the forward bend
at the hips); the head is ``R_trunk Rx(neck_flexion) Ry(neck_yaw)``. An upper arm is
first abducted in the frontal plane, then flexed about the trunk's left-right axis
(``Rz(+-abduction) Rx(-flexion)`` applied to "hanging"); the forearm continues in the
same plane, bent forward by the elbow flexion. The pelvis stays level; a thigh swings
forward by the hip flexion and the shank folds back by the knee flexion.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from edge_runtime.core import skeleton as sk
from edge_runtime.core.skeleton import BASE_HEIGHT_M

# --- anthropometry (fractions of height) ------------------------------------------------------
UPPER_ARM_FRAC = 0.186
FOREARM_FRAC = 0.146
HAND_FRAC = 0.108
THIGH_FRAC = 0.245
SHANK_FRAC = 0.246
HEAD_FRAC = 0.130
SHOULDER_WIDTH_FRAC = 0.259
HIP_WIDTH_FRAC = 0.191
SHOULDER_HEIGHT_FRAC = 0.818
ELBOW_HEIGHT_FRAC = 0.630
HIP_HEIGHT_FRAC = 0.530
KNEE_HEIGHT_FRAC = 0.285
NECK_UP_FRAC, NECK_FWD_FRAC = 0.100, 0.025       # thorax -> nose, upright
CROWN_UP_FRAC, CROWN_BACK_FRAC = 0.082, 0.022    # nose -> crown, upright
SPINE_AT = 0.45                                   # the spine joint, as a fraction of pelvis -> thorax
FEMALE_SHOULDER_SCALE, FEMALE_HIP_SCALE = 0.96, 1.04
HEIGHT_RANGE_M = (1.2, 2.3)
SEXES = ("F", "M")


class PostureError(ValueError):
    """A posture that cannot be built: a non-finite angle, or (strict) one outside its range of motion."""


@dataclass(frozen=True)
class Body:
    """One person's segment lengths (metres), derived from height by :meth:`from_height`.

    Build with :meth:`from_height`; vary single lengths with ``dataclasses.replace`` (the
    dataset does, for between-subject proportions)."""

    height_m: float
    sex: str = "M"
    upper_arm_m: float = 0.0        #: shoulder -> elbow
    forearm_m: float = 0.0          #: elbow -> wrist
    hand_m: float = 0.0             #: wrist -> fingertip (reach only; not a joint)
    thigh_m: float = 0.0            #: hip -> knee
    shank_m: float = 0.0            #: knee -> ankle
    head_m: float = 0.0             #: chin -> crown (documentation; the joints use neck/crown offsets)
    shoulder_width_m: float = 0.0   #: between the two shoulder joints
    hip_width_m: float = 0.0        #: between the two hip joints
    trunk_m: float = 0.0            #: pelvis -> thorax
    neck_m: float = 0.0             #: thorax -> nose
    crown_m: float = 0.0            #: nose -> crown

    @classmethod
    def from_height(cls, height_m: float, sex: str = "M") -> "Body":
        """Segment lengths as Drillis & Contini fractions of ``height_m`` (1.2-2.3 m); sex "F" or "M"."""
        h = float(height_m)
        if not np.isfinite(h) or not HEIGHT_RANGE_M[0] <= h <= HEIGHT_RANGE_M[1]:
            raise ValueError(f"height_m: expected {HEIGHT_RANGE_M[0]}-{HEIGHT_RANGE_M[1]} m, got {height_m!r}")
        if sex not in SEXES:
            raise ValueError(f"sex: expected 'F' or 'M', got {sex!r}")
        f = sex == "F"
        return cls(
            height_m=h, sex=sex,
            upper_arm_m=UPPER_ARM_FRAC * h, forearm_m=FOREARM_FRAC * h, hand_m=HAND_FRAC * h,
            thigh_m=THIGH_FRAC * h, shank_m=SHANK_FRAC * h, head_m=HEAD_FRAC * h,
            shoulder_width_m=SHOULDER_WIDTH_FRAC * h * (FEMALE_SHOULDER_SCALE if f else 1.0),
            hip_width_m=HIP_WIDTH_FRAC * h * (FEMALE_HIP_SCALE if f else 1.0),
            trunk_m=(SHOULDER_HEIGHT_FRAC - HIP_HEIGHT_FRAC) * h,
            neck_m=float(np.hypot(NECK_UP_FRAC, NECK_FWD_FRAC)) * h,
            crown_m=float(np.hypot(CROWN_UP_FRAC, CROWN_BACK_FRAC)) * h,
        )

    @property
    def hip_height_m(self) -> float:
        """Standing height of the hip joints (and the pelvis) above the floor."""
        return self.ankle_height_m + self.thigh_m + self.shank_m

    @property
    def ankle_height_m(self) -> float:
        """Height of the ankle joint above the floor (0.039 H: hip 0.530 H - thigh - shank)."""
        return (HIP_HEIGHT_FRAC - THIGH_FRAC - SHANK_FRAC) * self.height_m

    @property
    def arm_reach_m(self) -> float:
        """Shoulder -> fingertip with a straight arm."""
        return self.upper_arm_m + self.forearm_m + self.hand_m


# --- postures --------------------------------------------------------------------------------
ROM_DEG: dict[str, tuple[float, float]] = {
    "trunk_flexion_deg": (-30.0, 90.0),
    "trunk_lateral_deg": (-35.0, 35.0),
    "trunk_twist_deg": (-45.0, 45.0),
    "neck_flexion_deg": (-60.0, 70.0),
    "neck_yaw_deg": (-80.0, 80.0),
    "shoulder_flexion_deg": (-60.0, 180.0),
    "shoulder_abduction_deg": (-10.0, 180.0),
    "elbow_flexion_deg": (0.0, 150.0),
    "hip_flexion_deg": (-30.0, 125.0),
    "knee_flexion_deg": (0.0, 150.0),
}
"""Range of motion per posture field (degrees, inclusive); the paired fields apply to each side."""

SCALAR_FIELDS = ("trunk_flexion_deg", "trunk_lateral_deg", "trunk_twist_deg", "neck_flexion_deg", "neck_yaw_deg")
PAIRED_FIELDS = ("shoulder_flexion_deg", "shoulder_abduction_deg", "elbow_flexion_deg", "hip_flexion_deg",
                 "knee_flexion_deg")
VECTOR_FIELDS: tuple[str, ...] = SCALAR_FIELDS + tuple(
    f"{name}.{side}" for name in PAIRED_FIELDS for side in ("left", "right"))
"""Column names of a posture vector / angle array (15 columns, degrees)."""
N_ANGLES = len(VECTOR_FIELDS)
_LO = np.array([ROM_DEG[n.split(".")[0]][0] for n in VECTOR_FIELDS])
_HI = np.array([ROM_DEG[n.split(".")[0]][1] for n in VECTOR_FIELDS])
_COL = {n: i for i, n in enumerate(VECTOR_FIELDS)}


@dataclass(frozen=True)
class Posture:
    """Joint angles in degrees; 0 everywhere = upright, arms hanging, knees straight.

    Pairs are ``(left, right)``. Ranges and sign conventions: the module docstring."""

    trunk_flexion_deg: float = 0.0        #: forward bend of hip->thorax (negative = extension)
    trunk_lateral_deg: float = 0.0        #: sideways bend, positive toward the right
    trunk_twist_deg: float = 0.0          #: chest turned about the spine, positive to the left
    neck_flexion_deg: float = 0.0         #: forward bend of thorax->head (negative = extension)
    neck_yaw_deg: float = 0.0             #: head turned, positive to the left
    shoulder_flexion_deg: tuple[float, float] = (0.0, 0.0)    #: (left, right), forward raise of the upper arm
    shoulder_abduction_deg: tuple[float, float] = (0.0, 0.0)  #: (left, right), sideways raise
    elbow_flexion_deg: tuple[float, float] = (0.0, 0.0)       #: (left, right), 0 = straight arm
    hip_flexion_deg: tuple[float, float] = (0.0, 0.0)         #: (left, right), thigh forward
    knee_flexion_deg: tuple[float, float] = (0.0, 0.0)        #: (left, right), 0 = straight leg

    def to_vector(self) -> np.ndarray:
        """(15,) float64 angles in :data:`VECTOR_FIELDS` order."""
        vals = [float(getattr(self, n)) for n in SCALAR_FIELDS]
        for n in PAIRED_FIELDS:
            pair = getattr(self, n)
            if len(pair) != 2:
                raise PostureError(f"{n}: expected a (left, right) pair, got {pair!r}")
            vals += [float(pair[0]), float(pair[1])]
        return np.array(vals)

    @classmethod
    def from_vector(cls, v: Sequence[float]) -> "Posture":
        """The inverse of :meth:`to_vector`."""
        v = [float(x) for x in v]
        if len(v) != N_ANGLES:
            raise PostureError(f"posture vector: expected {N_ANGLES} angles, got {len(v)}")
        kw: dict = {n: v[i] for i, n in enumerate(SCALAR_FIELDS)}
        for k, n in enumerate(PAIRED_FIELDS):
            i = len(SCALAR_FIELDS) + 2 * k
            kw[n] = (v[i], v[i + 1])
        return cls(**kw)

    def violations(self) -> list[str]:
        """One line per angle outside its range of motion (empty when the posture is valid)."""
        return rom_violations(self.to_vector()[None])

    def clamped(self) -> "Posture":
        """This posture with every angle clamped to its range of motion."""
        return Posture.from_vector(np.clip(self.to_vector(), _LO, _HI))

    def replace(self, **changes) -> "Posture":
        """A copy with some fields changed (``dataclasses.replace``)."""
        return dataclasses.replace(self, **changes)


def rom_violations(angles_deg: np.ndarray) -> list[str]:
    """Lines naming each angle column of ``angles_deg`` (T, 15) that leaves its range (first offending frame)."""
    a = np.asarray(angles_deg, dtype=float).reshape(-1, N_ANGLES)
    out = []
    for j, name in enumerate(VECTOR_FIELDS):
        bad = np.flatnonzero((a[:, j] < _LO[j]) | (a[:, j] > _HI[j]))
        if bad.size:
            out.append(f"{name}: {a[bad[0], j]:g} deg outside {_LO[j]:g}..{_HI[j]:g}"
                       + (f" (frame {bad[0]})" if len(a) > 1 else ""))
    return out


def angle_column(name: str) -> int:
    """Column of a named angle in an angle array, e.g. ``"knee_flexion_deg.left"``."""
    return _COL[name]


# --- kinematics ------------------------------------------------------------------------------
def _rot(axis: int, a_rad: np.ndarray) -> np.ndarray:
    """(T, 3, 3) right-handed rotations by ``a_rad`` (T,) about body axis 0 (x), 1 (y) or 2 (z)."""
    c, s = np.cos(a_rad), np.sin(a_rad)
    R = np.zeros(a_rad.shape + (3, 3))
    i, j = [(1, 2), (2, 0), (0, 1)][axis]
    R[..., axis, axis] = 1.0
    R[..., i, i] = c
    R[..., j, j] = c
    R[..., i, j] = -s
    R[..., j, i] = s
    return R


def _apply(R: np.ndarray, v) -> np.ndarray:
    """(T, 3): each R[t] (T, 3, 3) applied to v (3,) or (T, 3)."""
    v = np.asarray(v, dtype=float)
    return np.einsum("tij,tj->ti", R, np.broadcast_to(v, R.shape[:-1]))


_DOWN = np.array([0.0, -1.0, 0.0])


def prepare_angles(angles_deg: np.ndarray, strict: bool = False) -> np.ndarray:
    """Check an angle array (T, 15) and clamp it to the ranges of motion (or raise, ``strict``)."""
    a = np.asarray(angles_deg, dtype=float)
    if a.ndim != 2 or a.shape[1] != N_ANGLES:
        raise PostureError(f"angles: expected shape (T, {N_ANGLES}), got {a.shape}")
    if not np.all(np.isfinite(a)):
        col = int(np.argwhere(~np.isfinite(a))[0, 1])
        raise PostureError(f"{VECTOR_FIELDS[col]}: not a finite angle")
    if strict:
        bad = rom_violations(a)
        if bad:
            raise PostureError("outside the range of motion: " + "; ".join(bad))
    return np.clip(a, _LO, _HI)


def joints_from_angles(body: Body, angles_deg: np.ndarray, pelvis_xz_m=(0.0, 0.0), heading_rad=0.0,
                       on_floor: bool = True, strict: bool = False) -> np.ndarray:
    """(T, 17, 3) robot-frame joints for T postures given as an angle array (T, 15), :data:`VECTOR_FIELDS`.

    ``pelvis_xz_m`` (2,) or (T, 2) and ``heading_rad`` scalar or (T,) place the body. With
    ``on_floor`` the pelvis height is set per frame so that the lower ankle sits at its
    standing height above the floor (the foot is on the ground); otherwise the pelvis is at
    the standing hip height. The fast path the motion generators use."""
    a = np.deg2rad(prepare_angles(angles_deg, strict))
    T = len(a)
    col = {n: a[:, i] for i, n in enumerate(VECTOR_FIELDS)}
    b = body
    P = np.zeros((T, sk.N_JOINTS, 3))

    # legs: pelvis level, thighs forward by hip flexion, shanks folded back by knee flexion
    for side, hip_j, knee_j, ankle_j, sign in (("right", sk.R_HIP, sk.R_KNEE, sk.R_ANKLE, -1.0),
                                               ("left", sk.L_HIP, sk.L_KNEE, sk.L_ANKLE, 1.0)):
        hf, kf = col[f"hip_flexion_deg.{side}"], col[f"knee_flexion_deg.{side}"]
        P[:, hip_j] = (sign * b.hip_width_m / 2, 0.0, 0.0)
        P[:, knee_j] = P[:, hip_j] + b.thigh_m * _apply(_rot(0, -hf), _DOWN)
        P[:, ankle_j] = P[:, knee_j] + b.shank_m * _apply(_rot(0, -(hf - kf)), _DOWN)

    # trunk, neck and head
    R_t = _rot(0, col["trunk_flexion_deg"]) @ _rot(2, col["trunk_lateral_deg"]) @ _rot(1, col["trunk_twist_deg"])
    P[:, sk.SPINE] = _apply(R_t, (0.0, SPINE_AT * b.trunk_m, 0.0))
    P[:, sk.THORAX] = _apply(R_t, (0.0, b.trunk_m, 0.0))
    R_n = R_t @ _rot(0, col["neck_flexion_deg"]) @ _rot(1, col["neck_yaw_deg"])
    h = b.height_m
    P[:, sk.NECK] = P[:, sk.THORAX] + _apply(R_n, (0.0, NECK_UP_FRAC * h, NECK_FWD_FRAC * h))
    P[:, sk.HEAD] = P[:, sk.NECK] + _apply(R_n, (0.0, CROWN_UP_FRAC * h, -CROWN_BACK_FRAC * h))

    # arms: abduct in the frontal plane, then flex forward; the forearm bends on in that plane
    for side, sh_j, el_j, wr_j, sign in (("left", sk.L_SHOULDER, sk.L_ELBOW, sk.L_WRIST, 1.0),
                                         ("right", sk.R_SHOULDER, sk.R_ELBOW, sk.R_WRIST, -1.0)):
        sf, ab, ef = (col[f"{n}.{side}"] for n in ("shoulder_flexion_deg", "shoulder_abduction_deg",
                                                   "elbow_flexion_deg"))
        R_ab = R_t @ _rot(2, sign * ab)
        P[:, sh_j] = P[:, sk.THORAX] + _apply(R_t, (sign * b.shoulder_width_m / 2, 0.0, 0.0))
        P[:, el_j] = P[:, sh_j] + b.upper_arm_m * _apply(R_ab @ _rot(0, -sf), _DOWN)
        P[:, wr_j] = P[:, el_j] + b.forearm_m * _apply(R_ab @ _rot(0, -(sf + ef)), _DOWN)

    # place in the robot frame
    heading = np.broadcast_to(np.asarray(heading_rad, dtype=float), (T,))
    xz = np.broadcast_to(np.asarray(pelvis_xz_m, dtype=float), (T, 2))
    if not (np.all(np.isfinite(heading)) and np.all(np.isfinite(xz))):
        raise PostureError("pelvis_xz_m / heading_rad: not finite")
    if on_floor:
        lowest = np.minimum(P[:, sk.L_ANKLE, 1], P[:, sk.R_ANKLE, 1])
        y0 = -BASE_HEIGHT_M + b.ankle_height_m - lowest
    else:
        y0 = np.full(T, -BASE_HEIGHT_M + b.hip_height_m)
    out = np.einsum("tij,tkj->tki", _rot(1, heading), P)
    out[..., 0] += xz[:, None, 0]
    out[..., 1] += y0[:, None]
    out[..., 2] += xz[:, None, 1]
    return out


def joints(body: Body, posture: Posture, pelvis_xz_m=(0.0, 0.0), heading_rad: float = 0.0,
           on_floor: bool = True, strict: bool = False) -> np.ndarray:
    """(17, 3) joint positions in the robot frame (metres, y up, floor at y = -BASE_HEIGHT_M), H36M order.

    heading 0 = the body faces +z. on_floor: the pelvis height is set so that the lower ankle
    touches the floor (sits at its standing height, 0.039 H). Angles outside their range of
    motion are clamped, or refused with :class:`PostureError` when ``strict``."""
    return joints_from_angles(body, posture.to_vector()[None], np.asarray(pelvis_xz_m, float)[None],
                              heading_rad, on_floor, strict)[0]


def joints_seq(body: Body, postures: Sequence[Posture] | np.ndarray, pelvis_xz_m=(0.0, 0.0), heading_rad=0.0,
               on_floor: bool = True, strict: bool = False) -> np.ndarray:
    """(T, 17, 3) for a sequence of :class:`Posture` (or an angle array (T, 15)); placement scalar or per frame."""
    if isinstance(postures, np.ndarray):
        angles = postures
    else:
        angles = np.stack([p.to_vector() for p in postures]) if len(postures) else np.zeros((0, N_ANGLES))
    return joints_from_angles(body, angles, pelvis_xz_m, heading_rad, on_floor, strict)


def facing(heading_rad: float) -> np.ndarray:
    """Unit vector (robot frame, horizontal) the body faces at ``heading_rad``."""
    return np.array([np.sin(heading_rad), 0.0, np.cos(heading_rad)])


def heading_towards(from_xz_m, to_xz_m) -> float:
    """The heading (rad) that faces from one floor point (x, z) toward another."""
    d = np.asarray(to_xz_m, float) - np.asarray(from_xz_m, float)
    return float(np.arctan2(d[0], d[1]))


def bone_lengths(j: np.ndarray) -> np.ndarray:
    """(..., 16) lengths of the (parent, child) bones of joints (..., 17, 3), :func:`edge_runtime.core.skeleton.bones` order."""
    bs = sk.bones()
    p = np.array([b[0] for b in bs])
    c = np.array([b[1] for b in bs])
    return np.linalg.norm(j[..., c, :] - j[..., p, :], axis=-1)
