"""The 3-marker camera -> robot calibration of dissertation Eq. 1-2.

Three markers lie on the floor at ``(0, floor, 1)``, ``(1, floor, 1)`` and
``(0, floor, 2)`` in the robot frame. A worker stands on each in turn; the lifter's
head and ankle-midpoint positions (camera frame, metres) at each marker give the
transform. The dissertation writes the floor as ``+H_base`` in a ``y``-down robot
frame, with the head at ``H_base - L_y``; our robot frame (``edge_runtime.core.skeleton``)
is ``y``-up with the floor at ``y = -0.914 m``, so here the floor is
``-base_height_m`` and the head at the markers is at ``floor + L_y``. The
``y`` axis vector of Eq. 2 is therefore ``head - ankle`` (pointing up), not the
dissertation's ``ankle - head``; nothing else changes.

Two fits, both giving ``p_robot = A @ p_cam + b``:

* ``"eq2"`` -- the dissertation's. Eq. 1: ``p_r = (p_c - ankle_m1) T^-1 + m1`` (row
  vectors) with Eq. 2's ``T = diag(1/L_x, 1/L_y, 1/L_z) [x_c; y_c; z_c]``,
  ``x_c = head_m2 - head_m1``, ``y_c = head_m1 - ankle_m1``, ``z_c = head_m3 - head_m1``:
  a scale per axis and a rotation, exact at the three markers. With noisy inputs the
  three axes are not orthogonal, so the map shears space, and it rests on four points
  only (three heads and one ankle).
* ``"rigid"`` -- a least-squares similarity (rotation by SVD, one scale,
  translation; Umeyama 1991) over all six correspondences, every head and every ankle
  at every marker. It cannot shear, uses twice the data, and its residuals measure
  how well the recording fits. tests/robot/test_calibration.py compares the two on simulated
  cameras with keypoint noise; the rigid fit's head error is the lower of the two. Set ``scale = false`` to keep the lifter's metric scale (a pure rigid
  transform).
* ``"pnp"`` (default) -- the camera pose from the directions of the six points only
  (``cv2.solvePnP`` with identity intrinsics on ``(x/z, y/z)``, started from the rigid
  fit): ignores the lifter's depth, which at a real detector's noise turns the rigid fit by
  4-5 degrees (reports/robot/head_error.md). Scale 1, so use it with the ground anchoring.

Ground anchoring (``ground_anchor``, :func:`anchor_factor`, :meth:`Calibration.to_robot`):
the lifter's weak part is the root's depth (from apparent body size). Once the floor is
known, each lifted skeleton is scaled about the camera centre (every 2D projection is
kept) so that its lower ankle rests ``ankle_height_m`` above the floor (both ankles' rays when
both feet are down); that factor can be fused with the lifter's own depth, each weighted by its error,
the fused one taken only where it puts the person nearer the arm (off as shipped:
``ANCHOR_LIFTER_DEPTH_SD``); guarded against flat rays and low
cameras, the factor clamped. In a stream
(:meth:`Calibration.to_robot`, :class:`FloorAnchor`) each person's factor is the median of his
recent plausible ones: one ankle ray's floor crossing is noisy, his distance is not.
reports/robot/head_error.md measures it.

``L_y`` is the height of the head joint above the ankle midpoint: the worker's height
as the skeleton measures it (``worker_height_m``; 0 means: measure it from the
recording as the mean head-ankle distance, in the lifter's metres).

Inputs are averaged robustly (a per-axis median over the frames at each marker), so
keypoint noise and a few bad frames do not move the result. Degenerate inputs are
refused with a ``CalibrationError`` that says what went wrong: markers on a line,
a worker who did not move between markers, too few frames, non-finite values. A worker
who moved along the camera's line of sight (a marker nearly behind another as the camera sees
them), whose move only the rays show, is fitted by ``pnp`` whatever ``method`` says: the
lifter's depth cannot tell those markers apart.
"""
from __future__ import annotations

import itertools
import json
import math
from collections import Counter, deque
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path

import numpy as np

from edge_runtime import config
from edge_runtime.core import strict_json
from edge_runtime.core.numeric import median_floats
from edge_runtime.core.skeleton import BASE_HEIGHT_M, HEAD, HIP, L_ANKLE, R_ANKLE
from edge_runtime.errors import ConfigError, InputError

FORMAT_VERSION = 1
METHODS = ("rigid", "eq2", "pnp")


class CalibrationError(InputError):
    """A calibration that cannot be made or loaded; the message says why."""


@config.section("calibration")
@dataclass(frozen=True)
class CalibrationParams:
    """The marker layout and the fit ([calibration] in the box configuration)."""

    markers_xz_m: tuple[tuple[float, float], ...] = ((0.0, 1.0), (1.0, 1.0), (0.0, 2.0))
    """Ground positions (x, z) of markers 1, 2 and 3 in the robot frame (m). Marker 2 lies
    along +x from marker 1 and marker 3 along +z, as in the dissertation's Fig. 3.1."""
    base_height_m: float = config.setting(BASE_HEIGHT_M, config.POSITIVE)
    """Height of the robot frame's origin (top of the base) above the floor (m)."""
    worker_height_m: float = config.setting(0.0, ("0 (measure) or a number in [1, 2.5]", lambda v: v == 0 or 1 <= v <= 2.5))
    """L_y: head-joint height above the ankle midpoint of the calibrating worker (m);
    0 = measure it from the recording."""
    ankle_height_m: float = config.setting(0.07, config.within(0, 0.2))
    """Height of the ankle joints above the floor (m; 0.039 of body height). The
    dissertation puts the ankle midpoint on the marker (0); this lifts it to the joint."""
    method: str = "pnp"
    """"pnp" (the camera pose from the six points' directions only, cv2.solvePnP; scale 1; the
    default), "rigid" (SVD similarity over six points) or "eq2" (the dissertation's). ``pnp`` fits
    the rays the runtime later ranges people along, so its floor crossings hold near the markers,
    next to the arm: the head error falls by 40 % (fresh seed 25: 0.198 / 0.595 m against ``rigid``'s
    0.328 / 0.931 m, median / p95; reports/robot/head_error.md), and the ray bound of a person not lifted,
    which takes the calibrated camera as exact, stays below the truth (0 of 1,190 bodies above it
    through 30 fitted pnp calibrations, against 34 of 1,177 with ``rigid``, up to 4.6 m above;
    reports/robot/ray_bound_s13.md). ``rigid``'s fit leans on the lifter's depths, which turn it by
    4-5 degrees at a real detector's error. The hrc suites' fresh-seed runs with it:
    reports/hrc/report.md, Session 13."""
    scale: bool = True
    """rigid only: estimate one scale factor (corrects a lifter's depth-scale bias)."""
    min_frames: int = config.setting(10, config.AT_LEAST_1)
    """Frames needed at each marker."""
    min_move_m: float = config.setting(0.3, config.POSITIVE)
    """The head must move at least this far between markers (m), else the worker did not move
    (unless his rays show it, ``min_ray_move_m``)."""
    min_ray_move_m: float = config.setting(0.1, config.POSITIVE)
    """A worker whose lifted head moved less than ``min_move_m`` but whose head or ankle moved at
    least this far across the camera's lines of sight (m) did move, along the line of sight,
    where the lifter's depth does not show it: the camera pose is then fitted from the rays alone
    (pnp). Standing still, the rays' medians move about 0.01 m."""
    still_speed_mps: float = config.setting(0.15, config.POSITIVE)
    """Recording segmentation: the ankle midpoint moving slower than this is standing (m/s)."""
    still_min_s: float = config.setting(1.0, config.POSITIVE)
    """Recording segmentation: a stand at a marker lasts at least this long (s)."""
    ground_anchor: bool = True
    """Re-anchor lifted skeletons on the floor (:func:`anchor_factor`): scale each about the
    camera centre so that its lower ankle is ``ankle_height_m`` above the floor. Fixes most of
    the lifter's depth error (depth from apparent body size); see reports/robot/head_error.md."""
    anchor_min_ray_deg: float = config.setting(3.0, config.within(0, 45))
    """Anchoring guard: the ray from the camera to the lower ankle must point at least this
    far below the horizontal (deg), else the floor crossing is too ill-conditioned and the
    lifter's depth is kept."""
    anchor_min_camera_height_m: float = config.setting(0.5, config.NON_NEGATIVE)
    """Anchoring guard: the camera centre must be at least this high above the ankle plane (m)."""
    anchor_min_scale: float = 0.7
    """Anchoring clamps its scale factor to [anchor_min_scale, anchor_max_scale]."""
    anchor_max_scale: float = 1.4
    """Upper bound of the anchoring's scale factor."""

    def __post_init__(self):
        if self.method not in METHODS:
            raise ValueError(f"method: must be one of {', '.join(METHODS)}, got {self.method!r}")
        if len(self.markers_xz_m) != 3 or any(len(m) != 2 for m in self.markers_xz_m):
            raise ValueError("markers_xz_m: must be three [x, z] pairs")
        if not 0 < self.anchor_min_scale <= 1 <= self.anchor_max_scale:
            raise ValueError("anchor_min_scale, anchor_max_scale: need 0 < min <= 1 <= max")

    @property
    def floor_y_m(self) -> float:
        return -self.base_height_m


def robust_mean(points) -> np.ndarray:
    """Per-axis median of (N, 3) points, ignoring non-finite rows."""
    p = np.asarray(points, dtype=float).reshape(-1, 3)
    p = p[np.isfinite(p).all(axis=1)]
    if len(p) == 0:
        raise CalibrationError("no finite positions")
    return np.median(p, axis=0)


def head_and_ankles(joints_cam_m) -> tuple[np.ndarray, np.ndarray]:
    """Head and ankle midpoint of (..., 17, 3) joints."""
    j = np.asarray(joints_cam_m, dtype=float)
    return j[..., HEAD, :], 0.5 * (j[..., L_ANKLE, :] + j[..., R_ANKLE, :])


# reasons of anchor_factor (None: applied)
ANCHOR_NO_ANKLE = "no_ankle"
ANCHOR_CAMERA_LOW = "camera_low"
ANCHOR_RAY_FLAT = "ray_flat"


def anchor_factor(joints_cam_m, A, b, params: CalibrationParams = CalibrationParams(),
                  observed=None) -> tuple[float, str | None]:
    """The floor re-anchoring of one lifted skeleton: ``(k, reason)``.

    ``joints_cam_m`` (17, 3) are camera-frame joints (m) and ``p_robot = A @ p_cam + b`` the
    calibration, so the camera centre (the camera frame's origin) is at ``b`` in the robot
    frame. Scaling the skeleton by ``k`` about the camera centre leaves every joint on its
    viewing ray (every 2D projection is kept) and moves it in depth; ``k`` is chosen so that
    the lower ankle (lower in the robot frame: the foot on the ground mid-stride) lies
    ``ankle_height_m`` above the floor, then clamped to ``[anchor_min_scale, anchor_max_scale]``.
    The lifter puts each joint on the ray of its keypoint (:mod:`edge_runtime.robot.lifter`), so
    this slides the skeleton along the observed rays: the ankle's ray meets the floor, and the
    head stays on its own ray. ``observed`` (17,) bool, when given, restricts the choice to the
    ankles seen in this frame (a held ankle's ray is an old one); with none seen, both count.
    When both ankles lie within :data:`ANCHOR_LEVEL_FEET_M` of each other in height (both feet on
    the floor), the floor's factor is the geometric mean of the two rays' factors. That factor is then
    fused with the lifter's own depth (factor 1), each weighted by its error (no weight as shipped:
    :data:`ANCHOR_LIFTER_DEPTH_SD` is infinite)
    (:func:`_fused_with_lifter`: a shallow ray of a low, far camera weighs little), and of the two, floor
    alone or fused, ``k`` is the one that puts the person nearer the arm (:func:`_nearer_to_arm`): the
    hazard monitor relies on people not being placed farther from the arm than they are.

    ``k`` is 1 with a reason when the anchoring cannot be trusted: ``no_ankle`` (no finite
    ankle), ``camera_low`` (camera centre less than ``anchor_min_camera_height_m`` above the
    ankle plane) or ``ray_flat`` (the ray to the ankle points less than
    ``anchor_min_ray_deg`` below the horizontal, or up).
    """
    j = np.asarray(joints_cam_m, float).reshape(-1, 3)
    A, b = np.asarray(A, float), np.asarray(b, float)
    return _anchor_factor((j[_ANKLES] @ A.T).tolist(), j, A, b, params, observed)


def _anchor_factor(rays: list, j: np.ndarray, A: np.ndarray, b: np.ndarray, params: CalibrationParams,
                   observed) -> tuple[float, str | None]:
    """:func:`anchor_factor` of skeleton ``j`` (17, 3), given its ankles' rays ``(j[_ANKLES] @ A.T).tolist()``
    (:class:`FloorAnchor` makes everyone's in one product: numpy's matmul of a stack multiplies each
    skeleton as it multiplies one alone, tests/robot/test_perception_batch_s18.py)."""
    # camera centre -> ankle, robot frame; the two rays' arithmetic goes on in Python floats (the same IEEE
    # operations as numpy's on these few numbers, without its per-call cost; tests/robot/test_calibration_fast.py)
    ok = [math.isfinite(x) and math.isfinite(y) and math.isfinite(z) for x, y, z in rays]
    if observed is not None:
        obs = np.asarray(observed, bool)
        seen = [ok[0] and bool(obs[L_ANKLE]), ok[1] and bool(obs[R_ANKLE])]
        ok = seen if seen[0] or seen[1] else ok
    rays = [r for r, keep in zip(rays, ok) if keep]
    if not rays:
        return 1.0, ANCHOR_NO_ANKLE
    # both feet down: two independent rays halve the floor crossing's variance; a raised foot's
    # ray would put the skeleton too far, so only the lower ankle counts then (np.argmin's first lowest,
    # np.ptp's max - min)
    heights = [r[1] for r in rays]
    lower = 1 if len(rays) == 2 and heights[1] < heights[0] else 0
    feet = rays if max(heights) - min(heights) <= ANCHOR_LEVEL_FEET_M else [rays[lower]]
    drop_m = b[1] - (params.floor_y_m + params.ankle_height_m)
    if not drop_m >= params.anchor_min_camera_height_m:
        return 1.0, ANCHOR_CAMERA_LOW
    # np.linalg.norm(feet, axis=1) is sqrt((x*x + y*y) + z*z), summed in that order (the tests pin it)
    steep = _sin_deg(params.anchor_min_ray_deg)
    if any(-y < steep * math.sqrt((x * x + y * y) + z * z) for x, y, z in feet):
        return 1.0, ANCHOR_RAY_FLAT
    logs = np.log(np.array([drop_m / -y for _, y, _ in feet])).tolist()  # numpy's log, as before
    log_floor = logs[0] if len(logs) == 1 else (logs[0] + logs[1]) / 2  # np.mean's sum, then / n
    k = np.exp(log_floor)
    if math.isfinite(ANCHOR_LIFTER_DEPTH_SD):  # the fusion (off as shipped: the floor rays alone, no work per frame)
        feet = np.array(feet)
        k = _nearer_to_arm(j[HIP] @ A.T, b, k, np.exp(_fused_with_lifter(log_floor, feet, drop_m)))
    # np.clip's arithmetic (min(max(k, lo), hi), a NaN k kept) on floats
    k = float(k)
    if k < params.anchor_min_scale:
        k = float(params.anchor_min_scale)
    if k > params.anchor_max_scale:
        k = float(params.anchor_max_scale)
    return k, None


_ANKLES = np.array([L_ANKLE, R_ANKLE])
_SIN_DEG: dict[float, np.float64] = {}


def _sin_deg(deg: float) -> np.float64:
    """``np.sin(np.radians(deg))``, remembered per angle (the anchoring's guard asks for the same one each frame)."""
    v = _SIN_DEG.get(deg)
    if v is None:
        v = _SIN_DEG[deg] = np.sin(np.radians(deg))
    return v


def _fused_with_lifter(log_floor: float, feet: np.ndarray, drop_m: float) -> float:
    """The floor rays' log factor fused with the lifter's own depth (log factor 0), each weighted by
    its error: a foot ray's floor crossing moves by ``cos(ray angle) / drop`` of the keypoint's error
    on the body (:data:`ANCHOR_ANKLE_SD_M`), plus the foot's height above the floor
    (:data:`ANCHOR_FOOT_SD_M`) over the drop, so a shallow ray of a low camera weighs little and the
    lifter's depth (:data:`ANCHOR_LIFTER_DEPTH_SD`) carries more there."""
    cos = np.hypot(feet[:, 0], feet[:, 2]) / np.linalg.norm(feet, axis=1)
    var_floor = float(np.mean((np.hypot(ANCHOR_ANKLE_SD_M * cos, ANCHOR_FOOT_SD_M) / drop_m) ** 2)) / len(feet)
    # written so that an infinite lifter error (no weight: the floor rays alone) is exact
    return log_floor * (1.0 - var_floor / (ANCHOR_LIFTER_DEPTH_SD ** 2 + var_floor))


def _nearer_to_arm(pelvis_ray, b, *factors: float) -> float:
    """Of several anchoring factors, the one that puts the pelvis (``b + k * pelvis_ray``, robot frame)
    nearest the arm's base axis (the robot frame's y axis) on the ground: where two depth estimates
    disagree, the hazard monitor gets the one that places the person nearer the arm, never the farther.
    The first factor when the pelvis is not finite."""
    if not np.isfinite(pelvis_ray).all():
        return factors[0]
    return min(factors, key=lambda k: float(np.hypot(*(b + k * pelvis_ray)[[0, 2]])))


ANCHOR_WINDOW_FRAMES = 15
"""Each person's anchoring factor is the median of his last this many plausible per-frame factors
(:class:`FloorAnchor`; 0.5 s at 30 Hz, the hazard monitor's head-fit span; 1 = each frame alone).
A module constant, not a [calibration] key: [calibration] is in the validated safety hash
(firmware_sim.scenarios.hrc), and making it configurable belongs with that re-validation."""
ANCHOR_LEVEL_FEET_M = 0.1
"""Both observed ankles within this height of each other (robot frame, the lifter's metres): both
feet are on the floor and both rays count in :func:`anchor_factor` (geometric mean of the two)."""
ANCHOR_ANKLE_SD_M = 0.10
"""A real 2D detector's ankle keypoint error on the body (m, 1 sd): COCO's ankle sigma (0.089) at a
standing person's scale (about 1.1 m, the square root of his box's area). Weighs the floor rays
against the lifter's depth (:func:`anchor_factor`); not tuned on the simulator."""
ANCHOR_FOOT_SD_M = 0.03
"""How far the lower ankle joint is from ``ankle_height_m`` above the floor (m, 1 sd): ankle heights
differ between people and a foot rolls and lifts mid-stride."""
ANCHOR_LIFTER_DEPTH_SD = np.inf
"""The lifter's own depth's relative error (1 sd, natural log) as :func:`anchor_factor` weighs it against the
floor rays. Shipped: infinite, i.e. no weight, the floor rays alone (what the hrc suites validated): the
fusion with :data:`ANCHOR_LIFTER_DEPTH_SD_FUSED` was measured with ``pnp`` and that candidate failed its
closed-loop validation in session 10 (reports/hrc/report.md). A module constant, not a [calibration] key,
as :data:`ANCHOR_WINDOW_FRAMES`: changing it needs the hrc suites re-run on a fresh seed."""
ANCHOR_LIFTER_DEPTH_SD_FUSED = 0.12
"""The lifter's own depth (from apparent body size): its relative error (1 sd, natural log) in the fusion
session 10 measured (reports/robot/head_error.md; not shipped, see :data:`ANCHOR_LIFTER_DEPTH_SD`). The simulator's lifter is within 0.07 (dev seed 4,
perfect calibration, real-detector noise); real people's heights (1.45-2.0 m) and motions vary more,
so a larger error is assumed (0.08-0.2 measured on development seeds 4, 13, 17;
reports/robot/head_error.md, Session 10)."""
ANCHOR_GATE_M = 0.5
""":class:`FloorAnchor` matches a skeleton to the person whose last anchored pelvis is nearest when
this skeleton is anchored with that person's factor, within this distance (m); farther, he is a
new person (anchored frame by frame until his window fills). Walking, a person moves 5 cm per
frame; the gate bounds what taking another person's factor for a frame can cost."""


@dataclass
class _AnchorTrack:
    factors: deque
    k: float
    root_m: np.ndarray
    pid: object = None
    last_in: np.ndarray | None = None
    last_out: np.ndarray | None = None
    missed: int = 0


class FloorAnchor:
    """The floor anchoring of a stream of frames, each person's factor filtered over time.

    A person's distance from the camera does not jump between frames; the floor crossing of one
    noisy ankle ray does (at a real detector's ankle noise, about 8 cm on the body, some 20 cm at
    5 m; reports/robot/head_error.md). So each person's anchoring factor is the median of his last
    ``calibration.anchor_window_frames`` plausible per-frame factors (:func:`anchor_factor`):
    factors a guard refused or the clamp limited are left out, and a wild ankle frame does not
    move the median. The factor is relative to the lifter's depth, which follows the person's
    motion. Causal: each frame uses this frame and earlier ones only.

    The robot loop gives no ids (``ids``, when a caller has a tracker's, keys the people by them):
    a skeleton belongs to the person whose last anchored pelvis is nearest to it anchored with his
    factor (the pelvis's ray, not the ankles', so a wild ankle does not make a new person), within
    :data:`ANCHOR_GATE_M`; one unseen for a window is forgotten. A skeleton given again unchanged (a second look at the same frame) gets
    the same answer and does not count twice.
    """

    def __init__(self, calibration: "Calibration"):
        self.calibration = calibration
        self.tracks: list[_AnchorTrack] = []

    def __call__(self, joints_cam_m, observed=None, ids=None) -> np.ndarray:
        """Robot-frame joints (P, 17, 3) of one frame's camera-frame skeletons (P, 17, 3);
        ``ids`` (P,), when given, name the people (a tracker's ids) instead of the nearest-pelvis
        match."""
        cal, p = self.calibration, self.calibration.params
        window = max(1, int(cal.anchor_window_frames))
        flat = np.asarray(joints_cam_m, float).reshape(-1, 17, 3)
        seen = [None] * len(flat) if observed is None else np.asarray(observed, bool).reshape(-1, 17)
        out, todo, matched = self._match(flat, ids, window)
        if not todo:
            return out
        # everyone's ankle rays, and below everyone's anchored joints, in one matrix product each (a stack's
        # product is each skeleton's own, to the bit: tests/robot/test_perception_batch_s18.py)
        A, b = np.asarray(cal.A, float), np.asarray(cal.b, float)
        # everyone's skeleton, a copy (one no caller holds: the tracks keep views of it); a copy of them all when
        # everyone is new in this frame (the usual frame), as the gather of every row makes it
        mine = flat.copy() if len(todo) == len(flat) else flat[todo]
        ankle_rays = (mine[:, _ANKLES] @ A.T).tolist()
        anchored = []
        for i, rays in zip(todo, ankle_rays):
            k, reason = _anchor_factor(rays, flat[i], A, b, p, seen[i])
            t = matched.get(i)
            if t is None:
                t = _AnchorTrack(deque(maxlen=window), k, np.full(3, np.nan), None if ids is None else ids[i])
                self.tracks.append(t)
            if reason is None and p.anchor_min_scale < k < p.anchor_max_scale:
                t.factors.append(k)
            t.k = median_floats(t.factors) if t.factors else k
            anchored.append(t)
        # cal.apply(k * joints) of each
        robot = (np.array([t.k for t in anchored])[:, None, None] * mine) @ cal.A.T + cal.b
        # each root's np.isfinite(...).all() on its three floats (numpy's test per element, without its calls)
        roots_finite = [all(map(math.isfinite, root)) for root in robot[:, HIP].tolist()]
        for i, t, joints, mine_i, root_finite in zip(todo, anchored, robot, mine, roots_finite):
            out[i] = joints
            if root_finite:
                t.root_m = joints[HIP]
            t.last_in, t.last_out = mine_i, joints  # views of this call's own arrays (no caller holds them)
        return out

    def _match(self, flat: np.ndarray, ids, window: int) -> tuple[np.ndarray, list[int], dict[int, _AnchorTrack]]:
        """The people's tracks for skeletons ``flat`` (P, 17, 3): (the output with the skeletons given again
        filled, the indices of the others, index -> its matched track); the tracks unseen for longer than
        ``window`` frames are forgotten."""
        cal = self.calibration
        out = np.empty_like(flat)
        todo, taken = [], set()
        for i, again in enumerate(self._given_before(flat)):
            if again is None:
                todo.append(i)
            else:
                out[i] = self.tracks[again].last_out
                taken.add(again)
        if ids is None:
            pairs = sorted((float(np.linalg.norm(cal.apply(t.k * flat[i][HIP]) - t.root_m)), i, n)
                           for i in todo for n, t in enumerate(self.tracks) if n not in taken)
        else:
            pairs = [(0.0, i, n) for i in todo for n, t in enumerate(self.tracks) if t.pid == ids[i]]
        matched = {}
        for d, i, n in pairs:
            if d <= ANCHOR_GATE_M and i not in matched and n not in taken:
                matched[i] = self.tracks[n]
                taken.add(n)
        for n, t in enumerate(self.tracks):
            t.missed = 0 if n in taken else t.missed + 1
        self.tracks = [t for t in self.tracks if t.missed <= window]
        return out, todo, matched

    def _given_before(self, flat: np.ndarray) -> list[int | None]:
        """For each skeleton of ``flat`` (P, 17, 3), the first track (index) whose last skeleton it equals,
        ``np.array_equal``'s way (every number ``==``, so one with a NaN never equals, and -0.0 equals 0.0),
        or None. A new frame's skeleton differs from the last ones in its first number already: that one
        Python comparison settles the usual pair, the whole arrays are compared only when it is equal."""
        known = [(n, t.last_in, t.last_in.item(0)) for n, t in enumerate(self.tracks) if t.last_in is not None]
        firsts = flat[:, 0, 0].tolist()
        return [next((n for n, last, x0 in known if x0 == f0 and (last == j).all()), None)
                for j, f0 in zip(flat, firsts)]


@dataclass
class Calibration:
    """A camera -> robot transform ``p_robot = A @ p_cam + b`` and how it was made."""

    A: np.ndarray
    b: np.ndarray
    method: str
    worker_height_m: float
    head_cam_m: np.ndarray
    """(3, 3) head positions at markers 1-3 (camera frame), the fit's inputs."""
    ankle_cam_m: np.ndarray
    """(3, 3) ankle midpoints at markers 1-3 (camera frame)."""
    params: CalibrationParams = field(default_factory=CalibrationParams)
    frames: tuple[int, ...] = ()
    anchor_window_frames: int = field(default=ANCHOR_WINDOW_FRAMES, compare=False)
    """:class:`FloorAnchor`'s window (frames) for this calibration's :meth:`to_robot`; not saved."""
    _anchor: FloorAnchor | None = field(default=None, init=False, repr=False, compare=False)

    def apply(self, points_cam_m) -> np.ndarray:
        """Robot-frame positions of camera-frame points (..., 3)."""
        p = np.asarray(points_cam_m, dtype=float)
        return p @ self.A.T + self.b

    @property
    def camera_centre_m(self) -> np.ndarray:
        """The camera centre (the camera frame's origin) in the robot frame (m)."""
        return self.b.copy()

    def anchor_to_floor(self, joints_cam_m, observed=None) -> tuple[np.ndarray, bool]:
        """Robot-frame joints (17, 3) of one camera-frame skeleton re-anchored on the floor
        (:func:`anchor_factor`: scaled about the camera centre so its lower ankle is
        ``ankle_height_m`` above the floor), and whether the anchoring applied (False: a
        guard refused and the lifter's depth was kept, or ``params.ground_anchor`` is off).
        Non-finite joints stay non-finite."""
        j = np.asarray(joints_cam_m, float)
        if not self.params.ground_anchor:
            return self.apply(j), False
        k, reason = anchor_factor(j, self.A, self.b, self.params, observed)
        return self.apply(k * j), reason is None

    def to_robot(self, joints_cam_m, observed=None, ids=None) -> np.ndarray:
        """Robot-frame joints of one frame's camera-frame skeletons (17, 3) or (P, 17, 3): each
        re-anchored on the floor when ``params.ground_anchor`` is on, else :meth:`apply`.
        Stateful: call it once per frame, frames in order; each person's anchoring factor is
        filtered over his recent frames (:class:`FloorAnchor`, ``anchor_window_frames``).
        ``observed`` ((17,) or (P, 17) bool, optional): the joints seen in this frame, so the
        anchoring uses an observed ankle's ray (:func:`anchor_factor`). ``ids`` ((P,), optional):
        each person's tracker id, to keep his factor by id (without: by the nearest pelvis;
        :class:`FloorAnchor`)."""
        j = np.asarray(joints_cam_m, float)
        if not self.params.ground_anchor or j.shape[-2:] != (17, 3):
            return self.apply(j)
        if self._anchor is None:
            self._anchor = FloorAnchor(self)
        return self._anchor(j, observed, None if ids is None else list(np.atleast_1d(ids))).reshape(j.shape)

    @property
    def scale(self) -> float:
        """Mean scale factor of A (1 for a pure rotation)."""
        return float(np.cbrt(abs(np.linalg.det(self.A))))

    def residuals_m(self) -> dict[str, list[float]]:
        """Distance (m) between each transformed input and its marker target; for ``pnp``, which
        fits the rays and not the lifter's depths, the distance of each target from its ray."""
        heads, ankles = targets(self.params, self.worker_height_m)
        return {"head": self._residual(self.head_cam_m, heads), "ankle": self._residual(self.ankle_cam_m, ankles)}

    def _residual(self, cam_m: np.ndarray, target_m: np.ndarray) -> list[float]:
        if self.method != "pnp":
            return np.linalg.norm(self.apply(cam_m) - target_m, axis=1).round(4).tolist()
        ray = cam_m @ self.A.T
        ray /= np.linalg.norm(ray, axis=1, keepdims=True)
        off = target_m - self.b
        across = off - np.sum(off * ray, axis=1, keepdims=True) * ray
        return np.linalg.norm(across, axis=1).round(4).tolist()

    def to_json(self) -> dict:
        return {
            "version": FORMAT_VERSION,
            "method": self.method,
            "A": self.A.tolist(),
            "b": self.b.tolist(),
            "scale": self.scale,
            "worker_height_m": self.worker_height_m,
            "inputs": {"head_cam_m": self.head_cam_m.tolist(), "ankle_cam_m": self.ankle_cam_m.tolist(),
                       "frames_per_marker": list(self.frames)},
            "residuals_m": self.residuals_m(),
            "params": {k: (list(map(list, v)) if k == "markers_xz_m" else v) for k, v in asdict(self.params).items()},
        }

    def save(self, path: str | Path) -> None:
        Path(path).write_text(json.dumps(self.to_json(), indent=2) + "\n")

    @classmethod
    def load(cls, path: str | Path) -> "Calibration":
        """A calibration file; any problem is one CalibrationError naming the file and the field."""
        p = Path(path)
        try:
            raw = p.read_bytes()
        except OSError as e:
            raise CalibrationError(f"{p}: cannot read ({e.strerror or e})") from None
        return cls.from_json(strict_json.loads(raw, str(p), CalibrationError), str(p))

    @classmethod
    def from_json(cls, data, where: str = "calibration") -> "Calibration":
        """Every field checked for its type and range (errors name ``where`` and the field):
        the file's one validation step, so that nothing malformed reaches the robot loop."""
        def fail(msg: str):
            raise CalibrationError(f"{where}: {msg}")

        if not isinstance(data, dict):
            fail("expected a JSON object")
        if data.get("version") != FORMAT_VERSION or isinstance(data.get("version"), bool):
            fail(f"field 'version': {data.get('version')!r}, expected {FORMAT_VERSION}"[:200])
        for key in ("A", "b", "method", "worker_height_m", "inputs"):
            if key not in data:
                fail(f"field {key!r}: missing")
        A = strict_json.number_array(data["A"], (3, 3), f"{where}: field 'A'", CalibrationError)
        b = strict_json.number_array(data["b"], (3,), f"{where}: field 'b'", CalibrationError, -100.0, 100.0)
        if not 1e-3 <= abs(np.linalg.det(A)) <= 1e3:
            fail("field 'A': singular or of an impossible scale (|det A| must lie in [1e-3, 1e3])")
        if data["method"] not in METHODS:
            fail(f"field 'method': expected one of {', '.join(METHODS)}, got {data['method']!r}"[:200])
        height = strict_json.number(data["worker_height_m"], f"{where}: field 'worker_height_m'", CalibrationError,
                                    0.5, 3.0)
        inputs = data["inputs"]
        if not isinstance(inputs, dict):
            fail("field 'inputs': expected an object")
        head, ankle = (strict_json.number_array(inputs.get(k), (3, 3), f"{where}: field 'inputs.{k}'",
                                                CalibrationError, -100.0, 100.0) for k in ("head_cam_m", "ankle_cam_m"))
        frames = inputs.get("frames_per_marker", [])
        if not isinstance(frames, list) or len(frames) > 3:
            fail("field 'inputs.frames_per_marker': expected a list of up to 3 integers")
        frames = tuple(strict_json.integer(n, f"{where}: field 'inputs.frames_per_marker'", CalibrationError,
                                           0, 10**9) for n in frames)
        params = data.get("params", {})
        if not isinstance(params, dict):
            fail("field 'params': expected an object")
        try:  # the box configuration's own schema and limits ([calibration]), so both agree
            params = config.from_dict({"calibration": params}, f"{where}: field 'params'").calibration
        except ConfigError as e:
            raise CalibrationError(str(e)) from None
        return cls(A, b, data["method"], height, head, ankle, params, frames)


def marker_points(params: CalibrationParams) -> np.ndarray:
    """(3, 3) robot-frame floor positions of the markers."""
    return np.array([[x, params.floor_y_m, z] for x, z in params.markers_xz_m], float)


def targets(params: CalibrationParams, worker_height_m: float) -> tuple[np.ndarray, np.ndarray]:
    """Robot-frame head and ankle positions (3, 3) of a worker standing on each marker."""
    ankles = marker_points(params) + [0.0, params.ankle_height_m, 0.0]
    return ankles + [0.0, worker_height_m, 0.0], ankles


def _check_markers(params: CalibrationParams) -> None:
    m = np.asarray(params.markers_xz_m, float)
    u, v = m[1] - m[0], m[2] - m[0]
    area = abs(u[0] * v[1] - u[1] * v[0])
    if area < 1e-3:
        raise CalibrationError(f"markers {params.markers_xz_m} are collinear: they must span the floor")


def fit(head_cam_m, ankle_cam_m, params: CalibrationParams = CalibrationParams(),
        frames: tuple[int, ...] = ()) -> Calibration:
    """The transform from the (3, 3) head and ankle-midpoint positions at markers 1-3."""
    _check_markers(params)
    heads = np.asarray(head_cam_m, float).reshape(3, 3)
    ankles = np.asarray(ankle_cam_m, float).reshape(3, 3)
    if not (np.isfinite(heads).all() and np.isfinite(ankles).all()):
        raise CalibrationError("non-finite head or ankle positions")
    method = params.method
    for k in (1, 2):
        moved = float(np.linalg.norm(heads[k] - heads[0]))
        if moved >= params.min_move_m:
            continue
        across = max(_across_rays_m(heads[0], heads[k]), _across_rays_m(ankles[0], ankles[k]))
        if across < params.min_ray_move_m:
            raise CalibrationError(f"the worker did not move from marker 1 to marker {k + 1} "
                                   f"(head moved {moved:.2f} m, need {params.min_move_m} m; across the camera's "
                                   f"rays {across:.2f} m, need {params.min_ray_move_m} m)")
        # he moved (the rays say so) but the lifted depth did not show it: marker k + 1 lies
        # nearly on marker 1's line of sight, where depth from apparent body size cannot tell the
        # two apart; a fit on the lifted positions would take the rays' word for it nowhere. The
        # camera pose from the six rays alone (pnp) does not use that depth (hard:200 seed 1,
        # hard_156: markers 1 and 3 1.7 deg apart as seen from a camera 7 m away, head moved 0.27 m)
        method = "pnp"
    x_c, z_c = heads[1] - heads[0], heads[2] - heads[0]
    if method != "pnp" and np.linalg.norm(np.cross(x_c, z_c)) < 0.1 * np.linalg.norm(x_c) * np.linalg.norm(z_c):
        raise CalibrationError("the head positions at the three markers are (nearly) collinear")
    if method != params.method:
        params = replace(params, method=method)
    height = params.worker_height_m or _measured_height(heads, ankles, params)
    if height < 0.5:
        raise CalibrationError(f"head only {height:.2f} m above the ankles: not a standing worker")
    head_r, ankle_r = targets(params, height)
    if params.method == "eq2":
        A, b = _fit_eq2(heads, ankles, head_r, ankle_r)
    elif params.method == "pnp":
        if not params.worker_height_m:  # the rays say how tall he is better than the lifter's depth
            height = _pnp_height(heads, ankles, params, height)
            head_r, ankle_r = targets(params, height)
        A, b = _fit_pnp(np.vstack([heads, ankles]), np.vstack([head_r, ankle_r]))
    else:
        A, b = _fit_similarity(np.vstack([heads, ankles]), np.vstack([head_r, ankle_r]), params.scale)
    cal = Calibration(A, b, params.method, height, heads, ankles, params, tuple(frames))
    if cal.method == "pnp":  # rigid refuses collinear heads above; pnp fits rays, so it judges its residuals
        residual_m = max(max(v) for v in cal.residuals_m().values())
        if not residual_m <= MAX_PNP_RESIDUAL_M:  # NaN fails too
            raise CalibrationError(f"the pnp fit misses a marker's ray by {residual_m:.2f} m (at most "
                                   f"{MAX_PNP_RESIDUAL_M} m): mislabelled or collinear stands")
    return cal



def _across_rays_m(a_cam_m, b_cam_m) -> float:
    """How far (m) a point moved across the camera's lines of sight from ``a_cam_m`` to
    ``b_cam_m`` (camera frame): the change of its ray (x/z, y/z) times its depth at ``a``. The
    rays are the keypoints themselves; only the depth rests on the lifter."""
    a, b = np.asarray(a_cam_m, float), np.asarray(b_cam_m, float)
    return float(np.linalg.norm(b[:2] / b[2] - a[:2] / a[2]) * a[2])


def _measured_height(heads, ankles, params: CalibrationParams) -> float:
    """L_y from the recording: the mean head-ankle distance, in metres of the robot frame.
    For the scaled rigid fit the lifter's metres are first corrected by the ratio of the
    known marker spacing to the spacing the lifter saw (else a lifter that sees everything
    15 % too large would also make the worker 15 % too tall and bias the fit)."""
    length = float(np.mean(np.linalg.norm(heads - ankles, axis=1)))
    if params.method == "eq2" or (params.method == "rigid" and not params.scale):
        return length
    mid = 0.5 * (heads + ankles)
    pairs = ((0, 1), (0, 2), (1, 2))
    m = marker_points(params)
    seen = sum(np.linalg.norm(mid[i] - mid[j]) for i, j in pairs)
    known = sum(np.linalg.norm(m[i] - m[j]) for i, j in pairs)
    return length * known / seen


def _fit_eq2(heads, ankles, head_r, ankle_r) -> tuple[np.ndarray, np.ndarray]:
    """Eq. 1-2 as a column-vector affine map: the camera vectors x_c, y_c, z_c map onto the
    robot-frame vectors between the same marker targets (which, for the default
    layout, are L_x e_x, L_y e_y, L_z e_z: Eq. 2's scaling times rotation)."""
    cam = np.stack([heads[1] - heads[0], heads[0] - ankles[0], heads[2] - heads[0]])  # rows x_c, y_c, z_c
    rob = np.stack([head_r[1] - head_r[0], head_r[0] - ankle_r[0], head_r[2] - head_r[0]])
    # rows: rob_i = A cam_i  ->  rob = cam A^T
    A = np.linalg.solve(cam, rob).T
    return A, ankle_r[0] - A @ ankles[0]


PNP_HEIGHTS_M = np.arange(1.1, 2.11, 0.01)
"""Worker heights (head joint above the ankle midpoint, m) the pnp fit tries when measuring."""


def _pnp_height(heads, ankles, params: CalibrationParams, guess_m: float) -> float:
    """L_y for the pnp fit from the six rays alone: the height whose marker targets the rays fit
    best (the least squared reprojection error in normalised image coordinates). The ankles lie
    at known floor points, so the heads' rays above them fix how tall the worker is; the lifter's
    depth, which the similarity-corrected measure relies on, is not used."""
    import cv2

    src = np.vstack([heads, ankles])
    uv = src[:, :2] / src[:, 2:3]
    best = (np.inf, guess_m)
    for h in PNP_HEIGHTS_M:
        head_r, ankle_r = targets(params, float(h))
        dst = np.vstack([head_r, ankle_r])
        try:
            A, b = _fit_pnp(src, dst)
        except CalibrationError:
            continue
        R = A.T
        proj, _ = cv2.projectPoints(dst.reshape(-1, 1, 3), cv2.Rodrigues(R)[0], -R @ b, np.eye(3), None)
        err = float(((proj.reshape(-1, 2) - uv) ** 2).sum())
        if err < best[0]:
            best = (err, float(h))
    return best[1]


def _fit_pnp(src, dst) -> tuple[np.ndarray, np.ndarray]:
    """The camera pose from the directions of the camera-frame points only (their depths,
    the lifter's weak part, are not used): ``cv2.solvePnP`` of the robot-frame targets
    against the normalised image coordinates ``(x/z, y/z)`` (identity intrinsics), started
    from the similarity fit. Returns the rigid camera -> robot map (scale 1)."""
    import cv2

    A0, b0 = _fit_similarity(src, dst, True)
    R0 = (A0 / np.cbrt(np.linalg.det(A0))).T                 # robot -> camera rotation
    t0 = -R0 @ b0
    uv = src[:, :2] / src[:, 2:3]
    if not (src[:, 2] > 0.1).all():
        raise CalibrationError("a calibration point is not in front of the camera")
    ok, rvec, tvec = cv2.solvePnP(dst.reshape(-1, 1, 3), uv.reshape(-1, 1, 2), np.eye(3), None,
                                  cv2.Rodrigues(R0)[0], t0.reshape(3, 1), useExtrinsicGuess=True,
                                  flags=cv2.SOLVEPNP_ITERATIVE)
    if not ok:
        raise CalibrationError("solvePnP found no camera pose for the marker points")
    R = cv2.Rodrigues(rvec)[0]
    return R.T, -R.T @ tvec.ravel()


def _fit_similarity(src, dst, with_scale: bool) -> tuple[np.ndarray, np.ndarray]:
    """Least-squares rotation (SVD), optional uniform scale and translation: dst ~ s R src + t."""
    mu_s, mu_d = src.mean(axis=0), dst.mean(axis=0)
    S, D = src - mu_s, dst - mu_d
    U, sig, Vt = np.linalg.svd(D.T @ S)
    E = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])  # a rotation, not a reflection
    R = U @ E @ Vt
    s = float(np.trace(np.diag(sig) @ E) / (S * S).sum()) if with_scale else 1.0
    A = s * R
    return A, mu_d - A @ mu_s


STAND_GAP_S = 1.0
"""Standing pieces at most this far apart in time whose rays agree are one stand (:func:`segment_stands`):
a glitch of a quarter second leaves a hole about this long in the half-second medians. The walk between
two markers 1 m apart moves the rays far more, so different markers are never joined."""
MAX_PNP_RESIDUAL_M = 0.3
"""A pnp fit, labelled or not, passes only when every marker target is within this of its ray
(:meth:`Calibration.residuals_m`). Right fits at a real detector's noise: 0.016-0.066 m (development
seed 4 of ``firmware_sim head-error``, labelled, 10 placements). Session 12's review: pnp accepted
collinear head positions (camera 52 deg off, residual 0.41 m) and the heads of two markers swapped
(56.7 deg off, 1.04 m) that ``rigid`` refuses or would. Without labels the stricter
:data:`MAX_UNLABELLED_RESIDUAL_M` applies as well."""
MAX_UNLABELLED_RESIDUAL_M = {"pnp": 0.12, "rigid": 0.6}
"""A fit of three stands found without labels (:func:`_fit_stands`) passes only when its largest residual
at the markers (:meth:`Calibration.residuals_m`: pnp the target's distance from its ray, rigid the 3-D
distance) is at most this, per method. Development seed 4 of ``firmware_sim head-error``'s calibration
walks at a real detector's noise: right fits 0.016-0.066 m (pnp, labelled, 10 placements), 0.10-0.37 m
(rigid); fits to the wrong stands 0.13-0.197 m (pnp; a 0.15 m limit let one through, turned by 130
degrees), 0.88-1.04 m (rigid). It catches those; it does not catch every wrong layout (:func:`_fit_stands`).
A module constant, not a [calibration] key, like the anchoring's: [calibration] is in the validated safety
hash, and the labelled path the hrc suites calibrate by does not use it."""
MAX_UNLABELLED_DISAGREEMENT_DEG = 10.0
"""Two trios of stands that both pass but put the camera more than this far apart (degrees) make the
recording ambiguous: refused. Right fits differ from the true pose by 2-4 degrees (pnp), 5-10 (rigid)."""
MAX_UNLABELLED_STANDS = 8
"""More standing periods than this are refused rather than searched (every three of them are fitted: 56
trios at 8, a few seconds with pnp; a long recording with many pauses would take hours)."""


def segment_stands(t_s, ankle_cam_m, params: CalibrationParams = CalibrationParams()) -> list[np.ndarray]:
    """Index arrays of the standing periods of a calibration recording, in time order.

    A frame is standing when the medians of the ankle midpoint over the half second
    before it and the half second after it are less than ``still_speed_mps * 0.5 s``
    apart (medians, so keypoint noise and outliers do not break a stand); standing runs
    shorter than ``still_min_s`` are dropped. The distance is measured across the viewing
    ray (the ankle's direction, (x/z, y/z), times its median depth): the lifter's depth
    jitters by decimetres from frame to frame at a real detector's noise, its rays do not
    (they are the keypoints), and a worker walking between markers moves across the image.
    Pieces of standing at most :data:`STAND_GAP_S` apart whose rays agree (within the same
    distance) are joined first, leaving out a short piece between them that does not agree: a real
    detector's noise breaks a stand now and then.
    """
    t = np.asarray(t_s, float)
    a = np.asarray(ankle_cam_m, float)
    with np.errstate(invalid="ignore", divide="ignore"):
        ray = a[:, :2] / a[:, 2:3]
    half = 0.5
    still = np.zeros(len(t), bool)
    ok = np.isfinite(ray).all(axis=1) & (a[:, 2] > 0)
    for i, ti in enumerate(t):
        before = ok & (t > ti - half) & (t <= ti)
        after = ok & (t >= ti) & (t < ti + half)
        if before.sum() >= 3 and after.sum() >= 3:
            depth_m = float(np.median(a[before | after, 2]))
            moved = np.linalg.norm(np.median(ray[after], axis=0) - np.median(ray[before], axis=0)) * depth_m
            still[i] = moved < params.still_speed_mps * half
    runs, start = [], None
    for i, s in enumerate(np.append(still, False)):
        if s and start is None:
            start = i
        elif not s and start is not None:
            runs.append(np.arange(start, i))
            start = None
    # a real detector's noise breaks one stand into pieces now and then (frames whose medians moved
    # past the threshold, a glitch the medians straddle): pieces close in time whose rays agree are one
    # stand; a short piece between them that does not agree (the glitch itself) is left out
    merged: list[np.ndarray] = []
    for run in runs:
        if merged and t[run[0]] - t[merged[-1][-1]] <= STAND_GAP_S:
            both = np.r_[merged[-1], run]
            depth_m = float(np.median(a[both[ok[both]], 2]))
            apart = np.linalg.norm(np.median(ray[run[ok[run]]], axis=0) - np.median(ray[merged[-1][ok[merged[-1]]]], axis=0))
            if apart * depth_m < params.still_speed_mps * half:
                merged[-1] = both
                continue
            if t[run[-1]] - t[run[0]] < params.still_min_s:
                continue
        merged.append(run)
    return [r for r in merged if t[r[-1]] - t[r[0]] >= params.still_min_s]


def from_recording(t_s, joints_cam_m, params: CalibrationParams = CalibrationParams(),
                   marker=None) -> Calibration:
    """Calibrate from a recording of the worker standing on markers 1, 2, 3 in turn.

    ``joints_cam_m`` is (N, 17, 3). ``marker`` (N,) may label each frame 1, 2, 3 (0 or
    negative: walking); without it the standing periods are found (:func:`segment_stands`) and
    chosen as :func:`_fit_stands` says.
    """
    heads, ankles = head_and_ankles(joints_cam_m)
    if marker is not None:
        marker = np.asarray(marker)
        return _fit_groups(heads, ankles, [np.flatnonzero(marker == k) for k in (1, 2, 3)], params)
    stands = segment_stands(t_s, ankles, params)
    if len(stands) < 3:
        raise CalibrationError(f"found {len(stands)} standing period(s) of at least {params.still_min_s} s; "
                               "need 3 (markers 1, 2, 3) -- did the worker move between markers?")
    if len(stands) > MAX_UNLABELLED_STANDS:
        raise CalibrationError(f"found {len(stands)} standing periods, at most {MAX_UNLABELLED_STANDS} can be told "
                               "apart: record the marker walk alone, or label the frames by marker")
    return _fit_stands(heads, ankles, stands, params)


def _fit_groups(heads, ankles, groups, params: CalibrationParams) -> Calibration:
    """The fit of the frames ``groups`` (index arrays of markers 1, 2, 3): each marker's robust
    head and ankle positions."""
    for k, g in enumerate(groups, 1):
        n_ok = int(np.isfinite(heads[g]).all(axis=1).sum()) if len(g) else 0
        if n_ok < params.min_frames:
            raise CalibrationError(f"marker {k}: {n_ok} usable frames, need {params.min_frames}")
    return fit(np.stack([robust_mean(heads[g]) for g in groups]), np.stack([robust_mean(ankles[g]) for g in groups]),
               params, frames=tuple(len(g) for g in groups))


def _fit_stands(heads, ankles, stands: list[np.ndarray], params: CalibrationParams) -> Calibration:
    """The calibration from standing periods found without labels.

    Without labels nothing says which stands are the markers: a stand the detector's noise broke in
    two, or a pause on the way, makes a fourth one, and taking the first three then fits a layout the
    worker never walked (development seed 4 of ``firmware_sim head-error``: fits turned by 22 and 88
    degrees with nothing to show it). So every three stands in time order are fitted, each fit's
    largest residual at the markers is judged against its method's limit
    (:data:`MAX_UNLABELLED_RESIDUAL_M`; a rigid trio can fall back to pnp, whose residuals are
    distances from rays, not 3-D), and the calibration is refused when no trio passes, or when two
    that pass put the camera more than :data:`MAX_UNLABELLED_DISAGREEMENT_DEG` apart (the stands do
    not say which are the markers). What this cannot see: with exactly three stands of which one is not
    a marker, a fit with a free scale (rigid) or height (pnp) can still pass (tests/robot/
    test_calibration.py); labelled frames are the safe way. eq2 leaves no residual at the markers to
    judge by, so without labels it takes the first three stands, as before.
    """
    if params.method == "eq2":
        return _fit_groups(heads, ankles, stands[:3], params)
    passed, errors = [], Counter()
    for trio in itertools.combinations(range(len(stands)), 3):
        try:
            cal = _fit_groups(heads, ankles, [stands[i] for i in trio], params)
        except CalibrationError as e:
            errors[str(e).split(" (")[0]] += 1
            continue
        residual_m = max(max(v) for v in cal.residuals_m().values())
        limit_m = MAX_UNLABELLED_RESIDUAL_M[cal.method]
        if not residual_m <= limit_m:  # NaN fails too
            errors[f"{cal.method} residual above {limit_m} m"] += 1
            continue
        passed.append((residual_m / limit_m, cal))
    if not passed:
        why = "; ".join(f"{n} x {e}" for e, n in errors.most_common(3))
        raise CalibrationError(f"no three of the {len(stands)} standing periods fit the marker layout ({why}): record "
                               "the walk again, standing still on each marker, or label the frames by marker")
    best = min(passed, key=lambda x: x[0])[1]
    apart_deg = max(rotation_between_deg(other.A, best.A) for _, other in passed)
    if apart_deg > MAX_UNLABELLED_DISAGREEMENT_DEG:
        raise CalibrationError(f"the {len(stands)} standing periods fit the marker layout in more than one way "
                               f"(camera poses {apart_deg:.0f} degrees apart): label the "
                               "frames by marker, or record the marker walk alone")
    return best


def rotation_between_deg(A1, A2) -> float:
    """Angle (degrees) between the rotations of two camera -> robot maps (their scales removed)."""
    R1, R2 = (np.asarray(A, float) / np.cbrt(abs(np.linalg.det(A))) for A in (A1, A2))
    return float(np.degrees(np.arccos(np.clip((np.trace(R1.T @ R2) - 1.0) / 2.0, -1.0, 1.0))))
