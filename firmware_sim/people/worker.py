"""The simulated worker of chapter 4: a person inserting wires into a breadboard the robot holds.

Setting (robot frame, y up, :mod:`edge_runtime.core.skeleton`)
---------------------------------------------------------
The breadboard (17 x 5.5 cm) is held by the end effector with its centre at
``(x_wp, h - 0.914, z_wp)``: ``h`` is its height above the floor and its pitch
``a`` tilts it about the robot x axis, face normal ``n = (0, cos a, sin a)``
(a > 0 turns the face toward the worker). The worker stands on the work side,
facing the robot (heading pi), pelvis at ``(x_wp, z_wp + d)``, both hands on
the board's near edge and eyes on the board.

Posture = the body's comfort optimum
------------------------------------
For a given (h, a) the worker takes the posture that minimises an internal
comfort cost (:class:`Style`) over the body model's angles
(:mod:`firmware_sim.people.human`): standing distance d, trunk flexion, neck flexion,
shoulder flexion, elbow flexion and knee flexion (hips flex by half the knee
angle, so a squat keeps the feet under the hips), subject to

* **reach**: the wrists at the grasp point on the board's near edge (equality
  constraint in the sagittal plane; the body model's arm moves in a plane through
  its shoulder, so the hands are taken to meet the board's ends sideways);
* **gaze**: the line of sight from the eyes (the nose joint) to the board centre
  is within the eyes' rotation range from the head's normal line of sight (15 deg
  below the head's forward direction), and the board's face is seen at most
  ``view_max_deg`` off its normal.

The comfort cost is a sum of squared, style-weighted deviations: trunk, neck,
eye rotation, shoulder elevation, elbow angle away from 90 deg, knee flexion, and
seeing the board from too far -- eyes-to-board distance over the square root of
the cosine of the viewing angle, since a board seen obliquely shows its holes
closer together (fine wire insertion needs the eyes near). It is *not* CAP: CAP's
neck slope is steep and its arm slope shallow, while a person's own sense of
comfort may weigh them the other way, which is why the Worker-selected position
(this cost's optimum over (h, a)) can disagree with CAP's (Fig. 4.10).

Styles (Fig. 4.9): **eye-movers** keep the neck straight and look down with their
eyes (cheap eye rotation, costly neck flexion); **neck-benders** bend the neck and
keep the eyes near their rest direction. Some workers dislike raising their arms
(``shoulder_weight`` high) and choose a low board with the neck flexed (the three
of Fig. 4.10). The scipy solution is the worker's typical posture at (h, a); each
repetition adds independent variation to the angles (:attr:`Style.trunk_sd_deg`)
and to the standing distance, as people never repeat a posture exactly.

Cohort (docs/design.md section 5): 172 +/- 11 cm, half women, half men (women
165 +/- 7.5 cm, men 179 +/- 7.5 cm), segment lengths from height (Drillis & Contini).
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass, replace

import numpy as np
from scipy.optimize import minimize

from edge_runtime.core.skeleton import BASE_HEIGHT_M, NECK, R_ELBOW, R_WRIST
from firmware_sim.people.human import N_ANGLES, Body, Posture, angle_column, joints_from_angles

NORMAL_LINE_OF_SIGHT_DEG = 15.0
"""The eyes' rest direction, below the head's forward direction (deg)."""
BOARD_DEPTH_M = 0.055
"""Breadboard size along the tilt direction (m); 0.17 m across."""
GRASP_ABOVE_M = 0.03
"""The wrist sits this far above the board's face (m) when the fingers are on it."""
GRASP_BACK_HAND_FRACTION = 0.35
"""The wrist sits this fraction of a hand length back from the near edge, toward the worker."""
DEFAULT_WORKPIECE_XZ_M = (0.0, 0.70)
"""Horizontal position of the breadboard centre in front of the robot (m)."""
COHORT_HEIGHT_M = {"F": (1.65, 0.075), "M": (1.79, 0.075)}
"""Height mean and SD per sex (m): pooled 1.72 +/- 0.10 m for a 10 F / 10 M cohort."""

# x = [d_m, trunk_deg, neck_deg, shoulder_flexion_deg, elbow_flexion_deg, knee_deg]
_VARS = ("standing_distance_m", "trunk_flexion_deg", "neck_flexion_deg", "shoulder_flexion_deg",
         "elbow_flexion_deg", "knee_flexion_deg")
_BOUNDS = ((0.15, 0.95), (-10.0, 80.0), (-40.0, 65.0), (-30.0, 170.0), (0.0, 145.0), (0.0, 100.0))
_COLS = {name: [angle_column(f"{name}.left"), angle_column(f"{name}.right")]
         for name in ("shoulder_flexion_deg", "shoulder_abduction_deg", "elbow_flexion_deg", "hip_flexion_deg",
                      "knee_flexion_deg")}
_TRUNK, _NECK = angle_column("trunk_flexion_deg"), angle_column("neck_flexion_deg")


@dataclass(frozen=True)
class Style:
    """A worker's sense of comfort: weights on squared, normalised deviations (dimensionless)."""

    kind: str = "eye-mover"
    """"eye-mover" or "neck-bender" (Fig. 4.9), for the record; the weights carry the behaviour."""
    trunk_weight: float = 1.0
    """Per (trunk flexion / 10 deg)^2: people bend the neck before the back to look down."""
    neck_weight: float = 1.0
    """Per (neck flexion / 15 deg)^2 (extension counts double)."""
    eye_weight: float = 1.0
    """Per (eye rotation from the normal line of sight / 15 deg)^2."""
    shoulder_weight: float = 1.0
    """Per (shoulder flexion / 30 deg)^2."""
    elbow_weight: float = 0.3
    """Per ((elbow flexion - 90 deg) / 40 deg)^2."""
    knee_weight: float = 2.0
    """Per (knee flexion / 15 deg)^2."""
    visual_weight: float = 1.0
    """Per (metres the eyes are beyond the viewing distance / 0.1 m)^2, the distance taken as
    eyes-to-board / sqrt(cos(angle off the board's normal)): a board seen obliquely shows its
    holes closer together, so it must be seen from nearer. Fine wire insertion needs the eyes close."""
    viewing_distance_m: float = 0.45
    """The farthest the eyes may be from a face-on board for this fine task without effort (m)."""
    eye_down_max_deg: float = 40.0
    """Largest downward eye rotation from the normal line of sight (deg)."""
    view_max_deg: float = 70.0
    """Largest angle between the board's normal and the line of sight at which the holes can be seen (deg)."""
    abduction_deg: float = 8.0
    """Habitual sideways raise of the upper arms (deg)."""
    trunk_sd_deg: float = 1.0
    """Repetition-to-repetition SD of the trunk flexion (deg)."""
    neck_sd_deg: float = 1.5
    """Repetition-to-repetition SD of the neck flexion (deg)."""
    shoulder_sd_deg: float = 1.5
    """Repetition-to-repetition SD of each shoulder's flexion (deg)."""
    elbow_sd_deg: float = 2.0
    """Repetition-to-repetition SD of each elbow's flexion (deg)."""
    distance_sd_m: float = 0.01
    """Repetition-to-repetition SD of the standing distance (m)."""


EYE_MOVER = Style("eye-mover", neck_weight=1.6, eye_weight=0.5)
NECK_BENDER = Style("neck-bender", neck_weight=0.5, eye_weight=2.0, eye_down_max_deg=25.0)


@dataclass(frozen=True)
class WorkPosture:
    """The worker's posture at one end-effector pose."""

    posture: Posture
    standing_distance_m: float
    """Pelvis to the board centre, horizontally (m)."""
    cost: float
    """The comfort cost (this worker's own, not CAP)."""
    eye_rotation_deg: float
    """Eyes below their normal line of sight (deg)."""
    view_deg: float
    """Angle between the board's normal and the line of sight (deg)."""
    reach_error_m: float
    """Distance of the wrists from the grasp point (m); ~0 when the board is within reach."""


@dataclass(frozen=True)
class Worker:
    """One simulated participant."""

    pid: int
    body: Body
    style: Style = EYE_MOVER
    workpiece_xz_m: tuple[float, float] = DEFAULT_WORKPIECE_XZ_M

    @property
    def label(self) -> str:
        return f"P{self.pid:02d}"

    # -- geometry ------------------------------------------------------------------------
    def board(self, height_m: float, pitch_deg: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(centre, face normal, wrist target) in the robot frame for a board height above the floor and pitch."""
        a = math.radians(pitch_deg)
        x, z = self.workpiece_xz_m
        centre = np.array([x, height_m - BASE_HEIGHT_M, z])
        normal = np.array([0.0, math.cos(a), math.sin(a)])
        toward = np.array([0.0, -math.sin(a), math.cos(a)])         # in the board's plane, toward the worker
        wrist = (centre + normal * GRASP_ABOVE_M + toward * (BOARD_DEPTH_M / 2)
                 + np.array([0.0, 0.0, GRASP_BACK_HAND_FRACTION * self.body.hand_m]))
        return centre, normal, wrist

    def angles(self, x: np.ndarray) -> np.ndarray:
        """(k, 15) body-model angles for (k, 6) solver variables."""
        x = np.atleast_2d(x)
        a = np.zeros((len(x), N_ANGLES))
        a[:, _TRUNK] = x[:, 1]
        a[:, _NECK] = x[:, 2]
        a[:, _COLS["shoulder_flexion_deg"]] = x[:, 3:4]
        a[:, _COLS["shoulder_abduction_deg"]] = self.style.abduction_deg
        a[:, _COLS["elbow_flexion_deg"]] = x[:, 4:5]
        a[:, _COLS["knee_flexion_deg"]] = x[:, 5:6]
        a[:, _COLS["hip_flexion_deg"]] = x[:, 5:6] / 2
        return a

    def joints_for(self, x: np.ndarray) -> np.ndarray:
        """(k, 17, 3) robot-frame joints for (k, 6) solver variables."""
        x = np.atleast_2d(x)
        xz = np.column_stack([np.full(len(x), self.workpiece_xz_m[0]), self.workpiece_xz_m[1] + x[:, 0]])
        return joints_from_angles(self.body, self.angles(x), xz, math.pi)

    def _terms(self, x: np.ndarray, height_m: float, pitch_deg: float) -> dict[str, np.ndarray]:
        """Cost terms, reach residual and gaze angles for (k, 6) variables."""
        x = np.atleast_2d(x)
        j = self.joints_for(x)
        centre, normal, wrist_target = self.board(height_m, pitch_deg)
        eye = j[:, NECK]
        sight = centre - eye                                        # eyes -> board
        horiz = eye[:, 2] - centre[2]                               # the worker faces -z
        depression = np.degrees(np.arctan2(-sight[:, 1], horiz))    # line of sight below horizontal
        eye_rot = depression - (x[:, 1] + x[:, 2]) - NORMAL_LINE_OF_SIGHT_DEG
        to_eye = -sight / np.linalg.norm(sight, axis=1, keepdims=True)
        cos_view = np.clip(to_eye @ normal, -1.0, 1.0)
        view = np.degrees(np.arccos(cos_view))
        seen_at = np.linalg.norm(sight, axis=1) / np.sqrt(np.maximum(cos_view, 0.04))
        s = self.style
        neck = x[:, 2]
        terms = {
            "trunk": s.trunk_weight * (x[:, 1] / 10.0) ** 2,
            "neck": s.neck_weight * (np.where(neck < 0, 2.0 * neck, neck) / 15.0) ** 2,
            "eye": s.eye_weight * (eye_rot / 15.0) ** 2,
            "shoulder": s.shoulder_weight * (x[:, 3] / 30.0) ** 2,
            "elbow": s.elbow_weight * ((x[:, 4] - 90.0) / 40.0) ** 2,
            "knee": s.knee_weight * (x[:, 5] / 15.0) ** 2,
            "visual": s.visual_weight * (np.maximum(seen_at - s.viewing_distance_m, 0.0) / 0.1) ** 2,
            # limits of the eyes and of seeing the holes: steep walls rather than hard constraints
            "limits": 50.0 * ((np.maximum(eye_rot - s.eye_down_max_deg, 0.0) / 5.0) ** 2
                              + (np.maximum(-eye_rot - 30.0, 0.0) / 5.0) ** 2
                              + (np.maximum(view - s.view_max_deg, 0.0) / 5.0) ** 2),
        }
        reach = j[:, R_WRIST, 1:] - wrist_target[1:]
        return {"terms": terms, "reach": reach, "eye_rot": eye_rot, "view": view}

    # -- the posture ---------------------------------------------------------------------
    def posture_at(self, height_m: float, pitch_deg: float) -> WorkPosture:
        """The typical (noise-free) posture at a board height above the floor (m) and pitch (deg)."""
        return _solve(self, round(float(height_m), 4), round(float(pitch_deg), 3))

    def perform(self, height_m: float, pitch_deg: float, rng: np.random.Generator) -> np.ndarray:
        """One repetition of the task: (17, 3) robot-frame joints, the typical posture plus variation."""
        wp = self.posture_at(height_m, pitch_deg)
        s = self.style
        p = wp.posture
        side = lambda pair, sd: tuple(float(a + sd * e) for a, e in zip(pair, rng.standard_normal(2)))  # noqa: E731
        noisy = replace(p, trunk_flexion_deg=p.trunk_flexion_deg + s.trunk_sd_deg * rng.standard_normal(),
                        neck_flexion_deg=p.neck_flexion_deg + s.neck_sd_deg * rng.standard_normal(),
                        shoulder_flexion_deg=side(p.shoulder_flexion_deg, s.shoulder_sd_deg),
                        elbow_flexion_deg=side(p.elbow_flexion_deg, s.elbow_sd_deg))
        d = wp.standing_distance_m + s.distance_sd_m * rng.standard_normal()
        x, z = self.workpiece_xz_m
        return joints_from_angles(self.body, noisy.to_vector()[None], (x, z + d), math.pi)[0]

    def comfort(self, height_m: float, pitch_deg: float) -> float:
        """The worker's own discomfort at a board pose (lower is better)."""
        return self.posture_at(height_m, pitch_deg).cost

    def standing_joints(self) -> np.ndarray:
        """(17, 3) robot-frame joints standing upright, arms hanging, in front of the work-piece."""
        x, z = self.workpiece_xz_m
        return joints_from_angles(self.body, np.zeros((1, N_ANGLES)), (x, z + 0.6), math.pi)[0]

    def elbow_height_m(self) -> float:
        """Right-elbow height above the floor standing upright with the arms hanging (the Elbow Height condition)."""
        return float(self.standing_joints()[R_ELBOW, 1] + BASE_HEIGHT_M)

    def selected_position(self, height_range_m=(0.70, 1.60), pitch_range_deg=(-30.0, 60.0)) -> tuple[float, float]:
        """The Worker-selected position: where this worker, adjusting the arm, is most comfortable.

        Nelder-Mead on the comfort cost over (height, pitch) from the elbow height and 0 deg,
        kept inside the cell's ranges."""
        lo = np.array([height_range_m[0], pitch_range_deg[0]])
        hi = np.array([height_range_m[1], pitch_range_deg[1]])
        scale = np.array([0.1, 10.0])                      # 10 cm ~ 10 deg for the simplex

        def f(u):
            h, a = np.clip(u * scale, lo, hi)
            return self.comfort(h, a)

        x0 = np.array([self.elbow_height_m(), 0.0]) / scale
        res = minimize(f, x0, method="Nelder-Mead", options={"xatol": 0.05, "fatol": 1e-3, "maxfev": 120,
                                                              "initial_simplex": [x0, x0 + [1.5, 0], x0 + [0, 2.0]]})
        h, a = np.clip(res.x * scale, lo, hi)
        return float(h), float(a)


class VisionPath:
    """CAP as the product measures it: the simulated camera's 2D keypoints of a task cycle
    (:func:`firmware_sim.devices.camera.detect`) -> the streaming pose lifter -> robot-frame joints.

    ``lifter`` is an :class:`edge_runtime.robot.lifter.StreamingLifter` (or anything with its
    ``push(t_s, keypoints) -> LiftedPose`` and ``restart()``); it is restarted for every
    cycle, as a worker is a new person to it after the pause between repetitions. A cycle
    is ``frames`` camera frames of the repetition's posture with a few millimetres of sway;
    the result is ``(frames, 17, 3)`` robot-frame joints, NaN where the lifter had no
    valid pose, for :func:`edge_runtime.posture.cap.cycle_cap`."""

    SWAY_M = 0.003
    """Frame-to-frame sway of every joint while working (m, SD)."""

    def __init__(self, lifter, camera, frames: int = 45, noise=None):
        from firmware_sim.devices.camera import DetectorNoise

        self.lifter = lifter
        self.camera = camera
        self.frames = int(frames)
        self.noise = noise if noise is not None else DetectorNoise()

    @classmethod
    def shipped(cls, precision: str = "int8", camera_eye_m=(3.0, 0.6, 1.1), frames: int = 45) -> "VisionPath":
        """The shipped lifter and a camera 3 m to the side of the work cell (Fig. 4.4), looking
        at the worker. Raises ``LookupError`` naming the problem when no lifter is shipped."""
        from edge_runtime.core.manifest import ManifestError, ModelIntegrityError
        from edge_runtime.robot.lifter import LifterParams, StreamingLifter
        from firmware_sim.devices.camera import Camera

        camera = Camera.look_at(camera_eye_m, (0.0, 0.2, 1.1))
        try:
            lifter = StreamingLifter.from_manifest(params=LifterParams(precision=precision),
                                                   camera=camera.intrinsics)
        except (ManifestError, ModelIntegrityError) as e:
            raise LookupError(f"the vision path needs the shipped pose lifter: {e}") from None
        return cls(lifter, camera, frames)

    def observe(self, joints_m: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """(frames, 17, 3) robot-frame joints the product would see of one repetition's posture."""
        from firmware_sim.devices.camera import detect

        seq = joints_m[None] + self.SWAY_M * rng.standard_normal((self.frames, 17, 3))
        keypoints = detect(self.camera, seq, rng, self.noise)
        self.lifter.restart()
        out = np.full(seq.shape, np.nan)
        for k, kp in enumerate(keypoints):
            pose = self.lifter.push(k / self.camera.rate_hz, kp)
            if pose.valid:
                out[k] = self.camera.to_robot(pose.joints_cam_m)
        return out


@functools.lru_cache(maxsize=4096)
def _solve(worker: Worker, height_m: float, pitch_deg: float) -> WorkPosture:
    """SLSQP over the six posture variables (the standing distance in cm, so that every variable
    moves on a similar scale); the reach residual is an equality constraint. Gradients by forward
    differences, all seven points in one batched body-model call. Starts: :func:`_starts`; the
    first that meets the reach constraint wins, else the one closest to it."""
    scale = np.array([0.01, 1.0, 1.0, 1.0, 1.0, 1.0])
    step = 1e-3
    cache: dict[bytes, tuple] = {}

    def evaluate(u):
        key = np.asarray(u, float).tobytes()
        if key not in cache:
            us = np.vstack([u, u + step * np.eye(len(u))])
            t = worker._terms(us * scale, height_m, pitch_deg)
            cost = sum(t["terms"].values())
            r = t["reach"]
            cache.clear()
            cache[key] = (cost[0], (cost[1:] - cost[0]) / step, r[0], ((r[1:] - r[0]) / step).T)
        return cache[key]

    bounds = [(lo / k, hi / k) for (lo, hi), k in zip(_BOUNDS, scale)]
    best = None
    for x0 in _starts(worker, height_m):
        res = minimize(lambda u: evaluate(u)[0], x0 / scale, jac=lambda u: evaluate(u)[1], method="SLSQP",
                       bounds=bounds, constraints=[{"type": "eq", "fun": lambda u: evaluate(u)[2],
                                                    "jac": lambda u: evaluate(u)[3]}],
                       options={"maxiter": 80, "ftol": 1e-6})
        err = float(np.linalg.norm(evaluate(res.x)[2]))
        cand = (err > 0.005, float(evaluate(res.x)[0]), res.x * scale)
        if best is None or cand[:2] < best[:2]:
            best = cand
        if not cand[0]:
            break
    x = best[2]
    t = worker._terms(x, height_m, pitch_deg)
    posture = Posture.from_vector(worker.angles(x)[0])
    return WorkPosture(posture, float(x[0]), float(sum(v[0] for v in t["terms"].values()) + 100.0 * best[0]),
                       float(t["eye_rot"][0]), float(t["view"][0]), float(np.linalg.norm(t["reach"][0])))


def _starts(worker: Worker, height_m: float) -> list[np.ndarray]:
    """Initial guesses: a relaxed stance scaled to the board's height relative to the elbow."""
    rel = (height_m - 0.63 * worker.body.height_m) / worker.body.height_m
    sf = float(np.clip(25.0 + 200.0 * rel, 0.0, 120.0))
    return [np.array([0.35, 5.0, 10.0, sf, 80.0, 0.0]),
            np.array([0.45, 25.0, 20.0, 20.0, 60.0, 0.0]),
            np.array([0.30, 0.0, 0.0, 60.0, 100.0, 20.0])]


def make_cohort(n: int = 20, seed: int = 0) -> list[Worker]:
    """``n`` participants, alternately women and men, heights per :data:`COHORT_HEIGHT_M`, styles at random:
    half eye-movers, half neck-benders; about one in seven shoulder-averse (Fig. 4.10)."""
    if n < 1:
        raise ValueError(f"cohort: need at least 1 participant, got {n}")
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        sex = "F" if i % 2 == 0 else "M"
        mu, sd = COHORT_HEIGHT_M[sex]
        height = float(np.clip(mu + sd * rng.standard_normal(), 1.45, 2.05))
        base = EYE_MOVER if rng.random() < 0.5 else NECK_BENDER
        jitter = lambda w: float(w * np.exp(0.2 * rng.standard_normal()))  # noqa: E731 - personal weights
        style = replace(base, trunk_weight=jitter(base.trunk_weight), neck_weight=jitter(base.neck_weight),
                        viewing_distance_m=float(np.clip(0.45 + 0.04 * rng.standard_normal(), 0.35, 0.55)),
                        eye_weight=jitter(base.eye_weight), shoulder_weight=jitter(base.shoulder_weight),
                        abduction_deg=float(np.clip(8.0 + 4.0 * rng.standard_normal(), 0.0, 20.0)))
        if rng.random() < 0.15:
            style = replace(style, shoulder_weight=3.0 * style.shoulder_weight)
        out.append(Worker(i + 1, Body.from_height(height, sex), style))
    return out


__all__ = ["Style", "EYE_MOVER", "NECK_BENDER", "Worker", "WorkPosture", "VisionPath", "make_cohort"]
