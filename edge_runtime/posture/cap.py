"""The continuous awkward-posture (CAP) score: a continuous fit of RULA (dissertation chapter 4.2.1).

RULA scores each body part with a step function of a joint angle, so two
postures in the same band score alike and an optimiser sees no gradient. CAP
replaces each step function with a piecewise-linear curve through the RULA
score at the midpoint of every band, so CAP equals RULA there and has a slope
everywhere else. Flexion and extension are scored alike (the dissertation's
choice), and a knee flexed beyond 20 degrees adds up to 4 (linearly).

Joint angles (degrees) from the 17 Human3.6M joints (``edge_runtime.core.skeleton``
order, robot frame: y up). All the reference vectors, stated once:

* ``up`` = world +y. ``right`` = left_hip -> right_hip plus left_shoulder ->
  right_shoulder, made horizontal. ``forward`` = up x right (the way the
  worker faces).
* trunk axis ``t`` = hip (pelvis) -> thorax. The trunk frame is ``t`` (its
  up), ``right`` made orthogonal to ``t`` (``r_t``) and ``f_t = t x r_t``
  (its forward).
* **trunk flexion** = the angle of ``t`` from ``up`` in the sagittal plane
  (``up``, ``forward``); positive forward. Lateral bend is not scored (RULA's
  +1 for side bending is left out, as in the dissertation).
* **neck flexion** = the angle of thorax -> head in the sagittal plane minus
  the trunk flexion, i.e. relative to the trunk; positive forward,
  negative = extension.
* **upper-arm flexion** = atan2(u . f_t, -u . t) for u = shoulder -> elbow:
  0 = hanging along the trunk, 90 = forward horizontal, negative = extension.
  **abduction** = asin(u . outward) with outward = +r_t (right arm) or -r_t
  (left arm): the angle out of the sagittal plane, positive away from the
  body. **elevation** = the angle between u and -t (flexion and abduction
  together, the "shoulder elevation" of the dissertation's discussion); the
  upper-arm part is scored on it.
* **elbow flexion** = 180 - the angle shoulder-elbow-wrist (0 = straight arm),
  RULA's lower-arm angle.
* **knee flexion** = 180 - the angle hip-knee-ankle (0 = straight leg).

The RULA bands (docs/design.md section 5) and the CAP knots, at band midpoints
(an open-ended band is taken as wide as the band before it):

=========  ==========================================  ==========================================
part       RULA                                        CAP knots (angle deg -> score)
=========  ==========================================  ==========================================
upper arm  -20..20 = 1, 20..45 = 2, 45..90 = 3, >90 = 4  0 -> 1, 32.5 -> 2, 67.5 -> 3, 112.5 -> 4
lower arm  60..100 = 1, else 2                         30 -> 2, 80 -> 1, 130 -> 2
neck       0..10 = 1, 10..20 = 2, >20 = 3, extension 4  5 -> 1, 15 -> 2, 25 -> 3
trunk      upright = 1, 0..20 = 2, 20..60 = 3, >60 = 4  0 -> 1, 10 -> 2, 40 -> 3, 80 -> 4
=========  ==========================================  ==========================================

Between knots CAP is linear; beyond the last knot it continues with the last
slope; below the first knot it holds the first score (the neck is 1 from 0
to 5 degrees). Where CAP differs from RULA by design: extension is scored like
flexion of the same size (RULA gives the neck 4 for any extension, and the
upper arm 2 for any extension beyond 20 degrees); a straight elbow scores 2.6
rather than 2 (the line continues); and the upper arm is scored on its
elevation, so abduction raises it smoothly instead of RULA's +1.

Parts are combined as ``sum(w_part * score_part ** power)`` over neck, trunk,
upper arm, lower arm and knee penalty (arms and knees: the mean of left and
right). Missing (NaN or infinite) joints never give a number: the result is
invalid and says which joints were missing.
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

from edge_runtime import config
from edge_runtime.core.skeleton import (
    HEAD,
    HIP,
    JOINTS,
    L_ANKLE,
    L_ELBOW,
    L_HIP,
    L_KNEE,
    L_SHOULDER,
    L_WRIST,
    R_ANKLE,
    R_ELBOW,
    R_HIP,
    R_KNEE,
    R_SHOULDER,
    R_WRIST,
    THORAX,
)

PARTS: tuple[str, ...] = ("neck", "trunk", "upper_arm", "lower_arm", "knee")
"""The CAP parts, in the order of their weights in :class:`CapParams`."""

KNOTS: dict[str, tuple[tuple[float, ...], tuple[float, ...]]] = {
    "upper_arm": ((0.0, 32.5, 67.5, 112.5), (1.0, 2.0, 3.0, 4.0)),
    "lower_arm": ((30.0, 80.0, 130.0), (2.0, 1.0, 2.0)),
    "neck": ((5.0, 15.0, 25.0), (1.0, 2.0, 3.0)),
    "trunk": ((0.0, 10.0, 40.0, 80.0), (1.0, 2.0, 3.0, 4.0)),
}
"""CAP knots per part: (angles in degrees, scores) at the RULA band midpoints."""

KNEE_PENALTY = 4.0
"""Score added for a deep squat (the dissertation's "+4 when the knee angle is over 20 degrees")."""
KNEE_PENALTY_START_DEG = 20.0
"""Knee flexion (deg) where the penalty starts to rise."""
KNEE_PENALTY_FULL_DEG = 40.0
"""Knee flexion (deg) where the penalty reaches KNEE_PENALTY (linear in between, constant beyond)."""

NEEDED: tuple[int, ...] = (HIP, R_HIP, R_KNEE, R_ANKLE, L_HIP, L_KNEE, L_ANKLE, THORAX, HEAD,
                           L_SHOULDER, L_ELBOW, L_WRIST, R_SHOULDER, R_ELBOW, R_WRIST)
"""Joints CAP reads (all but spine and neck_nose)."""


@config.section("cap")
@dataclass(frozen=True)
class CapParams:
    """How the part scores combine into one CAP (the box's [cap] configuration section)."""

    neck_weight: float = 1.0
    """Weight of the neck score (>= 0). Doubling it personalises for a sore neck (Fig. 4.11)."""
    trunk_weight: float = 1.0
    """Weight of the trunk score (>= 0)."""
    upper_arm_weight: float = 1.0
    """Weight of the upper-arm score (>= 0; mean of left and right)."""
    lower_arm_weight: float = 1.0
    """Weight of the lower-arm score (>= 0; mean of left and right)."""
    knee_weight: float = 1.0
    """Weight of the knee penalty (>= 0; 0 .. 4 per knee, mean of left and right)."""
    power: int = 1
    """1 = linear sum (the dissertation's default), 2 = square, 3 = cubic: sum(w * score ** power),
    which penalises one bad part more than several mediocre ones."""

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "power":
                ok = isinstance(v, int) and not isinstance(v, bool) and v in (1, 2, 3)
                need = "1, 2 or 3"
            else:
                ok = isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) and v >= 0
                need = "a finite number >= 0"
            if not ok:
                raise ValueError(f"[cap] {f.name}: must be {need}, got {v!r}")
        if not any(getattr(self, f"{p}_weight") > 0 for p in PARTS):
            raise ValueError("[cap] neck_weight: at least one weight must be positive (all are 0)")

    def weights(self) -> dict[str, float]:
        """Part name -> weight."""
        return {p: float(getattr(self, f"{p}_weight")) for p in PARTS}

    def with_weights(self, **weights: float) -> "CapParams":
        """A copy with some part weights replaced, e.g. ``with_weights(neck=2.0)``."""
        unknown = set(weights) - set(PARTS)
        if unknown:
            raise ValueError(f"[cap] {sorted(unknown)[0]}_weight: unknown part (known: {', '.join(PARTS)})")
        kw = {f.name: getattr(self, f.name) for f in fields(self)}
        kw.update({f"{p}_weight": float(w) for p, w in weights.items()})
        return CapParams(**kw)


@dataclass(frozen=True)
class JointAngles:
    """The angles CAP reads (degrees); see the module docstring for their reference vectors.
    Sided angles are (left, right)."""

    trunk_flexion_deg: float
    neck_flexion_deg: float
    upper_arm_flexion_deg: tuple[float, float]
    upper_arm_abduction_deg: tuple[float, float]
    upper_arm_elevation_deg: tuple[float, float]
    elbow_flexion_deg: tuple[float, float]
    knee_flexion_deg: tuple[float, float]


@dataclass(frozen=True)
class CapResult:
    """One CAP evaluation. ``valid`` False: ``cap`` is NaN and ``reason`` says why."""

    valid: bool
    cap: float
    parts: dict[str, float]
    """Unweighted part scores (neck, trunk, upper_arm, lower_arm, knee); empty when invalid."""
    angles: JointAngles | None
    reason: str = ""

    def as_dict(self) -> dict:
        """JSON-ready form."""
        out = {"valid": self.valid, "cap": None if not self.valid else round(self.cap, 6),
               "parts": {k: round(v, 6) for k, v in self.parts.items()}}
        if self.angles is not None:
            out["angles_deg"] = {f.name.removesuffix("_deg"): np.round(getattr(self.angles, f.name), 3).tolist()
                                 for f in fields(self.angles)}
        if self.reason:
            out["reason"] = self.reason
        return out


def part_curve(part: str, angle_deg):
    """CAP score of one part (``upper_arm``, ``lower_arm``, ``neck``, ``trunk``) at ``angle_deg``.

    Flexion and extension alike (the absolute angle), except the lower arm whose angle is
    the elbow flexion itself. Linear between knots, the last slope beyond the last knot,
    the first score below the first knot."""
    xs, ys = KNOTS[part]
    a = np.asarray(angle_deg, dtype=float)
    if part != "lower_arm":
        a = np.abs(a)
    y = np.interp(a, xs, ys)
    slope = (ys[-1] - ys[-2]) / (xs[-1] - xs[-2])
    return np.where(a > xs[-1], ys[-1] + slope * (a - xs[-1]), y)


def knee_penalty(knee_flexion_deg):
    """0 up to 20 degrees of knee flexion, rising linearly to 4 at 40 degrees, 4 beyond."""
    ramp_deg = KNEE_PENALTY_FULL_DEG - KNEE_PENALTY_START_DEG
    k = (np.asarray(knee_flexion_deg, dtype=float) - KNEE_PENALTY_START_DEG) / ramp_deg
    return KNEE_PENALTY * np.clip(k, 0.0, 1.0)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.sqrt(np.sum(v * v, axis=-1, keepdims=True))


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.sum(a * b, axis=-1)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """np.cross for (..., 3), without its per-call overhead (this runs once per camera frame)."""
    return np.stack([a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1],
                     a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2],
                     a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]], axis=-1)


def _angle_between_deg(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(_dot(_unit(a), _unit(b)), -1.0, 1.0)))


_SIDES = np.array([[L_SHOULDER, L_ELBOW, L_WRIST, L_HIP, L_KNEE, L_ANKLE],
                   [R_SHOULDER, R_ELBOW, R_WRIST, R_HIP, R_KNEE, R_ANKLE]])
_OUTWARD = np.array([-1.0, 1.0])       # outward = -r_t for the left arm, +r_t for the right


def joint_angles_array(joints: np.ndarray) -> dict[str, np.ndarray]:
    """The CAP angles (degrees) for ``(..., 17, 3)`` robot-frame joints, vectorised.

    Returns arrays of shape ``(...)`` for ``trunk_flexion``, ``neck_flexion`` and shape
    ``(..., 2)`` (left, right) for ``upper_arm_flexion``, ``upper_arm_abduction``,
    ``upper_arm_elevation``, ``elbow_flexion``, ``knee_flexion``. Missing joints give NaN."""
    j = np.asarray(joints, dtype=float)
    if j.shape[-2:] != (17, 3):
        raise ValueError(f"joints: expected shape (..., 17, 3), got {j.shape}")
    right = (j[..., R_HIP, :] - j[..., L_HIP, :]) + (j[..., R_SHOULDER, :] - j[..., L_SHOULDER, :])
    right = right * np.array([1.0, 0.0, 1.0])                          # horizontal
    right = _unit(right)
    forward = _cross(np.array([0.0, 1.0, 0.0]), right)

    t = j[..., THORAX, :] - j[..., HIP, :]
    trunk = np.degrees(np.arctan2(_dot(t, forward), t[..., 1]))
    n = j[..., HEAD, :] - j[..., THORAX, :]
    neck = np.degrees(np.arctan2(_dot(n, forward), n[..., 1])) - trunk

    t_u = _unit(t)
    r_t = _unit(right - _dot(right, t_u)[..., None] * t_u)
    f_t = _cross(t_u, r_t)
    sh, el, wr, hip, kn, an = (j[..., _SIDES[:, k], :] for k in range(6))          # (..., 2, 3) each
    u = _unit(el - sh)
    down_along = -_dot(u, t_u[..., None, :])
    return {"trunk_flexion": trunk, "neck_flexion": neck,
            "upper_arm_flexion": np.degrees(np.arctan2(_dot(u, f_t[..., None, :]), down_along)),
            "upper_arm_abduction": np.degrees(np.arcsin(np.clip(_OUTWARD * _dot(u, r_t[..., None, :]), -1.0, 1.0))),
            "upper_arm_elevation": np.degrees(np.arccos(np.clip(down_along, -1.0, 1.0))),
            "elbow_flexion": 180.0 - _angle_between_deg(sh - el, wr - el),
            "knee_flexion": 180.0 - _angle_between_deg(hip - kn, an - kn)}


def part_scores_array(angles: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Unweighted part scores from :func:`joint_angles_array` output (arms and knees: mean of both sides)."""
    return {
        "neck": part_curve("neck", angles["neck_flexion"]),
        "trunk": part_curve("trunk", angles["trunk_flexion"]),
        "upper_arm": part_curve("upper_arm", angles["upper_arm_elevation"]).mean(-1),
        "lower_arm": part_curve("lower_arm", angles["elbow_flexion"]).mean(-1),
        "knee": knee_penalty(angles["knee_flexion"]).mean(-1),
    }


def combine(parts: dict[str, np.ndarray], params: CapParams = CapParams()) -> np.ndarray:
    """sum(w * score ** power) over the parts."""
    w = params.weights()
    return sum(w[p] * np.asarray(parts[p], dtype=float) ** params.power for p in PARTS)


def cap_array(joints: np.ndarray, params: CapParams = CapParams()) -> np.ndarray:
    """CAP for ``(..., 17, 3)`` joints, vectorised; NaN where a needed joint is missing."""
    j = np.asarray(joints, dtype=float)
    with np.errstate(invalid="ignore", divide="ignore"):
        c = combine(part_scores_array(joint_angles_array(j)), params)
    bad = ~np.isfinite(j[..., list(NEEDED), :]).all(axis=(-1, -2))
    return np.where(bad, np.nan, c)


def missing_joints(joints: np.ndarray) -> list[str]:
    """Names of the joints CAP needs that are NaN or infinite in one ``(17, 3)`` pose."""
    ok = np.isfinite(np.asarray(joints, dtype=float)[list(NEEDED)]).all(axis=1)
    return [JOINTS[NEEDED[k]] for k in np.flatnonzero(~ok)]


def cap_score(joints: np.ndarray, params: CapParams = CapParams()) -> CapResult:
    """CAP of one ``(17, 3)`` robot-frame pose, with its parts and angles, or an invalid result
    naming the missing joints (never a silent number)."""
    j = np.asarray(joints, dtype=float)
    if j.shape != (17, 3):
        return CapResult(False, float("nan"), {}, None, f"expected a (17, 3) pose, got shape {j.shape}")
    missing = missing_joints(j)
    if missing:
        return CapResult(False, float("nan"), {}, None, "missing joints: " + ", ".join(missing))
    with np.errstate(invalid="ignore", divide="ignore"):
        a = joint_angles_array(j)
        parts = part_scores_array(a)
    if not np.isfinite(np.concatenate([np.ravel(v) for v in a.values()])).all():
        return CapResult(False, float("nan"), {}, None, "degenerate skeleton: a zero-length bone or no left-right axis")
    parts_f = {p: float(v) for p, v in parts.items()}
    angles = JointAngles(
        trunk_flexion_deg=float(a["trunk_flexion"]), neck_flexion_deg=float(a["neck_flexion"]),
        **{f"{k}_deg": (float(a[k][0]), float(a[k][1]))
           for k in ("upper_arm_flexion", "upper_arm_abduction", "upper_arm_elevation", "elbow_flexion",
                     "knee_flexion")})
    return CapResult(True, float(combine(parts_f, params)), parts_f, angles)


def cycle_cap(frames: np.ndarray, params: CapParams = CapParams(), min_valid_fraction: float = 0.5) -> CapResult:
    """CAP of one task cycle seen as ``(T, 17, 3)`` frames: the frame whose CAP is the median of
    the valid frames (so its parts and angles belong to one real pose). Invalid when fewer than
    ``min_valid_fraction`` of the frames are valid (the worker left or was not seen)."""
    f = np.asarray(frames, dtype=float)
    if f.ndim != 3 or f.shape[1:] != (17, 3) or len(f) == 0:
        return CapResult(False, float("nan"), {}, None, f"expected (T, 17, 3) frames, got shape {f.shape}")
    caps = cap_array(f, params)
    ok = np.isfinite(caps)
    if ok.sum() < max(1, min_valid_fraction * len(f)):
        return CapResult(False, float("nan"), {}, None,
                         f"only {int(ok.sum())} of {len(f)} frames had every joint CAP needs")
    idx = np.flatnonzero(ok)
    med = idx[np.argsort(caps[idx])[(len(idx) - 1) // 2]]
    return cap_score(f[med], params)


__all__ = ["CapParams", "CapResult", "JointAngles", "PARTS", "KNOTS", "cap_score", "cap_array", "cycle_cap",
           "joint_angles_array", "part_scores_array", "part_curve", "knee_penalty", "combine", "missing_joints"]
