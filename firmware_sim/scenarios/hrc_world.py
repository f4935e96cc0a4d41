"""The closed-loop world of ``python -m firmware_sim hrc``: worker, camera, perception, runtime, Sawyer.

Everything runs in SIMULATED time on one :class:`firmware_sim.robot.controller.SimClock`,
so a 10 s scenario takes about a second of CPU. Per physics/control step (``dt_s`` = 10 ms):

1. camera frames whose processing latency has elapsed are handed to the runtime
   (``RobotLoop.feed_lifted``), timed with ``perf_counter`` (``reaction_ms``);
2. ``RobotLoop.tick()`` (link poll, staleness check, task motion, heartbeat);
3. the collision check of the worker's TRUE joints against the arm's TRUE posture;
4. ``SimulatedRobot.step(dt_s)``: the controller reads the runtime's frames off the real
   link (CAN frames on python-can's virtual bus with E2E, or signed MAVLink 2 on a socket
   pair), moves the arm within its limits and reports its state back.

The worker (:mod:`firmware_sim.people.motions`, sampled at the physics rate) does not react to
the arm: he walks his path, and the runtime must keep the arm clear of him.

Camera and perception
---------------------
The camera (:mod:`firmware_sim.devices.camera`) captures at ``camera_hz`` (30 Hz, or the
dissertation's 5.8 Hz); :func:`firmware_sim.devices.camera.detect` turns the true joints into
2D keypoints with detector noise, outliers, limb swaps and missed joints. A frame reaches
the runtime ``latency_s`` after its capture (default: one camera period, i.e. detection
and lifting pipelined at the camera's rate; the dissertation's 5.8 Hz pipeline took
0.17 s per frame). Two perception paths:

* ``truth``: the detector's 2D keypoints are back-projected at the joint's true depth
  plus a depth error (``depth_noise_m``: a slowly drifting error common to the body plus
  white per-joint jitter, scaled with the detector noise), i.e. the detector-level noise
  mapped to 3D; missing joints are held for up to 3 frames like the lifter does, longer
  and the frame is invalid (``missing_joints``), nobody detected is ``no_person``. The
  joints arrive in the robot frame (no calibration).
* ``lifter``: keypoints -> :class:`edge_runtime.robot.lifter.StreamingLifter` (the shipped
  model, found through ``edge_runtime/assets/manifest.json``) -> the 3-marker calibration
  of Eq. 1-2, made per camera placement the way the dissertation does it: a simulated
  worker stands on the three floor markers in turn (:func:`calibrate`).

Collisions and separation
-------------------------
The clearance at a step is the smallest distance from any of the worker's 17 true joints
to the end effector (the hand origin) or to the SURFACE of any of the arm's collision
spheres (:meth:`firmware_sim.robot.sawyer.SawyerArm.collision_spheres`: links l0..l6, hand
and a 10 cm tool). A collision is a clearance below ``collision_m`` (0.10 m).
``min_separation_m`` is the smallest clearance over the run.

False alarms and reaction
-------------------------
A zone entry is a rise of the runtime's zone level (``HazardMonitor.level``) to LEVEL1 or
LEVEL2. It is a FALSE ALARM when, at that moment, the TRUE worker is outside that level's
radius plus ``false_alarm_margin_m`` by the runtime's own rule: the ground distance from
the true end effector to the nearer of the true head and the true predicted head (true
head + ``predict_s`` x true head velocity, Eq. 3) exceeds ``R_level + margin``.
``reaction_ms`` is wall-clock time from a frame's keypoints being handed to the runtime
to the command it caused being written on the link (``perf_counter`` around the perception
call and ``RobotLoop.feed_lifted``, for frames that caused a command). ``head_error_m`` is the
distance between the head the runtime was given (robot frame, after the calibration) and the
true head at the frame's capture, over valid frames. ``runtime_cpu_share``
is the wall-clock time spent inside the runtime (every frame and every tick) per simulated
second: the share of one core the runtime would take in real time.
The simulated-time delay per level is the time from the true distance first falling
to the level's radius to the first command the runtime sent in that level (negative:
the runtime acted before the truth got there, thanks to the prediction).
"""
from __future__ import annotations

import functools
import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from edge_runtime.core.skeleton import BASE_HEIGHT_M, HEAD
from edge_runtime.robot.hazard import State, arm_capsules, body_spheres, ground, separation_m
from edge_runtime.robot.lifter import MISSING_JOINTS, NO_PERSON, LiftedPose
from edge_runtime.robot.loop import RobotLoop
from edge_runtime.robot.rays import lifter_rays
from firmware_sim.devices.camera import CANONICAL, Camera, DetectorNoise, detect, resample
from firmware_sim.people import motions
from firmware_sim.people.human import Body, heading_towards
from firmware_sim.robot.controller import SimClock, SimulatedRobot
from firmware_sim.robot.sawyer import SawyerArm
from firmware_sim.scenarios.hrc_hard import HardNoise, coco_noise, occlude

HRC_TASK_M: tuple[tuple[float, float, float], ...] = (
    (0.55, 0.14, 0.75), (0.0, 0.14, 1.0), (-0.55, 0.14, 0.75))
"""The arm's task in these scenarios (robot-frame end-effector waypoints, m): a sweep that
reaches 1.0 m out on the work side, into the walkway, at the dissertation's working height
(y = 0.14 m is 1.055 m above the floor)."""
CELL_POINT_XZ_M = (0.0, 1.0)
"""The task's outermost point (ground x, z): where walkers aim and pass."""


@dataclass(frozen=True)
class WorldParams:
    """Timing and judging of the simulated world."""

    dt_s: float = 0.01
    """Physics and control step (s)."""
    camera_hz: float = 30.0
    """Camera frame rate (Hz): 30, or the dissertation's 5.8."""
    latency_s: float | None = None
    """Capture -> runtime latency of a frame (s); None: one camera period."""
    pre_roll_s: float = 1.5
    """Empty scene before the worker appears (the arm starts on its task's first waypoint): the
    runtime reaches NORMAL (after ``ZoneParams.dwell_s`` of poses) and the arm is at work."""
    collision_m: float = 0.10
    """A worker joint closer than this to the end effector or a collision-sphere surface is a collision (m)."""
    false_alarm_margin_m: float = 0.3
    """A zone entry with the true worker beyond the zone radius plus this is a false alarm (m)."""
    depth_noise_m: float = 0.06
    """``truth`` perception: depth error (m, 1 sd at noise scale 1), half a slowly drifting body error,
    half white per-joint jitter."""
    hold_frames: int = 3
    """``truth`` perception: a missed joint is held this many frames (as the lifter does)."""
    min_score: float = 0.3
    """``truth`` perception: keypoints scored below this are missed (as the lifter does)."""
    trace_every: int = 2
    """Keep every n-th step in the trace (for plots)."""
    labelled_calibration: bool = True
    """``lifter`` perception: the calibration is handed the simulator's marker labels (True), or the
    runtime's own stand detection must find the stands (False: ``hrc --unlabelled-calibration``)."""

    @property
    def frame_latency_s(self) -> float:
        return 1.0 / self.camera_hz if self.latency_s is None else self.latency_s


@dataclass(frozen=True)
class WorkerSpec:
    """One worker of a scenario: his path and how he walks it (he never reacts to the arm)."""

    waypoints_xz_m: tuple[tuple[float, float], ...]
    speeds_mps: tuple[float, ...]
    """Walking speed per leg of the path (m/s)."""
    height_m: float = 1.75
    stand_s: float = 1.0
    """Standing at the start, seen by the camera, before walking (s)."""
    linger_s: float = 1.0
    """Standing at the end of the path (s)."""
    start_s: float = 0.0
    """He enters the scene this long after the scenario starts (s; absent before)."""
    pause: tuple[int, float] | None = None
    """Stop-and-go: (waypoint index, seconds) he stands at that inner waypoint."""
    corner_radius_m: float = 0.0
    reach_s: float = 0.0
    """At the end of his path he reaches both arms toward the tool for this long (s)."""
    kind: str = "pass"
    seed: int = 0


@dataclass(frozen=True)
class Scenario:
    """One or more workers, their paths, one camera."""

    name: str
    waypoints_xz_m: tuple[tuple[float, float], ...]
    """The worker's path on the floor (robot x, z; m)."""
    speed_mps: float
    kind: str = "pass"
    """"pass": walks by and on; "stop": walks toward the cell and stops short of the end effector."""
    height_m: float = 1.75
    camera_eye_m: tuple[float, float, float] = (0.0, 0.6, 6.9)
    camera_target_m: tuple[float, float, float] = (0.0, 0.086, 0.9)
    noise_scale: float = 1.0
    """Detector noise multiplier (``DetectorNoise.scaled``)."""
    stand_s: float = 1.0
    """Standing at the start, seen by the camera, before walking (s)."""
    linger_s: float = 1.0
    """Standing at the end of the path (s)."""
    seed: int = 0
    task_m: tuple[tuple[float, float, float], ...] = HRC_TASK_M
    """The arm's task during this scenario (``LoopParams.task_waypoints_m``)."""
    min_base_distance_m: float = float("nan")
    """Closest ground distance of the path to the base's axis (m; filled in by the builders)."""
    first_worker: WorkerSpec | None = None
    """The first worker in full (the hard suite: speeds per leg, a pause, a reach); None: the
    fields above describe him."""
    extra_workers: tuple[WorkerSpec, ...] = ()
    """Further workers (the hard suite)."""
    hard: bool = False
    """The hard suite's world: a real detector's noise and offsets, occlusion, and a calibration
    from an unlabelled calibration walk (:mod:`firmware_sim.scenarios.hrc_hard`)."""

    def workers(self) -> list[WorkerSpec]:
        """Every worker: the scenario's own first, then ``extra_workers``."""
        first = self.first_worker or WorkerSpec(self.waypoints_xz_m, (self.speed_mps,) * (len(self.waypoints_xz_m) - 1),
                                                self.height_m, self.stand_s, self.linger_s, kind=self.kind,
                                                seed=self.seed)
        return [first, *self.extra_workers]

    def camera(self, rate_hz: float) -> Camera:
        return Camera.look_at(self.camera_eye_m, self.camera_target_m, CANONICAL, 0.0, rate_hz)

    def describe(self) -> dict:
        out = {"name": self.name, "kind": self.kind, "speed_mps": round(self.speed_mps, 3),
               "height_m": round(self.height_m, 3), "noise_scale": round(self.noise_scale, 3),
               "path_xz_m": [[round(a, 3), round(b, 3)] for a, b in self.waypoints_xz_m],
               "min_base_distance_m": round(self.min_base_distance_m, 3),
               "camera_eye_m": [round(v, 3) for v in self.camera_eye_m], "workers": 1 + len(self.extra_workers)}
        if self.extra_workers or self.hard:
            out["worker_specs"] = [{"kind": w.kind, "speeds_mps": [round(v, 2) for v in w.speeds_mps],
                                    "path_xz_m": [[round(a, 3), round(b, 3)] for a, b in w.waypoints_xz_m],
                                    "start_s": round(w.start_s, 2), "pause": w.pause, "reach_s": w.reach_s,
                                    "height_m": round(w.height_m, 3)} for w in self.workers()]
        return out


def path_base_distance(waypoints_xz_m) -> float:
    """Closest ground distance (m) of a polyline to the robot base's axis (the origin)."""
    p = np.asarray(waypoints_xz_m, float)
    best = math.inf
    for a, b in zip(p[:-1], p[1:]):
        d = b - a
        t = float(np.clip(-(a @ d) / max(d @ d, 1e-12), 0.0, 1.0))
        best = min(best, float(np.linalg.norm(a + t * d)))
    return best


def worker_motion(w: WorkerSpec | Scenario, rate_hz: float) -> motions.Motion:
    """A worker's true motion at ``rate_hz``: stand at the start, walk the path (standing at
    ``pause``), then stand, or reach toward the tool (``reach_s``), at the end."""
    if isinstance(w, Scenario):
        w = w.workers()[0]
    body = Body.from_height(w.height_m)
    pts = np.asarray(w.waypoints_xz_m, float)
    rng = np.random.default_rng(w.seed)
    h0 = heading_towards(pts[0], pts[1])
    legs = [(pts, w.speeds_mps)]
    if w.pause is not None and 0 < w.pause[0] < len(pts) - 1:
        i = w.pause[0]
        legs = [(pts[:i + 1], w.speeds_mps[:i]), (pts[i:], w.speeds_mps[i:])]
    parts = [motions.stand(body, pts[0], h0, w.stand_s, rate_hz, rng=rng)]
    for n, (leg, speeds) in enumerate(legs):
        walk = motions.walk(body, leg, speeds, rate_hz, corner_radius_m=w.corner_radius_m, rng=rng)
        parts.append(walk)
        end_xz, end_h = walk.end
        if n < len(legs) - 1:
            parts.append(motions.stand(body, end_xz, end_h, w.pause[1], rate_hz, rng=rng))
    if w.reach_s > 0:  # both arms out toward the tool at its height, as far as they go
        parts.append(motions.work_at(body, end_xz, end_h, w.reach_s, work_height_m=BASE_HEIGHT_M + 0.14,
                                     reach_m=0.75, rate_hz=rate_hz, rng=rng, label="reach"))
    parts.append(motions.stand(body, end_xz, end_h, w.linger_s, rate_hz, rng=rng))
    return motions.concat(parts, blend_s=0.2)


def scene_joints(sc: Scenario, rate_hz: float) -> np.ndarray:
    """(W, T, 17, 3) true joints of every worker at ``rate_hz``: NaN before he enters; after
    his motion ends he stays where it left him."""
    mots = [worker_motion(w, rate_hz) for w in sc.workers()]
    starts = [int(round(w.start_s * rate_hz)) for w in sc.workers()]
    T = max(s0 + len(m) for s0, m in zip(starts, mots))
    out = np.full((len(mots), T, 17, 3), np.nan)
    for i, (s0, m) in enumerate(zip(starts, mots)):
        out[i, s0:s0 + len(m)] = m.joints_m
        out[i, s0 + len(m):] = m.joints_m[-1]
    return out


# ----------------------------------------------------------------------------------------------
# perception

class TruthPerception:
    """Detector keypoints back-projected at the true depth (+ depth noise): see the module docstring.

    ``frame(k)`` returns a :class:`edge_runtime.robot.lifter.LiftedPose` whose joints are in the
    robot frame (the loop runs without a calibration)."""

    name = "truth"

    def __init__(self, camera: Camera, joints_m: np.ndarray, keypoints: np.ndarray, params: WorldParams,
                 noise_scale: float, rng: np.random.Generator):
        self.camera, self.params = camera, params
        cam = camera.to_camera(joints_m)                          # (T, 17, 3) true camera-frame joints
        T = len(cam)
        sd = params.depth_noise_m * noise_scale * math.sqrt(0.5)
        a = math.exp(-1.0 / (0.5 * camera.rate_hz))
        drift = np.empty(T)
        x = rng.normal()
        for t in range(T):
            x = a * x + math.sqrt(1 - a * a) * rng.normal()
            drift[t] = x
        self.depth = cam[..., 2] + sd * (drift[:, None] + rng.normal(size=(T, 17)))
        self.keypoints = keypoints
        self._last = np.full((17, 3), np.nan)
        self._age = np.full(17, np.inf)

    def frame(self, k: int, t_s: float) -> LiftedPose:
        kp = self.keypoints[k]
        ok = np.isfinite(kp[:, :2]).all(1) & (kp[:, 2] >= self.params.min_score)
        K = self.camera.intrinsics
        d = self.depth[k]
        cam = np.stack([(kp[:, 0] - K.cx_px) / K.fx_px * d, (kp[:, 1] - K.cy_px) / K.fy_px * d, d], 1)
        self._last[ok] = self.camera.to_robot(cam[ok])
        self._age[ok] = 0
        self._age[~ok] += 1
        stale = self._age > self.params.hold_frames
        if stale.any():
            code = NO_PERSON if not ok.any() else MISSING_JOINTS
            return LiftedPose(t_s, np.full((17, 3), np.nan), np.full(3, np.nan), False, f"{code}: simulated",
                              ok)
        return LiftedPose(t_s, self._last.copy(), self._last[0].copy(), True, None, ok)

    def push(self, k: int, t_s: float):
        return self.frame(k, t_s)


class LifterPerception:
    """Keypoints -> the shipped StreamingLifter (camera-frame joints); the loop applies the calibration."""

    name = "lifter"

    def __init__(self, lifter, keypoints: np.ndarray):
        self.lifter, self.keypoints = lifter, keypoints

    def push(self, k: int, t_s: float):
        kp = self.keypoints[k]
        return self.lifter.push(t_s, None if not np.isfinite(kp[:, :2]).any() else kp)


def lifter_available(assets_dir=None) -> bool:
    """Does the manifest list a pose lifter (arch "lifter")?"""
    import json

    from edge_runtime.core.manifest import ASSETS_DIR

    try:
        manifest = json.loads((Path(assets_dir or ASSETS_DIR) / "manifest.json").read_text())
    except (OSError, ValueError):
        return False
    return any(m.get("arch") == "lifter" for m in manifest.get("models", []))


def box_config():
    """The shipped box configuration (every robot section registered): what the cell runs by default."""
    import edge_runtime.robot.calibration  # noqa: F401  (registers [calibration])
    from edge_runtime import config

    return config.load(None)


def make_lifter(box=None):
    """The shipped lifter with the box's [lifter] settings (trained for 30 Hz; slower cameras are
    spaced out by it)."""
    from edge_runtime.robot.lifter import StreamingLifter

    return StreamingLifter.from_manifest(params=(box or box_config()).lifter)


def calibrate(camera: Camera, rng: np.random.Generator, noise: DetectorNoise, height_m: float = 1.75,
              stand_s: float | None = None, box=None, labelled: bool = True, real_noise: bool = False):
    """The dissertation's calibration for one camera placement: a simulated worker stands ``stand_s``
    (default: 4 s, or 80 camera frames when that is longer: at 5.8 Hz the lifter's warm-up takes
    about 2 s and every detector miss burst resets it) on each floor marker (Eq. 1-2's (0, 1), (1, 1), (0, 2)), walking between them; his keypoints go through
    the lifter (frames still warming up are not used) and :func:`edge_runtime.robot.calibration.from_recording`
    fits camera -> robot. ``real_noise`` (the hard suite): the detector has a real one's noise
    (:func:`firmware_sim.scenarios.hrc_hard.coco_noise`); ``labelled=False``: the runtime's procedure
    finds the three stands in the recording itself, without the simulator's labels (at a real
    detector's noise it does not: reports/hrc/report.md). Raises
    ``edge_runtime.robot.calibration.CalibrationError`` when the fit refuses."""
    from edge_runtime.robot.calibration import from_recording

    box = box or box_config()
    rate = camera.rate_hz
    stand_s = stand_s or max(4.0, 80.0 / rate)
    body = Body.from_height(height_m)
    markers = box.calibration.markers_xz_m
    parts, labels = [], []
    for i, m in enumerate(markers):
        if i:
            w = motions.walk(body, [markers[i - 1], m], 0.8, rate)
            parts.append(w)
            labels.append(np.zeros(len(w), int))
        s = motions.stand(body, m, math.pi, stand_s, rate, rng=rng)
        parts.append(s)
        labels.append(np.full(len(s), i + 1))
    mot = motions.concat(parts, blend_s=0.2)
    kp = detect(camera, mot.joints_m, rng, noise)
    if real_noise:
        kp = coco_noise(camera, mot.joints_m, kp, height_m, rng)
    lifter = make_lifter(box)
    t = np.arange(len(kp)) / rate
    joints = np.full((len(kp), 17, 3), np.nan)
    for k in range(len(kp)):
        out = lifter.push(t[k], kp[k] if np.isfinite(kp[k, :, :2]).any() else None)
        if out.valid and not out.warming_up:
            joints[k] = out.joints_cam_m
    cal = from_recording(t, joints, box.calibration, marker=np.concatenate(labels) if labelled else None)
    return cal, mot, lifter


# ----------------------------------------------------------------------------------------------
# the closed loop

ARM_FOOTPRINT_M = 1.45
"""No part of the arm (collision spheres, the 10 cm tool) reaches further than this from the
base's axis (m; the reach is 1.26 m from the shoulder)."""
FAR_CHECK_M, FAR_CHECK_EVERY = 0.5, 10
"""While every worker joint is more than ``ARM_FOOTPRINT_M + FAR_CHECK_M`` from the base's axis the
clearance is computed every ``FAR_CHECK_EVERY``-th step only (it is above 0.5 m anyway)."""


@functools.lru_cache(maxsize=16)
def task_start_posture(position_m: tuple, pitch_rad: float, yaw_rad: float) -> np.ndarray:
    """Joint angles (7,) with the end effector on the task's first waypoint (the arm starts at work)."""
    return SawyerArm().solve_ik(position_m, pitch_rad, yaw_rad)


def clearance_m(joints_m: np.ndarray, centres: np.ndarray, radii: np.ndarray, ee_m: np.ndarray) -> float:
    """Smallest distance (m) from any joint (17, 3) to the end effector or a sphere surface."""
    d_sph = np.linalg.norm(joints_m[:, None, :] - centres[None], axis=-1) - radii[None]
    d_ee = np.linalg.norm(joints_m - ee_m, axis=-1)
    return float(min(d_sph.min(), d_ee.min()))


@dataclass
class RunResult:
    """One scenario's figures (``summary``) and traces (for the plots)."""

    summary: dict
    t_s: np.ndarray
    head_xz_m: np.ndarray
    """(n, W, 2) every worker's head on the ground (NaN while absent)."""
    ee_xz_m: np.ndarray
    state: np.ndarray
    reaction_s: list = field(default_factory=list)
    head_error_m: list = field(default_factory=list)
    speed_mps: np.ndarray = field(default_factory=lambda: np.empty(0))
    """The hand's true speed (m/s) at each traced step."""
    limit_mps: np.ndarray = field(default_factory=lambda: np.empty(0))
    """The hand's speed limit while the arm works (0 while it is held: stopped, retracting, fault)."""


def run_scenario(sc: Scenario, link: str = "can", runtime: bool = True, perception: str = "truth",
                 world: WorldParams = WorldParams(), box=None) -> RunResult:
    """Run one scenario closed-loop with the box configuration ``box`` (default: the shipped one;
    the scenario's task replaces ``[robot_loop] task_waypoints_m``); see the module docstring for
    what is measured."""
    box = box or box_config()
    zones = box.zones
    dt = world.dt_s
    rate = round(1.0 / dt)
    rng = np.random.default_rng([sc.seed, 7])
    lp = replace(box.robot_loop, task_waypoints_m=sc.task_m)
    J = scene_joints(sc, rate)                          # (W, T, 17, 3) at the physics rate
    W = len(J)
    present = np.isfinite(J[..., 0, 0])                 # (W, T)
    n_pre = int(round(world.pre_roll_s / dt))
    n_total = n_pre + J.shape[1]
    camera = sc.camera(world.camera_hz)
    noise = DetectorNoise().scaled(sc.noise_scale)
    Jc = np.stack([resample(j, rate, world.camera_hz) for j in J])      # (W, Tc, 17, 3) at the camera's frames
    t_cap = n_pre * dt + np.arange(Jc.shape[1]) / world.camera_hz
    heights = [w.height_m for w in sc.workers()]
    kp = np.stack([detect(camera, Jc[w], rng, noise) for w in range(W)])
    if sc.hard:
        kp = np.stack([coco_noise(camera, Jc[w], kp[w], heights[w], rng) for w in range(W)])
    calibration = None
    if not runtime:
        percepts = None
    elif perception == "lifter":
        from edge_runtime.robot.calibration import CalibrationError

        try:
            calibration, _, _ = calibrate(camera, rng, noise, box=box, real_noise=sc.hard,
                                          labelled=world.labelled_calibration)
        except CalibrationError as e:  # the box would refuse to run: the arm never moves
            return _not_run(sc, link, world, f"calibration failed: {e}")
        percepts = [LifterPerception(make_lifter(box), kp[w]) for w in range(W)]
    else:
        percepts = [TruthPerception(camera, Jc[w], kp[w], world, sc.noise_scale, rng) for w in range(W)]
    # the truth: heads, their ground velocity and Eq. 3's prediction, at the physics rate
    head = J[:, :, HEAD]                                                # (W, T, 3)
    v = np.gradient(np.nan_to_num(head), dt, axis=1)
    k_smooth = max(1, int(0.2 / dt))
    v = np.apply_along_axis(lambda c: np.convolve(c, np.ones(k_smooth) / k_smooth, "same"), 1, v)
    pred = head + zones.predict_s * v
    whole_body = zones.separation == "whole_body"

    clock = SimClock()
    sim = SimulatedRobot(link, clock=clock, q0_rad=task_start_posture(lp.task_waypoints_m[0], lp.task_pitch_rad,
                                                                      lp.task_yaw_rad))
    loop = RobotLoop(sim.link, calibration=calibration, zones=zones, tracker=box.tracker, params=lp, clock=clock)
    radii = {State.LEVEL1: zones.r1_m, State.LEVEL2: zones.r2_m}
    frame_i, deliver = 0, t_cap + world.frame_latency_s
    empty_next = 0.0
    min_clear, collision_steps, first_collision = math.inf, 0, None
    arm_moved_s, arm_still_at_contact_s = -math.inf, None  # when the arm last moved; how long it had been still
    arm_moved_in_contact = False  # the arm moved at any step a worker was within collision_m of it
    reaction, entries, false_alarms = [], [], []
    true_enter = {State.LEVEL1: None, State.LEVEL2: None}
    act_at = {State.LEVEL1: None, State.LEVEL2: None}
    counters0 = None
    prev_level = State.NORMAL
    max_state = State.NORMAL
    trace_t, trace_head, trace_ee, trace_state, trace_speed, trace_limit = [], [], [], [], [], []
    frame_s = tick_s = 0.0  # wall-clock time inside the runtime (per-frame calls, ticks)
    head_err = []
    came_within, halts, prev_state = False, 0, State.NORMAL
    halt_reasons: dict[str, int] = {}
    state_steps: dict[str, int] = {}  # where the arm's time went: steps per monitor state (NORMAL: productive)
    halt_steps: dict[str, int] = {}  # and the halted steps by the reason the halt began with
    why = None
    try:
        for step in range(n_total):
            now = clock()
            k = step - n_pre
            if k == 0:
                counters0 = dict(vars(loop.counters))
            # 1. camera frames due now
            if k < 0 or percepts is None:
                if now + 1e-9 >= empty_next:  # an empty scene (or an arm unaware of the worker)
                    loop.feed_joints(None)
                    empty_next += 1.0 / world.camera_hz
            else:
                while frame_i < len(deliver) and deliver[frame_i] <= now + 1e-9:
                    if sc.hard:  # the world hides what the camera cannot see (not the runtime's time)
                        _occlude(percepts, frame_i, camera, Jc, sim.controller.arm)
                    w0 = time.perf_counter()
                    outs = [p.push(frame_i, t_cap[frame_i]) for p in percepts]
                    rec = _feed(loop, outs, percepts, frame_i)
                    w1 = time.perf_counter()
                    frame_s += w1 - w0
                    for w, out in enumerate(outs):  # the head the runtime saw, robot frame, against the truth
                        if out.valid and np.isfinite(Jc[w, frame_i, HEAD]).all():
                            seen = out.joints_cam_m[HEAD] if calibration is None else calibration.to_robot(
                                out.joints_cam_m)[HEAD]  # what the loop sees: floor-anchored when configured
                            head_err.append(float(np.linalg.norm(seen - Jc[w, frame_i, HEAD])))
                    if rec.command is not None:
                        reaction.append(w1 - w0)
                    frame_i += 1
            # 2. control cycle
            w0 = time.perf_counter()
            loop.tick()
            tick_s += time.perf_counter() - w0
            # 3. truth and judging
            arm = sim.controller.arm
            ee = arm.pose().position_m
            if k >= 0:
                here = present[:, k]
                c = math.inf
                if here.any():
                    Jk = J[here, k].reshape(-1, 3)
                    far = float(np.min(np.hypot(Jk[:, 0], Jk[:, 2]))) - ARM_FOOTPRINT_M
                    if far < FAR_CHECK_M or k % FAR_CHECK_EVERY == 0:  # far from any reach: every 10th step
                        centres, r = arm.collision_spheres()
                        c = clearance_m(Jk, centres, r, ee)
                if c < min_clear:
                    min_clear = c
                if arm.moving:
                    arm_moved_s = k * dt
                if c < world.collision_m:
                    collision_steps += 1
                    arm_moved_in_contact |= arm.moving
                    if first_collision is None:
                        first_collision = round(k * dt, 3)
                        arm_still_at_contact_s = round(min(k * dt - arm_moved_s, k * dt), 3)
                e = ground(ee)
                level = loop.monitor.level
                judge_now = level > prev_level and level in radii
                if whole_body:
                    judge_radii = {State.LEVEL1: zones.body_protective_distance_m(arm.speed_limit_mps),
                                   State.LEVEL2: zones.body_retract_distance_m
                                   + zones.retract_lead_s * zones.iso_human_speed_mps}
                    if judge_now or k % 5 == 0:
                        true_d = _true_separation(J[:, k], v[:, k], here, arm.q_rad, zones.predict_s)
                        came_within |= true_d <= zones.body_protective_distance_m(zones.iso_robot_speed_mps)
                else:
                    judge_radii = radii
                    true_d = min((min(np.linalg.norm(ground(pred[w, k]) - e), np.linalg.norm(ground(head[w, k]) - e))
                                  for w in range(W) if here[w]), default=math.inf)
                    came_within |= true_d <= radii[State.LEVEL1]
                if not whole_body or judge_now or k % 5 == 0:
                    for lvl, rad in judge_radii.items():
                        if true_enter[lvl] is None and true_d <= rad:
                            true_enter[lvl] = now
                if judge_now:
                    false = bool(true_d > judge_radii[level] + world.false_alarm_margin_m)
                    entries.append({"t_s": round(k * dt, 3), "level": level.name, "true_distance_m": round(
                        float(true_d), 3), "false_alarm": false})
                    false_alarms.append(false)
                prev_level = level
                st = loop.monitor.state
                if st != State.NORMAL and prev_state == State.NORMAL:  # a halt, and the runtime's reason
                    halts += 1
                    why = loop.monitor.reason.split(":", 1)[0].split(" (", 1)[0]
                    halt_reasons[why] = halt_reasons.get(why, 0) + 1
                state_steps[st.name] = state_steps.get(st.name, 0) + 1
                if st != State.NORMAL and why is not None:
                    halt_steps[why] = halt_steps.get(why, 0) + 1
                prev_state = st
                max_state = max(max_state, st) if st != State.FAULT else max_state
                for lvl in radii:
                    if act_at[lvl] is None and st == lvl:  # its command went out in the call that changed state
                        act_at[lvl] = now
                if k % world.trace_every == 0:
                    trace_t.append(k * dt)
                    trace_head.append(ground(head[:, k]))
                    trace_ee.append(e)
                    trace_state.append(int(st))
                    trace_speed.append(float(np.linalg.norm(arm.ee_velocity_mps())))
                    trace_limit.append(arm.speed_limit_mps if st == State.NORMAL else 0.0)
            # 4. the arm
            sim.step(dt)
    finally:
        sim.close()
    c1 = vars(loop.counters)
    diff = {key: c1[key] - (counters0 or {}).get(key, 0)
            for key in ("stops", "retracts", "unreachable", "invalid", "speed_changes")}
    delays = {lvl.name: (None if true_enter[lvl] is None or act_at[lvl] is None
                         else round(act_at[lvl] - true_enter[lvl], 3)) for lvl in radii}
    scenario_s = (n_total - n_pre) * dt
    productive_s = state_steps.get(State.NORMAL.name, 0) * dt
    worker_s = float(present.sum() * dt)
    summary = {
        **sc.describe(), "link": link, "runtime": runtime, "perception": percepts[0].name if percepts else "none",
        "camera_hz": world.camera_hz, "latency_ms": round(1000 * world.frame_latency_s, 1),
        "collision": collision_steps > 0, "collision_steps": collision_steps, "first_collision_s": first_collision,
        "arm_still_at_contact_s": arm_still_at_contact_s, "arm_moved_in_contact": arm_moved_in_contact,
        "min_separation_m": round(min_clear, 4), **diff,
        "false_alarms": int(sum(false_alarms)), "zone_entries": entries,
        "max_state": max_state.name, "command_delay_s": delays,
        "reaction_ms": percentiles(reaction), "frames": frame_i,
        "head_error_m": percentiles(head_err, 1.0, (50, 95)),
        "runtime_cpu_share": round((frame_s + tick_s) / max(n_total * dt, 1e-9), 5),
        "calibration_scale": None if calibration is None else round(calibration.scale, 4),
        "scenario_s": round(scenario_s, 3), "worker_s": round(worker_s, 3),
        "productive_s": round(productive_s, 3), "productive_time_share": round(productive_s / scenario_s, 4),
        "came_within_protective": bool(came_within), "halts": halts, "halt_reasons": halt_reasons,
        "state_s": {name: round(n * dt, 3) for name, n in state_steps.items()},
        "halt_s": {name: round(n * dt, 3) for name, n in halt_steps.items()},
    }
    return RunResult(summary, np.array(trace_t), np.array(trace_head), np.array(trace_ee), np.array(trace_state),
                     reaction, head_err, np.array(trace_speed), np.array(trace_limit))


def _true_separation(joints_m: np.ndarray, head_velocity_mps: np.ndarray, here: np.ndarray, q_rad,
                     predict_s: float) -> float:
    """The judge's whole-body separation (m): the runtime's rule (hazard.separation_m, body radii,
    the arm's capsules) on the TRUE joints and the TRUE arm, now and ``predict_s`` ahead."""
    caps = arm_capsules(q_rad)
    best = math.inf
    for w in np.flatnonzero(here):
        centres, r = body_spheres(joints_m[w])
        ahead = np.array([head_velocity_mps[w, 0], 0.0, head_velocity_mps[w, 2]]) * predict_s
        best = min(best, separation_m(centres, r, caps), separation_m(centres + ahead, r, caps))
    return best


def _occlude(percepts, k: int, camera: Camera, Jc: np.ndarray, arm) -> None:
    """The hard suite: every worker's keypoints of camera frame ``k`` are missed where another
    worker or the arm (where it is now) blocks the view, and scored low where his own trunk does
    (a detector guesses those)."""
    here = np.isfinite(Jc[:, k, 0, 0])
    hidden, behind = occlude(camera.position_m, Jc[:, k], here, arm.collision_spheres())
    for w, p in enumerate(percepts):
        kp = p.keypoints[k]
        kp[hidden[w]] = [np.nan, np.nan, 0.0]
        kp[behind[w], 2] = np.minimum(kp[behind[w], 2], HardNoise().self_occluded_score)


def _feed(loop: RobotLoop, outs: list, percepts: list, k: int):
    """One camera frame (``k``) of every worker's perception into the loop, with his worker index
    as his id (the simulator knows who is who: it stands in for ``keypoints.PersonTracker``), the
    way the product feeds its tracked people (``RobotLoop.feed_people``): a worker lifted invalidly
    comes with his keypoints' rays through the lifter's camera."""
    rays = {w: lifter_rays(p.lifter, p.keypoints[k]) for w, (p, out) in enumerate(zip(percepts, outs))
            if not out.valid and isinstance(p, LifterPerception)}
    return loop.feed_poses(list(enumerate(outs)), rays=rays)


def _not_run(sc: Scenario, link: str, world: WorldParams, why: str) -> RunResult:
    """A scenario that could not run (the lifter path's calibration was refused for this camera)."""
    summary = {**sc.describe(), "link": link, "runtime": True, "perception": "lifter", "camera_hz": world.camera_hz,
               "latency_ms": round(1000 * world.frame_latency_s, 1), "not_run": why, "collision": False,
               "collision_steps": 0, "first_collision_s": None, "arm_still_at_contact_s": None,
               "arm_moved_in_contact": False, "min_separation_m": None, "stops": 0, "retracts": 0,
               "unreachable": 0, "invalid": 0, "false_alarms": 0, "zone_entries": [], "max_state": "NORMAL",
               "command_delay_s": {"LEVEL1": None, "LEVEL2": None}, "reaction_ms": percentiles([]), "frames": 0,
               "head_error_m": percentiles([], 1.0, (50, 95)), "runtime_cpu_share": None, "calibration_scale": None,
               "speed_changes": 0, "scenario_s": 0.0, "worker_s": 0.0, "productive_s": 0.0,
               "productive_time_share": None, "came_within_protective": False, "halts": 0,
               "halt_reasons": {}, "state_s": {}, "halt_s": {}}
    return RunResult(summary, np.empty(0), np.empty((0, 1, 2)), np.empty((0, 2)), np.empty(0, int))


def percentiles(samples, scale: float = 1000.0, q=(50, 99)) -> dict:
    """{"median", "p<q>", "n"} of ``samples`` x ``scale`` (default: seconds -> ms)."""
    keys = ["median" if k == 50 else f"p{k}" for k in q]
    if not len(samples):
        return {**{k: None for k in keys}, "n": 0}
    v = np.percentile(scale * np.asarray(samples, float), q)
    return {**{k: round(float(x), 4) for k, x in zip(keys, v)}, "n": len(samples)}


# ----------------------------------------------------------------------------------------------
# scenarios

CAMERA_6M = ((0.0, 1.8 - 0.914, 6.9), (0.0, 0.086, 0.9))
"""The dissertation's webcam: about 6 m in front of the robot, 1.8 m high, aimed at the cell."""


EXTENDED_M = ((0.0, 0.14, 1.0),)
"""An expanded working posture: the end effector held 1.0 m out on the work side."""
DISSERTATION = ("left_to_right", "right_to_left", "front")


def dissertation_scenarios(seed: int = 0) -> list[Scenario]:
    """Chapter 3's validation walks (Fig. 3.7-3.8), at 1.4 m/s, starting 3.2 m from the end effector,
    the camera 6 m in front of the cell:

    * ``left_to_right``: the arm in an expanded posture (end effector held 1.0 m out) blocks the
      walkway; the worker walks from -x to +x with his pelvis 0.3 m outside the end effector, so
      his body sweeps through the tool;
    * ``right_to_left``: the same posture, the worker walks from +x to -x straight through the tip
      of the tool (the end effector mid-path; the path passes 1.1 m from the base's axis, the
      closest a path can pass and still be avoidable, see ``RandomParams.min_base_distance_m``);
    * ``front``: the same posture; the worker walks from +z straight at the end effector and stops
      with his pelvis 0.15 m short of it (the tool points at him)."""
    eye, target = CAMERA_6M
    cx, cz = CELL_POINT_XZ_M
    common = dict(speed_mps=1.4, camera_eye_m=eye, camera_target_m=target)
    out = [
        Scenario("left_to_right", ((cx - 3.2, cz + 0.3), (cx + 3.2, cz + 0.3)), seed=seed, task_m=EXTENDED_M,
                 **common),
        Scenario("right_to_left", ((cx + 3.2, cz + 0.1), (cx - 3.2, cz + 0.1)), seed=seed + 1, task_m=EXTENDED_M,
                 **common),
        Scenario("front", ((cx, cz + 3.2), (cx, cz + 0.15)), kind="stop", seed=seed + 2, task_m=EXTENDED_M,
                 **common),
    ]
    return [replace(s, min_base_distance_m=path_base_distance(s.waypoints_xz_m)) for s in out]


@dataclass(frozen=True)
class RandomParams:
    """How random approaches are drawn (see :func:`random_scenario`)."""

    speed_mps: tuple[float, float] = (0.5, 2.0)
    start_distance_m: tuple[float, float] = (3.0, 6.0)
    """Start: this far (ground) from the task's outermost point (m)."""
    pass_distance_m: tuple[float, float] = (1.1, 1.8)
    """A passing worker's path comes this close to the base's axis (m; the task reaches 1.0 m
    out, its tool 1.1 m, and a walker's joints 0.3 m to the side of his path)."""
    pass_bearing_deg: float = 60.0
    """The passing path's nearest point lies within this bearing of +z (deg): in front of the arm."""
    pass_oblique_deg: float = 35.0
    """The passing path is up to this far off the tangent there (deg)."""
    stop_short_m: tuple[float, float] = (0.3, 0.9)
    """A stopping worker's pelvis stops this far short of the task's outermost point (m)."""
    min_base_distance_m: float = 1.1
    """Paths that come closer than this to the base's axis are redrawn (m). Nothing can avoid a
    worker who walks through the robot's base, and the arm cannot shrink below a footprint: folded
    as far as a retraction takes it (hand 0.35-0.5 m from the axis, tool turned toward the base)
    its collision spheres still reach 0.62-0.69 m from the axis (measured on the simulated Sawyer),
    a walker's joints reach about 0.3 m to the side of his path, and a collision is 0.10 m; so a
    path must pass about 0.69 + 0.3 + 0.1 = 1.1 m from the axis to be avoidable at all."""
    noise_scale: tuple[float, float] = (0.5, 2.0)
    height_m: tuple[float, float] = (1.55, 1.95)
    camera_distance_m: tuple[float, float] = (3.0, 8.0)
    camera_height_m: tuple[float, float] = (1.0, 3.0)
    p_stop: float = 0.5
    """Share of approaches that stop short (the rest walk past)."""


def random_scenario(rng: np.random.Generator, index: int, seed: int, params: RandomParams = RandomParams()) -> Scenario:
    """A random approach to the cell from the work side: direction, speed, start distance, worker
    height, camera placement (3-8 m, 1-3 m high, aimed at the cell) and detector noise scale; the
    worker either walks past in front of the cell (nearest to the base's axis 1.1-1.8 m out) or
    walks at the task's outermost point and stops short of it. Paths that pass closer than ``min_base_distance_m`` to the base are redrawn."""
    from firmware_sim.devices.camera import random_placement

    p = params
    cell = np.asarray(CELL_POINT_XZ_M, float)
    while True:
        stop = rng.random() < p.p_stop
        # approach direction: from anywhere on the work side (the heading the worker walks)
        come_from = rng.uniform(-0.45 * math.pi, 0.45 * math.pi)      # bearing of the start from the cell, 0 = +z
        u = np.array([math.sin(come_from), math.cos(come_from)])    # cell -> start
        dist = rng.uniform(*p.start_distance_m)
        if stop:
            start = cell + dist * u
            end = cell + rng.uniform(*p.stop_short_m) * u
            pts = (start, end)
        else:
            # pass: a straight walk along the front of the cell, nearest to the base's axis at a
            # bearing within pass_bearing_deg of +z, turned up to pass_oblique_deg off the tangent
            phi = math.radians(rng.uniform(-1.0, 1.0) * p.pass_bearing_deg)
            radial = np.array([math.sin(phi), math.cos(phi)])
            psi = math.radians(rng.uniform(-1.0, 1.0) * p.pass_oblique_deg) + (0.0 if rng.random() < 0.5 else math.pi)
            tangent = np.array([radial[1], -radial[0]])
            walk_dir = math.cos(psi) * tangent + math.sin(psi) * radial
            near = rng.uniform(*p.pass_distance_m) * radial
            pts = (near - dist * walk_dir, near + 1.5 * walk_dir)
        d_base = path_base_distance(pts)
        if d_base >= p.min_base_distance_m:
            break
    cam = random_placement(rng, distance_m=p.camera_distance_m, height_m=p.camera_height_m)
    aim = np.array([0.0, 0.086, 0.9])
    return Scenario(
        f"random_{index:03d}", tuple(tuple(float(v) for v in q) for q in pts), float(rng.uniform(*p.speed_mps)),
        "stop" if stop else "pass", float(rng.uniform(*p.height_m)), tuple(float(v) for v in cam.position_m),
        tuple(float(v) for v in aim), float(rng.uniform(*p.noise_scale)), seed=int(seed * 100003 + index),
        min_base_distance_m=d_base)


def random_scenarios(n: int, seed: int, max_speed_mps: float = 2.0, params: RandomParams = RandomParams()) -> list[Scenario]:
    p = replace(params, speed_mps=(params.speed_mps[0], max_speed_mps))
    rng = np.random.default_rng(seed)
    return [random_scenario(rng, i, seed, p) for i in range(n)]



@dataclass(frozen=True)
class HardParams:
    """How the hard suite's scenarios are drawn (:func:`hard_scenario`; the module docstring of
    :mod:`firmware_sim.scenarios.hrc_hard` describes the suite)."""

    speed_mps: tuple[float, float] = (0.5, 2.0)
    """Speed of each leg (m/s): running bursts up to 2.0."""
    workers: tuple[int, ...] = (1, 2, 2, 3)
    """Drawn from for the number of workers."""
    kinds: tuple[str, ...] = ("approach", "pass", "pass", "walkby")
    """Drawn from for each worker's kind."""
    p_pause: float = 0.4
    """Share of workers who stop and go (a pause of ``pause_s`` at an inner waypoint)."""
    pause_s: tuple[float, float] = (0.5, 2.0)
    p_reach: float = 0.5
    """Share of approaching workers who reach toward the tool at the end."""
    reach_s: tuple[float, float] = (1.5, 3.0)
    start_s: tuple[float, float] = (0.0, 3.0)
    """A second or third worker enters this long after the scenario starts (s)."""
    start_distance_m: tuple[float, float] = (3.0, 6.0)
    approach_short_m: tuple[float, float] = (0.4, 0.9)
    """An approaching worker's pelvis stops this far short of the task's outermost point (m)."""
    pass_distance_m: tuple[float, float] = (1.1, 2.0)
    walkby_distance_m: tuple[float, float] = (2.5, 4.5)
    """Background traffic passes this far from the base's axis (m)."""
    min_base_distance_m: float = 1.1
    """As for random approaches: closer paths cannot be avoided by any arm (RandomParams)."""
    height_m: tuple[float, float] = (1.55, 1.95)
    corner_radius_m: tuple[float, float] = (0.3, 1.0)
    bend_m: tuple[float, float] = (0.3, 1.2)
    """A curved path's inner waypoints are pushed this far sideways from the straight line (m)."""


def _curved(rng: np.random.Generator, a: np.ndarray, b: np.ndarray, p: HardParams) -> np.ndarray:
    """A path from ``a`` to ``b`` with one or two inner waypoints pushed sideways (a curve with turns)."""
    n_inner = int(rng.integers(1, 3))
    d = b - a
    side = np.array([-d[1], d[0]]) / max(float(np.linalg.norm(d)), 1e-9)
    inner = [a + f * d + rng.choice([-1.0, 1.0]) * rng.uniform(*p.bend_m) * side
             for f in np.sort(rng.uniform(0.25, 0.75, n_inner))]
    return np.array([a, *inner, b])


def _hard_worker(rng: np.random.Generator, kind: str, index: int, seed: int, p: HardParams) -> WorkerSpec:
    cell = np.asarray(CELL_POINT_XZ_M, float)
    while True:
        come_from = rng.uniform(-0.45 * math.pi, 0.45 * math.pi)
        u = np.array([math.sin(come_from), math.cos(come_from)])
        dist = rng.uniform(*p.start_distance_m)
        if kind == "approach":
            a, b = cell + dist * u, cell + rng.uniform(*p.approach_short_m) * u
        else:
            phi = math.radians(rng.uniform(-60.0, 60.0))
            radial = np.array([math.sin(phi), math.cos(phi)])
            tangent = np.array([radial[1], -radial[0]]) * (1.0 if rng.random() < 0.5 else -1.0)
            near = rng.uniform(*(p.walkby_distance_m if kind == "walkby" else p.pass_distance_m)) * radial
            a, b = near - dist * tangent, near + 2.0 * tangent
        pts = _curved(rng, a, b, p) if kind != "approach" or rng.random() < 0.7 else np.array([a, b])
        floor = p.walkby_distance_m[0] if kind == "walkby" else p.min_base_distance_m
        if path_base_distance(pts) >= floor:
            break
    legs = len(pts) - 1
    pause = (int(rng.integers(1, legs)), float(rng.uniform(*p.pause_s))) if legs > 1 and rng.random() < p.p_pause \
        else None
    reach = float(rng.uniform(*p.reach_s)) if kind == "approach" and rng.random() < p.p_reach else 0.0
    return WorkerSpec(tuple(tuple(float(v) for v in q) for q in pts),
                      tuple(float(v) for v in rng.uniform(*p.speed_mps, legs)), float(rng.uniform(*p.height_m)),
                      stand_s=1.0, linger_s=1.0, start_s=0.0 if index == 0 else float(rng.uniform(*p.start_s)),
                      pause=pause, corner_radius_m=float(rng.uniform(*p.corner_radius_m)), reach_s=reach, kind=kind,
                      seed=int(seed * 100003 + index))


def hard_scenario(rng: np.random.Generator, index: int, seed: int, params: HardParams = HardParams()) -> Scenario:
    """One scenario of the hard suite: 1-3 workers of random kinds, a random camera, the hard
    world's detector and calibration (see :mod:`firmware_sim.scenarios.hrc_hard`)."""
    from firmware_sim.devices.camera import random_placement

    p = params
    n = int(rng.choice(p.workers))
    specs = [_hard_worker(rng, str(rng.choice(p.kinds)), w, seed * 1000 + index, p) for w in range(n)]
    cam = random_placement(rng, distance_m=(3.0, 8.0), height_m=(1.0, 3.0))
    first = specs[0]
    return Scenario(
        f"hard_{index:03d}", first.waypoints_xz_m, max(first.speeds_mps), first.kind, first.height_m,
        tuple(float(v) for v in cam.position_m), (0.0, 0.086, 0.9), 1.0, seed=first.seed,
        min_base_distance_m=min(path_base_distance(w.waypoints_xz_m) for w in specs),
        first_worker=first, extra_workers=tuple(specs[1:]), hard=True)


def hard_scenarios(n: int, seed: int, params: HardParams = HardParams()) -> list[Scenario]:
    rng = np.random.default_rng([seed, 13])
    return [hard_scenario(rng, i, seed, params) for i in range(n)]
