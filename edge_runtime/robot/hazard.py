"""Head tracking, prediction, the hazard zones of dissertation chapter 3, whole-body speed and
separation monitoring (ISO/TS 15066) and the retraction (Eq. 6).

All positions are in the robot frame of :mod:`edge_runtime.core.skeleton` (metres, ``y``
up, origin on top of the Sawyer base). "Ground-projected" distances drop ``y``.

Sections, in file order: configuration (``TrackerParams``, ``ZoneParams``); tracking
(``HeadTracker``); the state machine (``HazardMonitor``, with the head zones and the
whole-body separation as its two ways of sizing a person's distance); whole-body geometry
(the arm's capsules, the body's spheres); the retraction's pure functions.

Two ways to protect people (``[zones] separation``):

* **"whole_body"** (shipped): every lifted joint of every worker, as a sphere of its body
  part's radius (``BODY_RADII_M``; limb midpoints too), against the arm's links as capsules
  along the Sawyer's chain (``SAWYER_JOINT_ORIGINS``, from the joint angles the arm reports;
  the end effector alone until it has reported any). A person's separation is the smaller of
  now and ``predict_s`` ahead (his whole body moved with his head's velocity). ISO/TS 15066
  speed and separation monitoring: the protective separation distance at robot speed v_r is
  ``S_p = v_h (T_r + T_s) + v_r (T_r + T_s / 2) + C + Z_d + Z_r`` (v_h: his tracked speed,
  at least ISO 13855's 1.6 m/s; T_s the full-speed one, or with ``stop_time_scales``
  shrinking with v_r), so a
  separation allows the robot speed that inverts it. NORMAL works at that speed
  (``speed_scale``, in steps of ``speed_step``; stop-only: full speed or nothing), LEVEL1
  stops below the protective distance at the slowest useful speed, LEVEL2 retracts for anyone
  within ``reach_retract_m`` and for a person who keeps coming (toward the arm faster than
  ``approach_speed_mps``) within ``body_retract_distance_m`` + his approach speed x
  ``retract_lead_s``. After a retraction the arm works again once the person has been
  beyond both exit distances for ``dwell_s`` (``scaled_dwell_s`` with speed scaling). Someone
  still within ``reach_retract_m`` of a finished (or stopped) retraction turns the arm about its base to where its whole body is clearest
  of everyone, without sweeping past anyone nearer than it is (``escape_deg``, :func:`plan_escape_turn`;
  planned again while level 2 lasts); a retraction whose joint motion carries the arm toward someone is
  replaced (:class:`edge_runtime.robot.loop.RobotLoop`, ``retract_backfire_m``).
  **People the camera loses** (hidden, out of view, or lifted invalidly while others are
  lifted): each is judged by his reachable set, his last valid body with every joint
  ``lost_person_speed_mps`` x the time since closer to the arm. While that set stays outside
  the protective distance he is no reason to stop (the arm slows for it as for anyone); once
  it reaches it, the arm stops (``person_lost``) until he is seen again or, ``lost_hold_s``
  after his last valid pose, he is forgotten. **People seen in 2D but never lifted validly**
  (walking in, half out of the picture, partly hidden) are bounded by their keypoints' rays
  (``ray_bound``, :func:`ray_separation_m`): with the calibrated camera, a seen ankle's ray meets
  the floor within a range of distance (or the head's ray crosses the heights of a standing
  person's head; with none of those, any joint he shows is between the floor and a raised wrist's
  height), and every joint he shows lies on its own ray near that range. That region
  stops the arm (``person_unlifted``) once it comes within the protective distance; when his
  rays stop bounding him, his last bound shrinks as a lost person's reachable set does. One
  whose rays never bounded him stops the arm (FAULT, ``person_unseen``) as long as he is in
  view unlifted. The camera or lifter failing as a whole (stale or invalid frames) is still a
  fault stop.
* **"head"**: the dissertation's zones around the end effector, below.

* **Tracking and prediction (Eq. 3).** ``HeadTracker`` fits a straight line to the
  head positions of the last ``window_s`` seconds (least squares, per axis). Its slope
  is the head velocity and its value now is the filtered head position; the prediction
  is ``P_head(T + t) = P_head(T) + t * V_head`` with ``t = 0.5 s``. A finite difference
  of two frames turns 3 cm of head noise per axis at 30 Hz into 2.2 m/s (rms, 3D) of
  velocity noise, i.e. 1.1 m of prediction noise; the 0.5 s fit brings it to 0.09 m/s
  (tests/robot/test_hazard.py::test_least_squares_velocity_rejects_keypoint_noise measures
  both). The price is lag: a change of walking speed is fully seen after ``window_s``.
* **Zones (Eq. 4-5).** Two vertical cylinders around the end effector::

      R2 = V_worker * (T_retract - t) + R_margin2     (Eq. 4)  1.4 * (1 - 0.5) + 0.3 = 1.0 m
      R1 = R2 + R_margin1                             (Eq. 5)  1.0 + 2.0              = 3.0 m

  or, with ``sizing = "iso15066"``, R1 is ISO/TS 15066's protective separation distance
  ``S_p = v_h (T_r + T_s) + v_r T_r + S_s + C + Z_d + Z_r`` (v_h = 1.6 m/s per ISO 13855)
  and R2 stays Eq. 4's retraction radius (R1 is never below R2).
* **Decision.** A worker's distance is the smaller of the ground-projected distances
  from the end effector to his predicted and to his current head (the dissertation uses
  the predicted head only; the current head keeps a worker who stops or turns away
  inside the zone from being waved through). With several workers the nearest counts.
* **States** (``State``): ``NORMAL`` (task motion, green light, no tone) ->
  ``LEVEL1`` (stop, red light, 2000 Hz at 70 dB) -> ``LEVEL2`` (retract along Eq. 6,
  4000 Hz at 80 dB). Escalation is immediate. De-escalation needs the distance above
  the *exit* radius (entry radius + ``hysteresis_m``) for ``dwell_s`` without a break,
  so keypoint noise at a zone boundary cannot make the arm chatter.
* **Fail-safe** (``FAULT``): no pose for more than ``stale_after_s`` (200 ms), or the
  lifter's output invalid, and the arm stops with a distinct reason ("head": one person's
  invalid lift is an invalid frame; "whole_body": see people the camera loses, above). A
  worker who was inside R1 and vanishes from view also holds the arm stopped
  (``worker_lost``, "head").
  The fault clears after ``dwell_s`` of valid frames.
* **Retraction (Eq. 6 and Sec. 3.2.4.4)**, at the end of this module as pure functions:
  where the hand goes when a worker enters level 2, and which way the tool points. Numbers
  and parameters in, a target out; :class:`edge_runtime.robot.loop.RobotLoop` decides when
  to retract and sends what they return. The weights are zone parameters
  (``retract_weight_away_m``, ``retract_weight_path_m``), the limits ``RetractLimits``.
  The zones and the retraction are one module because together they are the one step of
  a camera frame's path that decides what the cell does about the people it sees.
  - **Eq. 6.** ``L = w1 * unit(P_eff - P_head) + w2 * unit(V_ground)``, on the ground
    (``w1 = 0.3 m`` away from the head, ``w2 = 0.2 m`` along the worker's walk; a standing
    worker contributes no second term). The target is ``P_eff + s * L``, with the step ``s``
    (0..1) shortened so that the hand never comes closer than ``min_radius_m`` to the base's
    axis (closer in, the Sawyer cannot hold its tool pointed at the base), then pulled in
    to ``max_radius_m`` (with its tool pointed at the base the Sawyer reaches 0.7-0.8 m).
  - **The fallback.** When the controller refuses Eq. 6's target: straight toward the base's
    axis, as far as Eq. 6's step (``w1 + w2``) but not inside ``min_radius_m``.
  - **Height.** No target below ``min_height_m``.
  - **Tool.** Turned toward the base by at most ``max_turn_deg`` from where it points now
    (a large turn swings the joints, and with them the hand, through the cell); a repeat
    retraction keeps the first one's yaw.
"""
from __future__ import annotations

import enum
import itertools
import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from edge_runtime import config
from edge_runtime.core.memo import Recent
from edge_runtime.core.skeleton import HEAD as HEAD_JOINT
from edge_runtime.core.skeleton import HIP as HIP_JOINT
from edge_runtime.core.skeleton import L_ANKLE, L_HIP, L_SHOULDER, PARENTS, R_ANKLE, R_HIP, R_SHOULDER, SPINE, THORAX

GROUND_AXES = (0, 2)  # x and z: the robot frame's ground plane (y is up)


def ground(v) -> np.ndarray:
    """The ground projection (x, z) of a robot-frame point or vector."""
    v = np.asarray(v, dtype=float)
    # the same copy of the same elements as v[..., GROUND_AXES], a tenth of the cost (no tuple to convert, no
    # ellipsis for the common single vector): a frame asks for a few dozen
    return v[_GROUND_INDEX] if v.ndim == 1 else v[..., _GROUND_INDEX]


_GROUND_INDEX = np.array(GROUND_AXES)


def vector_norm(v) -> float:
    """``float(np.linalg.norm(v))`` of a vector, by its own arithmetic (``sqrt(dot(v, v))``, a correctly rounded sqrt)
    without its dispatch: the retraction's geometry and the loop's waypoint checks take several a frame or tick."""
    v = np.asarray(v, float)
    return math.sqrt(v.dot(v))


# ----------------------------------------------------------------------------------------------
# Configuration

@config.section("tracker")
@dataclass(frozen=True)
class TrackerParams:
    """Head tracking ([tracker] in the box configuration)."""

    window_s: float = config.setting(0.5, config.POSITIVE)
    """Length of the least-squares window for velocity and position (s). Longer rejects
    more noise but reacts later to a change of walking direction."""
    min_samples: int = config.setting(3, ("an integer of at least 2", lambda v: v >= 2))
    """Frames a fit needs; with fewer (a new track) the velocity is taken as zero. At
    5.8 Hz a 0.5 s window holds 3 frames."""
    min_span_s: float = config.setting(0.3, config.NON_NEGATIVE)
    """A fit also needs its frames to span this long (s); a new track's shorter one is taken as
    zero velocity too (0: as before session 22). At 30 Hz three frames span 0.07 s, and a lifted
    head's depth error (0.2-0.6 m, reports/robot/head_error.md) over 0.07 s reads as 2-5 m/s:
    walk-by traffic tracked afresh (entering, or after a jump) was taken as coming and retracted
    from (hard:200 seed 31, hard_003 and hard_153: 2.2 and 4.0 m/s from 3 frames of people walking
    0.1 m/s toward the arm; reports/hrc/s22_walkby/). A person met by a new track is still judged
    at ISO 13855's 1.6 m/s at least (``[zones] iso_human_speed_mps``)."""
    max_speed_mps: float = config.setting(3.0, config.POSITIVE)
    """Head speeds above this (m/s) are clipped: faster than a running worker, so noise. (2.0 m/s,
    the fastest the hard suite's workers walk, cut retractions for walkers tracked too fast from a
    far camera, but a worker whose lift jumped in close was then retracted from too late:
    hard:200, hard_163, 0.05 m.)"""
    jump_m: float = config.setting(1.0, config.POSITIVE)
    """A head that moves further than this between two frames (beyond what
    ``max_speed_mps`` allows) is a new track: the window restarts."""


@config.section("zones")
@dataclass(frozen=True)
class ZoneParams:
    """Hazard-zone sizing and the state machine ([zones] in the box configuration)."""

    sizing: str = "eq45"
    """"eq45": the dissertation's Eq. 4-5; "iso15066": R1 is ISO/TS 15066's S_p."""
    predict_s: float = config.setting(0.5, config.POSITIVE)
    """Prediction horizon t of Eq. 3 (s)."""
    worker_speed_mps: float = config.setting(1.4, config.POSITIVE)
    """V_worker of Eq. 4: the assumed walking speed (m/s; Bohannon & Andrews 2011)."""
    retract_time_s: float = config.setting(2.0, config.POSITIVE)
    """T_retract of Eq. 4: time the arm needs to retract (s). The Sawyer needs about 2 s for a
    retraction that also turns the tool toward the base (measured on the simulated arm from the
    extended posture: half way after 1.5 s, done after 1.9-2.7 s), so R2 = 2.4 m, R1 = 4.4 m;
    the dissertation's 1.0 s (R2 = 1.0 m) let workers reach the tool (reports/hrc/report.md).
    ``python -m firmware_sim hrc`` validates this default (reports/hrc/validated.json)."""
    margin2_m: float = config.setting(0.3, config.NON_NEGATIVE)
    """R_margin2 of Eq. 4 (m)."""
    margin1_m: float = config.setting(2.0, config.NON_NEGATIVE)
    """R_margin1 of Eq. 5 (m)."""
    iso_human_speed_mps: float = config.setting(1.6, config.POSITIVE)
    """ISO/TS 15066 v_h: the human's approach speed (m/s; ISO 13855's walking speed)."""
    iso_robot_speed_mps: float = config.setting(0.6, config.NON_NEGATIVE)
    """v_r: the robot's speed toward the human (m/s; Intera's default Cartesian limit)."""
    iso_reaction_time_s: float = config.setting(0.15, config.NON_NEGATIVE)
    """T_r: camera frame + lifting + link until the stop command lands (s)."""
    iso_stop_time_s: float = config.setting(0.3, config.NON_NEGATIVE)
    """T_s: the robot's stopping time (s)."""
    iso_stop_distance_m: float = config.setting(0.09, config.NON_NEGATIVE)
    """S_s: the robot's stopping distance (m)."""
    iso_intrusion_m: float = config.setting(0.85, config.NON_NEGATIVE)
    """C: intrusion distance (m; ISO 13855's 850 mm reach for coarse body detection, since
    a hand reaches ahead of the tracked head)."""
    iso_sensing_uncertainty_m: float = config.setting(0.1, config.NON_NEGATIVE)
    """Z_d: uncertainty of the worker's position (m; calibrated head error)."""
    iso_robot_uncertainty_m: float = config.setting(0.01, config.NON_NEGATIVE)
    """Z_r: uncertainty of the robot's position (m)."""
    separation: str = config.setting("whole_body", config.one_of("whole_body", "head"))
    """"whole_body": every lifted joint (with a radius per body part) against the arm's links
    (capsules along the Sawyer's chain, from the joint angles the arm reports), with ISO/TS 15066
    speed and separation monitoring; "head": the dissertation's head-to-end-effector zones
    (Eq. 3-5, ``sizing``)."""
    speed_scaling: bool = True
    """whole_body: the arm slows continuously as people come closer (True), or works at full
    speed until it must stop (False: stop-only, for comparison)."""
    body_intrusion_m: float = config.setting(0.1, config.NON_NEGATIVE)
    """whole_body: ISO/TS 15066's C (m). Every joint is tracked and a wrist's radius holds the
    hand, so only what reaches beyond them (fingers, a held tool) is left; 0.85 m is for a
    head-only sensor."""
    body_sensing_uncertainty_m: float = config.setting(0.3, config.NON_NEGATIVE)
    """whole_body: ISO/TS 15066's Z_d (m): the error of a lifted joint in the robot frame (the
    head's after calibration: median 0.29 m, reports/robot/head_error.md)."""
    body_retract_distance_m: float = config.setting(0.6, config.POSITIVE)
    """whole_body: a person who keeps coming (faster than ``approach_speed_mps`` toward the arm)
    makes it retract (Eq. 6) once his separation is below this (m) plus his approach speed times
    ``retract_lead_s``: 1.9 m at 1.4 m/s, 2.4 m at 2.0 m/s, 1.1 m at 0.5 m/s."""
    retract_lead_s: float = config.setting(0.9, config.NON_NEGATIVE)
    """whole_body: how long before he would reach ``body_retract_distance_m`` the retraction
    starts (s). The Sawyer needs about 2 s to finish a retraction but moves its hand half of the
    way in the first second, at up to 0.6 m/s; a slower walker lets the arm work longer."""
    stop_time_scales: bool = True
    """whole_body: T_s in S_p shrinks with the arm's speed (``iso_stop_time_s`` from full speed,
    proportionally less from a slower one: a constant deceleration, T_s(v_r) = 0.3 s x v_r / 0.6 m/s and
    S_s = v_r T_s / 2), so the arm may work slowly closer in (S_p 0.71 m at 10 % speed, 1.31 m at full
    speed, against 1.13-1.31 m with the full-speed T_s throughout). As a model of the arm it is
    conservative: the simulated Sawyer (full joint speed in 0.25 s, its speed override scaling every
    joint's limit) stops doing the cell's task from 0.6 m/s in 0.13 s with no point of it travelling more
    than 0.041 m, from 0.06 m/s in 0.013 s (tests/sim/test_sawyer.py checks it at 10-100 % speed).
    On since session 14. Off before: with the ``rigid`` calibration, workers reached a slow arm in
    development runs (sessions 7 and 9: hard_038, hard_084, hard_075), since a person placed up to metres
    too far (reports/robot/ray_bound_s13.md) let the arm work on closer in. With ``pnp`` (session 13)
    those scenarios clear (0.378, 0.192, 0.606 m), and on development seeds it collided no more than the
    full-speed T_s (seed 15: 2 against 3, the two it shares; seed 13: 0 against 1) while the arm worked
    1.33x as long as stop-only on seed 19 (0.410 against 0.310; full-speed T_s 1.08x):
    reports/hrc/s14_sts/. ``python -m firmware_sim hrc`` validates this default (reports/hrc/validated.json)."""
    reach_retract_m: float = config.setting(0.85, config.NON_NEGATIVE)
    """whole_body: anyone whose separation is below this (m) makes the arm retract (Eq. 6), coming
    or not: he can reach it faster than the camera and the lifter see an arm move (ISO 13855's
    850 mm reach, C), so the arm does not work, even slowly, within his reach. Chosen with
    ``stop_time_scales`` on, where it bounds the band in which the arm works slowly (development
    suite hard:60 seed 5: 0.9 m gave 1.29x stop-only's productive share, 0.75 m 1.36x, both without
    a collision; shipped with it since session 14); with the full-speed T_s S_p at the slowest speed
    is 1.13 m and this only turns a stop into a retraction for someone standing within reach."""
    escape_deg: float = config.setting(180.0, config.within(0, 180))
    """whole_body: someone within ``reach_retract_m`` of an arm whose retraction is done (or that was
    stopped) makes it turn about its base by at most this much (deg; 0: never), to where it is clearest
    of everyone (:func:`plan_escape_turn`; ``[robot_loop] escape_*``): folded in front of him the arm is
    within his reach (an arm reaching 0.75-1.05 m from a pelvis 1.4 m out), beside or behind the base it
    is not. 180: as far as the arm's first joint turns."""
    approach_speed_mps: float = config.setting(0.3, config.NON_NEGATIVE)
    """whole_body: a person "keeps coming" when his head moves toward the end effector faster
    than this (m/s; above the tracker's 0.1 m/s of velocity noise)."""
    min_speed_fraction: float = config.setting(0.1, config.within(0, 1))
    """whole_body with speed scaling: below this share of full speed the arm stops instead
    (a crawl gets no work done and still needs the stop's distance)."""
    speed_step: float = config.setting(0.1, ("a number in (0, 1]", lambda v: 0 < v <= 1))
    """whole_body with speed scaling: speed overrides are multiples of this share of full speed,
    so keypoint noise does not send a new command every frame."""
    hysteresis_m: float = config.setting(0.2, config.NON_NEGATIVE)
    """Exit radii are the entry radii plus this (m)."""
    dwell_s: float = config.setting(1.0, config.NON_NEGATIVE)
    """A lower level is entered only after this long (s) beyond its exit radius, and a
    fault clears only after this long of valid frames."""
    scaled_dwell_s: float = config.setting(0.5, config.NON_NEGATIVE)
    """whole_body with speed scaling: ``dwell_s`` for stepping down a level (after a stop or a
    retraction). It may be shorter: the arm resumes at the speed its separation allows, not at
    full speed as stop-only's does, and speeds up only with ``hysteresis_m`` more separation."""
    stale_after_s: float = config.setting(0.2, ("a number in (0, 1]", lambda v: 0 < v <= 1))
    """No pose for longer than this (s) and the arm stops (reason ``pose_stale``)."""
    lost_hold_s: float = config.setting(3.0, config.NON_NEGATIVE)
    """How long (s) a person stays accounted for after his last valid pose. "head": a worker
    last seen inside R1 who vanishes holds the arm stopped this long of empty frames (reason
    ``worker_lost``). "whole_body": a person hidden, out of view or lifted invalidly is judged
    by his reachable set (``lost_person_speed_mps``) for this long, then forgotten: by then he
    has left the camera's view (which must cover the protective zone, ISO 13855 5), and coming
    back he is a new person, who stops the arm until he is lifted validly."""
    lost_person_speed_mps: float = config.setting(2.0, config.POSITIVE)
    """whole_body: how fast (m/s) a person the camera has lost may have come closer since his last
    valid pose, every joint of him (his reachable set grows this fast, or at his last tracked
    speed if that was faster): ISO 13855's 2.0 m/s for a hand or arm (K = 2000 mm/s, 6.2.3),
    above its 1.6 m/s walking, and the hard suite's running bursts."""
    lost_reach_retracts: bool = True
    """whole_body: a lost person (:meth:`HazardMonitor._lost`) whose reachable set comes within
    ``reach_retract_m``, or would stop the arm (within the protective distance at the slowest speed:
    0.78 m at 2.0 m/s, 0.96 m at a last tracked 3.0 m/s), makes it retract (Eq. 6, away from where
    his rays say he stands or else from where he was last seen) instead of stopping it (False: it
    stopped where it stood, extended, and retracted only once he was seen again within reach; fresh
    hard:200 seed 31, hard_096: a worker lost 1.3 s while walking up, retracted from 0.33 s after
    the stop, bent into the tool still folding in, 0.083 m; with True 0.283 m; reports/hrc/s22_walkby/).
    On since session 22."""
    ray_bound: bool = True
    """whole_body: a person the camera sees but the lifter has not (yet) lifted validly is bounded
    by his keypoints' rays (:func:`ray_separation_m`: his feet on the floor along the ankles' rays,
    or his head within ``ray_head_heights_m`` along its ray; every joint he shows on its own ray
    within ``ray_body_extent_m`` of that), and stops the arm only when that region comes within the
    protective distance (False: he stops it while he is in view, ``person_unseen``). Without a
    usable ankle or head ray he stops it as before."""
    ray_ankle_heights_m: tuple[float, float] = config.setting(
        (0.0, 0.45), ("[low, high] heights (m) with 0 <= low < high", lambda v: len(v) == 2 and 0 <= v[0] < v[1]))
    """whole_body ray bound: the height above the floor (m) of an ankle: a foot on the ground (0.04 x
    body height) or in the air mid-stride or running, and the calibration's floor error."""
    ray_stride_m: float = config.setting(1.0, config.POSITIVE)
    """whole_body ray bound: how far apart (ground, m) the feet may be (a running stride): with one
    ankle seen, the foot on the ground may be the other one."""
    ray_hip_heights_m: tuple[float, float] = config.setting(
        (0.45, 1.15), ("[low, high] heights (m) with 0 < low < high", lambda v: len(v) == 2 and 0 < v[0] < v[1]))
    """whole_body ray bound: the hip joints' (and pelvis's) height above the floor (m): 0.53 x body height
    standing, lower bending or crouching."""
    ray_head_heights_m: tuple[float, float] = config.setting(
        (1.2, 2.05), ("[low, high] heights (m) with 0 < low < high", lambda v: len(v) == 2 and 0 < v[0] < v[1]))
    """whole_body ray bound: the head joint's (the crown's) height above the floor (m): people 1.45-2.0
    m tall, bending toward the work down to 1.2 m."""
    ray_joint_heights_m: tuple[float, float] = config.setting(
        (0.0, 2.6), ("[low, high] heights (m) with 0 <= low < high", lambda v: len(v) == 2 and 0 <= v[0] < v[1]))
    """whole_body ray bound, for a person who shows no ankle, hip, pelvis or head (a wrist, a knee or a
    shoulder at the picture's edge or past an occluder): any joint's height above the floor (m), from the
    floor to a 2.0 m person's wrist raised over his head; every other joint of him is within its bones
    (``JOINT_REACH_M``) of it. Looser than the anchors above, but it bounds someone far out where he
    stopped the arm (``person_unseen``) before."""
    ray_body_extent_m: float = config.setting(1.3, config.POSITIVE)
    """whole_body ray bound: how far (ground distance, m) any joint of a person may be from his foot on
    the ground (or, bounded by the head, from his head): a pelvis over the feet and an arm reaching
    forward (the hard suite's reach: the wrists 0.75-1.05 m in front of the pelvis)."""
    retract_weight_away_m: float = config.setting(0.3, config.NON_NEGATIVE)
    """Eq. 6 weight factor 1: the step away from the head (m)."""
    retract_weight_path_m: float = config.setting(0.2, config.NON_NEGATIVE)
    """Eq. 6 weight factor 2: the step along the worker's walking direction (m)."""
    level1_tone_hz: float = config.setting(2000.0, config.POSITIVE)
    level1_tone_db: float = config.setting(70.0, config.NON_NEGATIVE)
    level2_tone_hz: float = config.setting(4000.0, config.POSITIVE)
    level2_tone_db: float = config.setting(80.0, config.NON_NEGATIVE)

    def __post_init__(self):
        if self.sizing not in ("eq45", "iso15066"):
            raise ValueError(f"sizing: must be eq45 or iso15066, got {self.sizing!r}")
        if self.separation not in ("whole_body", "head"):
            raise ValueError(f"separation: must be whole_body or head, got {self.separation!r}")

    def stop_time_s(self, robot_speed_mps: float) -> float:
        """whole_body: T_s at robot speed v_r (s): ``iso_stop_time_s`` from full speed
        (``iso_robot_speed_mps``), and with ``stop_time_scales`` proportionally less from a lower
        one (a constant deceleration)."""
        if not self.stop_time_scales or self.iso_robot_speed_mps <= 0:
            return self.iso_stop_time_s
        return self.iso_stop_time_s * min(max(robot_speed_mps, 0.0) / self.iso_robot_speed_mps, 1.0)

    def body_protective_distance_m(self, robot_speed_mps: float, human_speed_mps: float | None = None) -> float:
        """whole_body: ISO/TS 15066's S_p (m, 5.5.4.2.3) at robot speed v_r:
        ``v_h (T_r + T_s) + v_r T_r + v_r T_s / 2 + C + Z_d + Z_r``, with the stopping distance
        ``S_s = v_r T_s / 2`` of a constant deceleration, T_s = :meth:`stop_time_s` and v_h at
        least ``iso_human_speed_mps``."""
        v_h = max(self.iso_human_speed_mps, human_speed_mps or 0.0)
        t_s = self.stop_time_s(robot_speed_mps)
        return (v_h * (self.iso_reaction_time_s + t_s) + robot_speed_mps * (self.iso_reaction_time_s + 0.5 * t_s)
                + self.body_intrusion_m + self.body_sensing_uncertainty_m + self.iso_robot_uncertainty_m)

    def allowed_speed_mps(self, separation_m: float, human_speed_mps: float | None = None) -> float:
        """whole_body: the fastest robot speed (m/s, 0..``iso_robot_speed_mps``) whose S_p is
        within ``separation_m`` (S_p is linear in v_r, or quadratic with ``stop_time_scales``: this
        inverts it)."""
        slack = separation_m - self.body_protective_distance_m(0.0, human_speed_mps)
        v_h = max(self.iso_human_speed_mps, human_speed_mps or 0.0)
        if self.stop_time_scales and self.iso_robot_speed_mps > 0:
            k = self.iso_stop_time_s / self.iso_robot_speed_mps      # T_s = k v_r
            a, b = 0.5 * k, v_h * k + self.iso_reaction_time_s          # S_p - S_p(0) = a v^2 + b v
            if slack <= 0:
                v = 0.0
            elif a > 0:
                v = (-b + math.sqrt(b * b + 4 * a * slack)) / (2 * a)
            else:
                v = slack / b if b > 0 else math.inf
        else:
            per_mps = self.iso_reaction_time_s + 0.5 * self.iso_stop_time_s
            v = slack / per_mps if per_mps > 0 else (math.inf if slack >= 0 else 0.0)
        return float(min(max(v, 0.0), self.iso_robot_speed_mps))

    @property
    def r2_m(self) -> float:
        """Level-2 (retract) radius, Eq. 4 (never below R_margin2: a prediction horizon longer
        than the retraction already covers it)."""
        return max(self.worker_speed_mps * (self.retract_time_s - self.predict_s), 0.0) + self.margin2_m

    @property
    def protective_distance_m(self) -> float:
        """ISO/TS 15066 S_p = v_h (T_r + T_s) + v_r T_r + S_s + C + Z_d + Z_r (m)."""
        return (self.iso_human_speed_mps * (self.iso_reaction_time_s + self.iso_stop_time_s)
                + self.iso_robot_speed_mps * self.iso_reaction_time_s + self.iso_stop_distance_m
                + self.iso_intrusion_m + self.iso_sensing_uncertainty_m + self.iso_robot_uncertainty_m)

    @property
    def r1_m(self) -> float:
        """Level-1 (stop and warn) radius: Eq. 5, or S_p (never below R2)."""
        if self.sizing == "iso15066":
            return max(self.protective_distance_m, self.r2_m)
        return self.r2_m + self.margin1_m


class State(enum.IntEnum):
    """The arm's safety state, ordered by how much it restricts the arm."""

    NORMAL = 0
    LEVEL1 = 1
    FAULT = 2
    LEVEL2 = 3


@dataclass(frozen=True)
class Alarm:
    """Light and tone the arm's beacon shows."""

    light: str
    tone_hz: float = 0.0
    tone_db: float = 0.0


# ----------------------------------------------------------------------------------------------
# Tracking (Eq. 3)

@dataclass(frozen=True)
class HeadEstimate:
    """One worker's head: filtered position, velocity and the Eq. 3 prediction (robot frame)."""

    t_s: float
    position_m: np.ndarray
    velocity_mps: np.ndarray
    predicted_m: np.ndarray


def _frozen_new(cls, **fields):
    """``cls(**fields)`` of a frozen dataclass given every field: the same object, without the generated
    ``__init__``'s ``object.__setattr__`` per field (which is all it does): two a person per frame."""
    obj = object.__new__(cls)
    obj.__dict__.update(fields)
    return obj


def _fit_times(t: np.ndarray) -> tuple:
    """The head fit's terms of its window's times ``t`` (from the fit's time, s): (their mean as np.mean takes it, a
    sum then / the count; the centred times; their sum of squares as a float)."""
    t_mean = np.add.reduce(t) / len(t)
    tc = t - t_mean
    return t_mean, tc, float(tc @ tc)


def _time_terms(times: np.ndarray, t_s: float) -> tuple:
    """:func:`_fit_times` of ``times - t_s``, remembered by the times' bytes and ``t_s``'s (every person seen in a
    frame has the same window of times, as a rule: the second one's fit reuses the first one's terms; the bytes
    tell signed zeros apart, as the arithmetic does)."""
    key = (times.tobytes(), float(t_s).hex())
    hit = _TIME_TERMS.get(key)
    if hit is None:
        hit = _TIME_TERMS.put(key, _fit_times(times - t_s))
    return hit


_TIME_TERMS: Recent[tuple] = Recent(4)
""":func:`_time_terms` of the last few windows (read-only use: the fit only reads them)."""

_FIT_ROWS = 64
"""Rows a :class:`HeadTracker` keeps its window's samples in at first (a 0.5 s window at 30 Hz holds 16)."""


class HeadTracker:
    """Least-squares head tracker for one worker (see the module docstring)."""

    def __init__(self, params: TrackerParams = TrackerParams(), predict_s: float = 0.5):
        self.p = params
        self.predict_s = predict_s
        self._t: deque[float] = deque()
        self._x: deque[np.ndarray] = deque()
        self.resets = 0
        # the window's times and heads also as arrays, the last len(self._t) rows up to self._end: the fit reads
        # them as one slice each (np.fromiter of the times and np.array of the heads were a fifth of a fit)
        self._t_rows = np.empty(_FIT_ROWS)
        self._x_rows = np.empty((_FIT_ROWS, 3))
        self._end = 0

    def reset(self) -> None:
        self._t.clear()
        self._x.clear()

    def update(self, t_s: float, head_m) -> HeadEstimate:
        head = np.asarray(head_m, dtype=float)
        if self._t:
            dt = t_s - self._t[-1]
            step = head - self._x[-1]
            # np.linalg.norm of a vector is sqrt(dot(v, v)): the same dot, a correctly rounded sqrt
            jumped = math.sqrt(step.dot(step)) > self.p.jump_m + self.p.max_speed_mps * dt
            if dt <= 0 or dt > self.p.window_s or jumped:  # a gap or a jump: a new track
                self.reset()
                self.resets += 1
        self._t.append(t_s)
        self._x.append(head)
        while t_s - self._t[0] > self.p.window_s:
            self._t.popleft()
            self._x.popleft()
        self._keep_rows(t_s, head)
        return self._estimate(t_s)

    def _keep_rows(self, t_s: float, head: np.ndarray) -> None:
        """The newest sample into the arrays' rows, after the window's others (the last ``len(self._t) - 1`` rows
        written: a reset or a trim only drops the oldest); when the rows run out, the window's others are
        copied to the front of new ones. A head that is not 3 numbers stops the rows for good (the fit then
        reads the deques, as it did before the rows)."""
        if self._end < 0:
            return
        if head.shape != (3,):
            self._end = -1
            return
        n, end = len(self._t), self._end
        if end == len(self._t_rows) or n > len(self._t_rows):
            size = max(len(self._t_rows), 2 * n)
            t_rows, x_rows = np.empty(size), np.empty((size, 3))
            t_rows[:n - 1], x_rows[:n - 1] = self._t_rows[end - n + 1:end], self._x_rows[end - n + 1:end]
            self._t_rows, self._x_rows, end = t_rows, x_rows, n - 1
        self._t_rows[end] = t_s
        self._x_rows[end] = head
        self._end = end + 1

    def _estimate(self, t_s: float) -> HeadEstimate:
        if len(self._t) < self.p.min_samples or self._t[-1] - self._t[0] < self.p.min_span_s:
            pos, vel = self._x[-1], np.zeros(3)
        else:
            n, end = len(self._t), self._end
            if end >= 0:  # the window's rows (the same doubles as the deques hold, a C-contiguous slice of each)
                t_mean, tc, tt = _time_terms(self._t_rows[end - n:end], t_s)
                x = self._x_rows[end - n:end]
            else:
                t, x = np.fromiter(self._t, float) - t_s, np.array(list(self._x))  # (n, 3): np.stack's values
                t_mean, tc, tt = _fit_times(t)
            # each mean once (the fit used both twice), as np.mean does it: a sum, then / the count
            x_mean = np.add.reduce(x, axis=0) / len(x)
            vel = tc @ (x - x_mean) / tt
            pos = x_mean - t_mean * vel  # the fitted line at t_s
            speed = math.sqrt(vel.dot(vel))  # np.linalg.norm's own arithmetic for a vector
            if speed > self.p.max_speed_mps:
                vel = vel * (self.p.max_speed_mps / speed)
        return _frozen_new(HeadEstimate, t_s=t_s, position_m=pos, velocity_mps=vel, predicted_m=pos + self.predict_s * vel)


def distance_to_effector(est: HeadEstimate, effector_m) -> float:
    """Ground-projected distance from the end effector to the nearer of the predicted and
    the current head (m)."""
    e = ground(effector_m)
    return min(vector_norm(ground(est.predicted_m) - e), vector_norm(ground(est.position_m) - e))


# ----------------------------------------------------------------------------------------------
# The state machine: head zones (Eq. 4-5) or whole-body speed and separation monitoring

@dataclass
class Decision:
    """What the arm should do now, and why."""

    state: State
    reason: str
    distance_m: float = math.inf
    """The nearest worker's distance: ground head-to-effector (``separation = "head"``) or the
    whole-body separation (m)."""
    worker: int | None = None
    head: HeadEstimate | None = None
    changed: bool = False
    speed_scale: float = 1.0
    """Share of full speed the arm may work at in NORMAL (whole-body speed and separation
    monitoring; 1.0 otherwise)."""
    coming: bool = True
    """whole_body: someone keeps coming at the arm where it is now (the retraction rule:
    approaching faster than ``approach_speed_mps`` within ``body_retract_distance_m`` + his
    approach speed x ``retract_lead_s``), not just standing within reach or passing it: only then
    does a repeat retraction make sense ("head": always True)."""


def alarms(params: ZoneParams) -> dict[State, Alarm]:
    """The beacon for each state (Fig. 3.5): green, red + 2000 Hz/70 dB, red + 4000 Hz/80 dB;
    a fault shows yellow without a tone."""
    return {
        State.NORMAL: Alarm("green"),
        State.LEVEL1: Alarm("red", params.level1_tone_hz, params.level1_tone_db),
        State.LEVEL2: Alarm("red", params.level2_tone_hz, params.level2_tone_db),
        State.FAULT: Alarm("yellow"),
    }


@dataclass
class _Hold:
    """Time since a condition stopped holding (for dwell timing)."""

    since_s: float | None = None

    def clear_for(self, t_s: float, clear: bool) -> float:
        if not clear:
            self.since_s = None
            return 0.0
        if self.since_s is None:
            self.since_s = t_s
        return t_s - self.since_s


@dataclass(frozen=True)
class _Seen:
    """A person's last valid pose (robot frame) and his tracked ground speed then."""

    t_s: float
    person_m: np.ndarray
    speed_mps: float
    spheres: tuple
    """:func:`body_spheres` of ``person_m`` (centres, radii; read-only), made once per frame: the lost-person
    check, the escape plan and the loop's backfire check use them at every frame and tick."""
    clear_of: tuple | None = None
    """(capsules, separation m): his separation now from the arm's capsules his frame was judged with (read-only
    ones, :func:`arm_capsules`'s, by identity), as :func:`separation_m` gives it; None when not known so."""
    also_clear_of: tuple | None = None
    """The same for the other capsules his frame was asked about (:meth:`HazardMonitor.observe`'s
    ``also_capsules``: where the retraction under way began), or None."""

    def known_separation_m(self, capsules) -> float | None:
        """His separation now from ``capsules`` when his frame measured it (:attr:`clear_of`,
        :attr:`also_clear_of`, by the capsules' identity), else None."""
        for known in (self.clear_of, self.also_clear_of):
            if known is not None and known[0] is capsules:
                return known[1]
        return None


def _least(values: list[float]) -> float:
    """``float(np.min(values))`` of a few floats: the least, or NaN if any is NaN (numpy's minimum propagates it)."""
    least = values[0]
    for v in values[1:]:
        if v < least or v != v:
            least = v
    return least


def _head_of(person_m: np.ndarray) -> np.ndarray:
    """A person's head: his body's head joint, or the head alone when that is all he is given as."""
    return person_m if person_m.shape == (3,) else person_m[HEAD_JOINT]


@dataclass
class HazardMonitor:
    """The zone state machine over every tracked worker (see the module docstring).

    Call ``observe(t_s, people, effector_m, arm_q_rad)`` once per pose frame, with ``people``
    a mapping worker id -> his skeleton (17, 3) or head (3,) (robot frame, metres) for the
    workers seen in it (empty: nobody seen) and ``arm_q_rad`` the arm's reported joint angles
    (None: not known yet, the end effector stands for the arm), ``invalid(t_s, reason)`` for a
    frame the lifter marked invalid, and ``check(t_s)`` at every control cycle (staleness)."""

    zones: ZoneParams = field(default_factory=ZoneParams)
    tracker: TrackerParams = field(default_factory=TrackerParams)

    def __post_init__(self):
        self.state = State.FAULT
        self.reason = "no_pose_yet"
        self.level = State.NORMAL  # the zone level, before faults
        self._alarms = alarms(self.zones)
        self._trackers: dict[int, HeadTracker] = {}
        self.estimates: dict[int, HeadEstimate] = {}
        """Each worker's head estimate of the last valid frame (for the loop's log)."""
        self._last_pose_s: float | None = None
        self._fault: str | None = "no_pose_yet"  # nothing is known until poses have flowed for dwell_s
        self._fault_clear = _Hold()
        self._below = {State.LEVEL2: _Hold(), State.LEVEL1: _Hold()}
        self._lost_since_s: float | None = None
        self._scale = 1.0
        self._seen: dict = {}
        """whole_body: each person's last valid pose (``_Seen``), kept ``lost_hold_s`` after it."""
        self._unseen: str | None = None  # this frame: a person lifted invalidly and never validly
        self._lost_stop: list = []  # this frame: the lost people whose reachable set stops the arm
        self._unlifted_stop: list = []  # this frame: the people never lifted whose rays' bound stops the arm
        self._bounded: dict = {}
        """whole_body: each never-lifted person's last ray bound (time s, separation m, his point nearest the arm)."""
        self._coming = False  # this frame: someone keeps coming at the arm (the retraction rule)
        self.last = Decision(self.state, self.reason)
        self.stale_events = 0
        """How often the pose stream went stale."""
        self.bounds_refused = 0
        """Lost people's ray bounds that contradicted their reachable set and were not heard (:meth:`_lost`)."""

    # -- inputs ---------------------------------------------------------------------------

    def observe(self, t_s: float, people: dict[int, np.ndarray], effector_m, arm_q_rad=None,
                unseen: dict | None = None, rays: dict | None = None, also_capsules=None) -> Decision:
        """A valid pose frame: update the trackers and the zone level. ``unseen``: id -> reason for
        the people the camera reports in this frame but the lifter could not lift (whole_body: each
        is judged from his last valid pose, :meth:`_lost`, and by his keypoints' rays, ``rays``: id ->
        :class:`PersonRays`, :meth:`_unlifted`; "head": the frame is invalid). ``also_capsules``
        (whole_body, read-only capsules such as :func:`arm_capsules`' or None): another posture of the
        arm whose separation from everyone seen the caller will ask for (:meth:`people_separations_m`:
        the loop's backfire check, where the retraction under way began), measured in the same pass as
        the frame's own (the same numbers as a pass of its own)."""
        unseen = dict(unseen or {})
        if unseen and self.zones.separation == "head":
            wid, why = next(iter(unseen.items()))
            return self.invalid(t_s, f"person {wid}: {why}")
        self._last_pose_s = t_s
        keep = people if self.zones.separation == "head" else self._seen.keys() | people.keys()
        for wid in [w for w in self._trackers if w not in keep]:  # a lost person's tracker bridges his gap
            del self._trackers[wid]
        ests = {}
        for wid, person in people.items():
            person = np.asarray(person, float)
            head = _head_of(person)
            tracker = self._trackers.get(wid)
            if tracker is None:  # (not setdefault: that made a tracker for every person at every frame)
                tracker = self._trackers[wid] = HeadTracker(self.tracker, self.zones.predict_s)
            ests[wid] = tracker.update(t_s, head)
        self.estimates = ests  # each person's head estimate, for the per-person log
        if self.zones.separation == "head":
            entry, exit_r, nearest = self._head_zones(ests, effector_m)
            d_exit = nearest[0]
        else:
            entry, exit_r, nearest, d_exit = self._speed_and_separation(t_s, people, ests, effector_m, arm_q_rad,
                                                                        unseen, rays or {}, also_capsules)
        self._update_level(t_s, entry, d_exit, nearest[2], exit_r)
        if self._fault is not None and self._fault_clear.clear_for(t_s, True) >= self.zones.dwell_s:
            self._fault = None
        return self._decide(t_s, *nearest)

    def _head_zones(self, ests: dict[int, HeadEstimate], effector_m):
        """The dissertation's zones: the nearest predicted or current head to the end effector
        (ground distance) against R1 and R2. (entry level, exit radii, nearest (d, id, head))."""
        z = self.zones
        nearest = (math.inf, None, None)
        for wid, est in ests.items():
            d = distance_to_effector(est, effector_m)
            if d < nearest[0]:
                nearest = (d, wid, est)
        d = nearest[0]
        entry = State.LEVEL2 if d <= z.r2_m else State.LEVEL1 if d <= z.r1_m else State.NORMAL
        self._scale = 1.0
        return entry, {State.LEVEL2: z.r2_m + z.hysteresis_m, State.LEVEL1: z.r1_m + z.hysteresis_m}, nearest

    def _speed_and_separation(self, t_s: float, people, ests: dict[int, HeadEstimate], effector_m, arm_q_rad,
                              unseen: dict, rays: dict, also_capsules=None):
        """Whole-body speed and separation monitoring (ISO/TS 15066). Per person: the smallest
        separation of his body now and predicted ``predict_s`` ahead (every joint moved with his
        head's velocity) from the arm's capsules; the robot speed that separation allows; and
        whether he keeps coming. LEVEL2 (retract) for one closer than ``body_retract_distance_m``
        who keeps coming, LEVEL1 (stop) below the protective distance at the slowest useful
        speed (stop-only: at full speed), else NORMAL at the speed the nearest one allows. The
        people seen before but not now count by their reachable set (:meth:`_lost`).
        (entry level, exit radii, nearest seen (d, id, head), the separation the exit is judged on:
        the smallest, lost people's included). The nearest is a person seen in this frame: a
        retraction goes away from someone whose head is known."""
        z = self.zones
        caps = arm_capsules(arm_q_rad) if arm_q_rad is not None else effector_capsule(effector_m)
        eff_g = ground(effector_m)
        v_full = z.iso_robot_speed_mps
        v_stop = z.min_speed_fraction * v_full if z.speed_scaling else v_full
        entry, nearest = State.NORMAL, (math.inf, None, None)
        self._coming = False
        worst = (v_full, None, math.inf)  # (allowed speed, human speed, separation) of the most restrictive
        persons = [np.asarray(people[wid], float) for wid in ests]
        # each head velocity on the ground as three floats (the same doubles an array of them holds)
        bodies = {wid: (person_m, centres, radii, (float(est.velocity_mps[0]), 0.0, float(est.velocity_mps[2])))
                  for (wid, est), person_m, (centres, radii) in zip(ests.items(), persons, body_spheres_of(persons))}
        # everyone now and predict_s ahead in one call: numpy's per-call overhead, not the arithmetic, is the cost
        also = also_capsules if also_capsules is not caps else None
        seps, also_seps = (_separations_m([b[1:] for b in bodies.values()], (0.0, z.predict_s), caps, also)
                           if bodies else ([], None))
        for k, ((wid, est), sep) in enumerate(zip(ests.items(), seps)):
            person_m, centres, radii, velocity = bodies[wid]
            v_g = ground(est.velocity_mps)
            speed = math.sqrt(v_g.dot(v_g))  # np.linalg.norm's own arithmetic for a vector (below too)
            toward = eff_g - ground(est.position_m)
            # ndarray.dot of two vectors is the dot `@` calls (numpy's DOUBLE_dot), without the ufunc machinery
            approach = float(v_g.dot(toward)) / max(math.sqrt(toward.dot(toward)), 1e-9)
            sep_s = sep.tolist()
            d = _least(sep_s)
            # moved by 0 s his spheres are where they are (c + 0 v is c, but for the sign of a zero, which no
            # clearance keeps): sep[0] is separation_m's, to the bit, while his velocity is finite
            unmoved = math.isfinite(velocity[0]) and math.isfinite(velocity[2])
            now = (caps, sep_s[0]) if unmoved else None
            also_now = (also, also_seps[k]) if unmoved and also_seps is not None else None
            self._seen[wid] = _frozen_new(_Seen, t_s=t_s, person_m=person_m, speed_mps=speed, spheres=(centres, radii),
                                          clear_of=now, also_clear_of=also_now)
            allowed = z.allowed_speed_mps(d, speed)
            # he keeps coming: toward the arm faster than approach_speed_mps, and within the distance his
            # approach speed covers over the retraction's lead. (His path over the lead instead, so that a
            # walker passing the cell is not retracted from, let a passer reach the arm in hard:200 seed 1,
            # hard_093, 0.035 m: taken back.)
            coming = approach > z.approach_speed_mps and d <= z.body_retract_distance_m + approach * z.retract_lead_s
            self._coming |= coming
            if d <= z.reach_retract_m or coming:
                level = State.LEVEL2
            elif allowed < v_stop - 1e-9:
                level = State.LEVEL1
            else:
                level = State.NORMAL
            entry = max(entry, level)
            if d < nearest[0]:
                nearest = (d, wid, est)
            if allowed < worst[0] or worst[1] is None:
                worst = (allowed, speed, d)
        bounds = {w: ray_separation_m(rays[w], caps, z) for w in unseen if z.ray_bound and w in rays}
        self._lost_stop, self._unlifted_stop = [], []
        # a lost person whose reachable set would stop the arm makes it retract instead (lost_reach_retracts)
        for stops, judged, stop_retracts in (
                (self._lost_stop, self._lost(t_s, set(ests), caps, bounds), z.lost_reach_retracts),
                (self._unlifted_stop, self._unlifted(t_s, unseen, bounds, set(ests)), False)):
            for wid, d, speed, point in judged:
                allowed = z.allowed_speed_mps(d, speed)
                if point is not None and (d <= z.reach_retract_m or (stop_retracts and allowed < v_stop - 1e-9)):
                    # within reach by what is known of him: retract, away from where his rays say he stands (or,
                    # lost with no rays, where he was last seen)
                    entry = State.LEVEL2
                    if d < nearest[0]:
                        nearest = (d, wid, HeadEstimate(t_s, point, np.zeros(3), point))
                elif allowed < v_stop - 1e-9:
                    entry = max(entry, State.LEVEL1)
                    stops.append(wid)
                if allowed < worst[0] or worst[1] is None:
                    worst = (allowed, speed, d)
        human_speed = worst[1]
        exit_r = {State.LEVEL2: max(z.body_retract_distance_m, z.reach_retract_m) + z.hysteresis_m,
                  State.LEVEL1: z.body_protective_distance_m(v_stop, human_speed) + z.hysteresis_m}
        # nobody seen or accounted for (every lost person forgotten after lost_hold_s): full speed
        self._scale = 1.0 if worst[1] is None else self._speed_scale(worst[2], human_speed)
        return entry, exit_r, nearest, min(nearest[0], worst[2])

    def _unlifted(self, t_s: float, unseen: dict, bounds: dict, lifted_now: set):
        """(id, worst-case separation m, his speed m/s, where his rays say he stands or None) of
        every person in view whom the lifter has
        never lifted validly but whose keypoints' rays bound him (``bounds``: id -> the
        :func:`ray_separation_m` of this frame, or None); such a person whose rays bound nothing
        (no usable ankle or head ray) stops the arm (``person_unseen``), unless his rays bounded
        him within the last ``lost_hold_s``: then, as for a lost person, that bound shrinks by his
        speed (``lost_person_speed_mps``) and the arm's full speed times the time since, and so
        does it while he is out of view, until he is forgotten."""
        z = self.zones
        speed = z.lost_person_speed_mps
        self._unseen = None
        out = []
        for wid, why in unseen.items():
            if wid in self._seen:
                continue  # lifted validly before: judged by his reachable set (_lost)
            bound = bounds.get(wid)
            if bound is not None:
                self._bounded[wid] = (t_s, *bound)
            elif wid not in self._bounded and self._unseen is None:
                self._unseen = f"person {wid}: {why}"
        for wid, (t_b, d_b, point) in list(self._bounded.items()):
            age = t_s - t_b
            if wid in lifted_now or wid in self._seen or age > z.lost_hold_s or age < 0:
                del self._bounded[wid]
                continue
            out.append((wid, d_b - (speed + z.iso_robot_speed_mps) * age, speed, point if age == 0 else None))
        return out

    def _lost(self, t_s: float, seen_now: set, caps, bounds: dict | None = None):
        """(id, worst-case separation m, his speed m/s, where his rays say he stands or None) of
        every person seen validly before but not in this frame (hidden, out of view, or lifted invalidly), for ``lost_hold_s`` after his last
        valid pose, then forgotten. His reachable set: his last valid body, every joint come
        ``v (t - t_seen)`` closer, v = ``lost_person_speed_mps`` or his last tracked speed if faster
        (ISO 13855's approach speeds): nothing the camera lost is assumed to have stood still, and
        once that set is within the protective distance the arm stops (``person_lost``). In view
        with rays that bound him (``bounds``: id -> :func:`ray_separation_m`), the larger of the
        two bounds counts, but only a ray bound his track allows: he cannot be further than his last
        body's separation plus ``v (t - t_seen)`` either. A bound beyond that contradicts his track
        (a keypoint on the wrong person or thing, a ray through a miscalibrated camera: hard:200
        seed 1 had bounds of 11 m for a worker 1.25 m from the arm) and is not heard
        (``bounds_refused``): the reachable set alone counts."""
        z = self.zones
        bounds = bounds or {}
        out = []
        for wid, seen in list(self._seen.items()):
            if wid in seen_now:
                continue
            age = t_s - seen.t_s
            if age > z.lost_hold_s or age < 0:
                del self._seen[wid]
                self._trackers.pop(wid, None)
                continue
            speed = max(z.lost_person_speed_mps, seen.speed_mps)
            last = separation_m(*seen.spheres, caps)
            d, point = last - speed * age, (_head_of(seen.person_m) if z.lost_reach_retracts else None)
            bound = bounds.get(wid)
            if bound is not None:  # in view: where his rays say he stands (retract away from it)
                if bound[0] <= last + speed * age:
                    d, point = max(d, bound[0]), (point if bound[1] is None else bound[1])
                else:
                    self.bounds_refused += 1
            out.append((wid, d, speed, point))
        return out

    def _speed_scale(self, d: float, human_speed_mps: float | None) -> float:
        """The share of full speed at separation ``d``: down to a multiple of ``speed_step`` at
        once, up again only when ``hysteresis_m`` more separation allows it (no chatter)."""
        z = self.zones
        if not z.speed_scaling:
            return 1.0
        step, full = z.speed_step, z.iso_robot_speed_mps

        def quantised(sep: float) -> float:
            return min(1.0, math.floor(z.allowed_speed_mps(sep, human_speed_mps) / full / step + 1e-9) * step)

        now = quantised(d)
        return now if now <= self._scale else max(self._scale, quantised(d - z.hysteresis_m))

    def bodies(self) -> list[np.ndarray]:
        """whole_body: every person accounted for, at his last valid body (robot frame)."""
        return [seen.person_m for seen in self._seen.values()]

    def people_spheres(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """whole_body: :func:`body_spheres` of each of :meth:`bodies` (read-only arrays, made once per frame)."""
        return [seen.spheres for seen in self._seen.values()]

    def people_separations_m(self, capsules) -> np.ndarray:
        """whole_body: :func:`people_separations_m` of :meth:`people_spheres` (at least one) from ``capsules``;
        without a clearance when they are the capsules everyone's last frame judged him against or was asked
        about (``also_capsules``: the loop's backfire check asks for the arm where it is, which it was at the frame,
        and where the retraction began: that frame's separations)."""
        seen = list(self._seen.values())
        known = [s.known_separation_m(capsules) for s in seen]
        if None not in known:
            return np.array(known, float)
        return people_separations_m([s.spheres for s in seen], capsules)

    def escape_people(self, sweep_m: float) -> list[tuple[np.ndarray, np.ndarray]] | None:
        """whole_body: everyone accounted for at the last pose frame, as body spheres (centres, radii;
        robot frame) for planning an escape turn (:func:`plan_escape_turn`): a person seen then at his
        body; one lost since at his last valid body with every radius grown by how far he can have come
        since (his speed or ``lost_person_speed_mps``, as :meth:`_lost` judges him: he is not assumed to
        stand still). None while someone known only by his keypoints' rays is within ``reach_retract_m``
        plus ``sweep_m`` (how far the turn can carry any point of the arm): the rays put him anywhere
        along a metre or more of them, which no turn can be shown to clear in a frame's time
        (:func:`ray_separation_m` takes milliseconds a call). (Before session 12 the turn's sweep was
        left out: its review had a person bounded at 0.88 m swept to 0.66 m by a planned turn.)"""
        z, t = self.zones, self._last_pose_s
        if t is None:
            return []
        for t_b, d_b, _ in self._bounded.values():
            if d_b - (z.lost_person_speed_mps + z.iso_robot_speed_mps) * (t - t_b) <= z.reach_retract_m + sweep_m:
                return None
        out = []
        for seen in self._seen.values():
            centres, radii = seen.spheres
            grown_m = max(z.lost_person_speed_mps, seen.speed_mps) * max(t - seen.t_s, 0.0)
            out.append((centres, radii + grown_m))
        return out

    def escape_separations_m(self, capsules) -> np.ndarray | None:
        """whole_body: everyone's separation now (P,) from ``capsules``, as :func:`plan_escape_turn` measures it of
        :meth:`escape_people`, when the last pose frame measured it (every one seen then, at a finite speed: his
        radii not grown, :attr:`_Seen.clear_of`), else None: the escape plan then need not measure it again."""
        t = self._last_pose_s
        known = [s.known_separation_m(capsules) if s.t_s == t and math.isfinite(s.speed_mps) else None
                 for s in self._seen.values()]
        return np.array(known, float) if known and None not in known else None

    def invalid(self, t_s: float, reason: str) -> Decision:
        """A frame the lifter (or the input) marked invalid: stop."""
        self._last_pose_s = t_s
        self._set_fault(t_s, f"pose_invalid: {reason}" if reason else "pose_invalid")
        return self._decide(t_s)

    def check(self, t_s: float) -> Decision:
        """Staleness check, at every control cycle."""
        if self._last_pose_s is None:
            self._set_fault(t_s, "no_pose_yet")
            return self._decide(t_s)
        if t_s - self._last_pose_s > self.zones.stale_after_s:
            self._set_fault(t_s, "pose_stale")
            return self._decide(t_s)
        return self.last

    # -- internals ------------------------------------------------------------------------

    def _set_fault(self, t_s: float, reason: str) -> None:
        if reason == "pose_stale" and self._fault != reason:
            self.stale_events += 1
        self._fault = reason
        self._fault_clear.clear_for(t_s, False)
        self._trackers.clear()  # velocities across a gap are meaningless

    def _update_level(self, t_s: float, entry: State, d: float, est, exit_r: dict) -> None:
        z = self.zones
        if z.separation == "head" and est is None and self.level >= State.LEVEL1:
            # nobody seen: a worker last seen inside R1 may be hidden, not gone
            if self._lost_since_s is None:
                self._lost_since_s = t_s
            if t_s - self._lost_since_s < z.lost_hold_s:
                entry = max(entry, State.LEVEL1)
        else:
            self._lost_since_s = None
        if entry >= self.level:
            self.level = entry
            for hold in self._below.values():
                hold.clear_for(t_s, False)
            return
        # de-escalate one level at a time, each after dwell_s beyond its exit radius. "head": the
        # dissertation's steps, a dwell each (Fig. 3.5); whole_body: each level's dwell counts from
        # when the separation got beyond its exit radius, so a person who has left both the retract
        # and the stop distance for dwell_s lets the arm work at once after its retraction (the same
        # evidence, not a second wait: resuming promptly is what SSM is for, ISO/TS 15066 5.5.4.2)
        together = z.separation == "whole_body"
        beyond = {lvl: hold.clear_for(t_s, d > exit_r[lvl]) for lvl, hold in self._below.items()} if together else {}
        dwell_s = z.scaled_dwell_s if together and z.speed_scaling else z.dwell_s
        while self.level > entry:
            level = State.LEVEL2 if self.level == State.LEVEL2 else State.LEVEL1
            if (beyond[level] if together else self._below[level].clear_for(t_s, d > exit_r[level])) < dwell_s:
                break
            self.level = State.LEVEL1 if level == State.LEVEL2 else State.NORMAL
            if not together:
                self._below[level].clear_for(t_s, False)

    def _decide(self, t_s: float, d: float = math.inf, wid=None, est=None) -> Decision:
        if self._fault is not None and self.level != State.LEVEL2:
            state, reason = State.FAULT, self._fault
        elif self._unseen is not None and self.level != State.LEVEL2:
            state, reason = State.FAULT, f"person_unseen: {self._unseen}"
        elif self.level == State.NORMAL:
            state, reason = State.NORMAL, "clear"
        elif self._lost_since_s is not None:
            state, reason = self.level, "worker_lost"
        elif self._lost_stop and self.level == State.LEVEL1:
            state, reason = self.level, f"person_lost: {', '.join(str(w) for w in self._lost_stop)}"
        elif self._unlifted_stop and self.level == State.LEVEL1:
            state, reason = self.level, f"person_unlifted: {', '.join(str(w) for w in self._unlifted_stop)}"
        else:
            state, reason = self.level, ("level2_retract" if self.level == State.LEVEL2 else "level1_stop")
        if self._fault is not None and state == State.LEVEL2:
            reason = f"level2_retract ({self._fault})"
        scale = self._scale if state == State.NORMAL else 1.0
        dec = Decision(state, reason, d, wid, est, changed=(state, reason) != (self.last.state, self.last.reason),
                       speed_scale=scale, coming=self._coming or self.zones.separation == "head")
        self.state, self.reason, self.last = state, reason, dec
        return dec

    def alarm(self, state: State) -> Alarm:
        return self._alarms[state]


# ----------------------------------------------------------------------------------------------
# Whole-body separation: the arm's links as capsules, the people's joints as spheres

SAWYER_JOINT_ORIGINS: tuple[tuple[tuple[float, float, float], tuple[float, float, float]], ...] = (
    # (xyz m, rpy rad) of right_j0 .. right_j6 in their parent link, then the fixed hand: the
    # public Sawyer description (sawyer_description/urdf/sawyer_base.urdf.xacro). The runtime
    # carries its own copy because the box never installs the simulator;
    # tests/robot/test_hazard.py pins it to firmware_sim/robot/sawyer.py's kinematics.
    ((0.0, 0.0, 0.08), (0.0, 0.0, 0.0)),
    ((0.081, 0.05, 0.237), (-math.pi / 2, math.pi / 2, 0.0)),
    ((0.0, -0.14, 0.1425), (math.pi / 2, 0.0, 0.0)),
    ((0.0, -0.042, 0.26), (-math.pi / 2, 0.0, 0.0)),
    ((0.0, -0.125, -0.1265), (math.pi / 2, 0.0, 0.0)),
    ((0.0, 0.031, 0.275), (-math.pi / 2, 0.0, 0.0)),
    ((0.0, -0.11, 0.1053), (-math.pi / 2, -math.radians(10.0), math.pi)),
    ((0.0, 0.0, 0.0245), (0.0, 0.0, math.pi / 2)),
)
ARM_LINK_RADII_M = (0.08, 0.07, 0.06, 0.06, 0.055, 0.05, 0.045, 0.035, 0.035)
"""Capsule radius (m) of each segment base-j0, j0-j1, ..., j6-hand, hand-tool tip: the
description's collision geometry, as thick as the simulator's collision spheres."""
TOOL_LENGTH_M = 0.10
"""The gripper or tool beyond the hand, along the tool axis (m)."""
_URDF_TO_ROBOT = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
"""Robot frame (x, y, z) = URDF base frame (y, z, x) (edge_runtime/core/skeleton.py)."""

BODY_RADII_M = np.array([0.15, 0.10, 0.08, 0.08, 0.10, 0.08, 0.08,   # pelvis, right/left hip, knee, ankle
                         0.15, 0.15, 0.08, 0.12,                     # spine, thorax, neck, head
                         0.08, 0.06, 0.12, 0.08, 0.06, 0.12])        # shoulders, elbows, wrists
"""Radius (m) of the body around each H36M joint: the trunk's half depth, a limb's half
thickness, the head, and at the wrist the hand beyond it (10-12 cm)."""
LIMBS = ((1, 2), (2, 3), (4, 5), (5, 6), (11, 12), (12, 13), (14, 15), (15, 16))
"""Thigh, shank (right, left), upper arm, forearm (left, right): their midpoints are checked
too, so an arm link passing between two joints of a 0.4 m bone is not missed."""


def _rpy_transform(xyz, rpy) -> np.ndarray:
    """4x4 transform of a URDF origin: translation, then Rz(yaw) Ry(pitch) Rx(roll)."""
    (cr, sr), (cp, sp), (cy, sy) = ((math.cos(a), math.sin(a)) for a in rpy)
    t = np.eye(4)
    t[:3, :3] = [[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                 [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                 [-sp, cp * sr, cp * cr]]
    t[:3, 3] = xyz
    return t


_ORIGIN_TRANSFORMS = tuple(_rpy_transform(xyz, rpy) for xyz, rpy in SAWYER_JOINT_ORIGINS)
_EYE4 = np.eye(4)
"""np.eye(4), made once (read-only: :func:`arm_points_m` copies it where it writes)."""
_EYE4.setflags(write=False)


def arm_points_m(q_rad) -> np.ndarray:
    """(10, 3) robot-frame points along the arm for joint angles ``q_rad`` (7,): the base top,
    joints j0..j6, the hand and the tool tip."""
    q = np.asarray(q_rad, float).reshape(7)
    qs = q.tolist()  # the same doubles, for math.cos and math.sin without numpy's scalars
    t = _EYE4  # only read (each product is a new matrix)
    pts = np.zeros((10, 3))
    turn = _EYE4.copy()  # the joint's turn about its z axis, filled in per joint (the same matrices, built faster)
    # ndarray.dot of two C-contiguous 4 x 4 float64 matrices is the BLAS dgemm call `@` makes, without the ufunc
    # machinery's microseconds (tests/robot/test_frame_cost_s16.py pins the points to the `@` form's, to the bit)
    for k, origin in enumerate(_ORIGIN_TRANSFORMS):
        t = t.dot(origin)
        if k < 7:  # every arm joint turns about its own z axis
            c, s_ = math.cos(qs[k]), math.sin(qs[k])
            turn[0, 0], turn[0, 1], turn[1, 0], turn[1, 1] = c, -s_, s_, c
            t = t.dot(turn)
        pts[k + 1] = t[:3, 3]
    pts[9] = t[:3, 3] + TOOL_LENGTH_M * t[:3, 2]
    return pts @ _URDF_TO_ROBOT.T


def arm_capsules(q_rad) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The arm as capsules: segment starts (9, 3), ends (9, 3) and radii (9,), robot frame (m); read-only
    arrays, the same ones for the same joint angles (the arm reports them at 100 Hz, and a frame, the ticks
    between frames and the retraction's backfire check ask for the same few: :data:`_CAPSULE_CACHE`)."""
    q = np.asarray(q_rad, float).reshape(7)
    key = q.tobytes()
    caps = _CAPSULE_CACHE.get(key)
    if caps is None:
        p = arm_points_m(q)
        p.setflags(write=False)
        caps = _CAPSULE_CACHE.put(key, (p[:-1], p[1:], _ARM_LINK_RADII))
    return caps


_CAPSULE_CACHE: Recent[tuple[np.ndarray, np.ndarray, np.ndarray]] = Recent(8)
""":func:`arm_capsules` by the joint angles' bytes (the arm's now, where its retraction began, ...)."""
_ARM_LINK_RADII = np.asarray(ARM_LINK_RADII_M, float)
_ARM_LINK_RADII.setflags(write=False)


def _frozen(arrays: tuple) -> tuple:
    """``arrays`` made read-only (they are kept and shared: nobody may change them in place)."""
    for a in arrays:
        a.setflags(write=False)
    return arrays


def effector_capsule(effector_m) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The end effector alone, as a tool-sized sphere: what is known of the arm before it has
    reported its joint angles."""
    e = np.asarray(effector_m, float).reshape(1, 3)
    return e, e, np.array([TOOL_LENGTH_M])


def body_spheres(person_m) -> tuple[np.ndarray, np.ndarray]:
    """Centres (N, 3) and radii (N,) covering a person: the 17 joints and the limb midpoints;
    a lone head position (3,) is one head-sized sphere. A skeleton with joints not known (NaN:
    the lifter's ``missing`` ones) is covered by :func:`_bounded_spheres` instead."""
    p = np.asarray(person_m, float)
    if p.shape == (3,):
        return p[None], BODY_RADII_M[HEAD_JOINT:HEAD_JOINT + 1]
    known = np.isfinite(p).all(axis=1)
    if not known.all():
        return _bounded_spheres(p, known)
    a, b = _LIMB_ENDS
    centres = np.concatenate([p, 0.5 * (p[a] + p[b])])
    return centres, _BODY_SPHERE_RADII_M.copy()


def body_spheres_of(persons_m) -> list[tuple[np.ndarray, np.ndarray]]:
    """:func:`body_spheres` of each of ``persons_m``, read-only (they are kept and shared: nobody may change them
    in place). Whole skeletons all at once (numpy's per-call overhead, not the arithmetic, is the cost of a
    frame's few people; each centre is the per-person call's to the bit), their radii one shared array."""
    if persons_m and all(p.shape == (17, 3) for p in persons_m):
        p = np.array(persons_m, float)  # np.stack's values, without its per-array reshaping
        if np.isfinite(p).all():
            a, b = _LIMB_ENDS
            centres = np.concatenate([p, 0.5 * (p[:, a] + p[:, b])], axis=1)   # (P, 25, 3), as body_spheres
            centres.setflags(write=False)  # and so every person's view of it
            return [(c, _BODY_SPHERE_RADII_M) for c in centres]
    return [_frozen(body_spheres(p)) for p in persons_m]


_LIMB_ENDS = (np.array([i for i, _ in LIMBS]), np.array([j for _, j in LIMBS]))
_BODY_SPHERE_RADII_M = np.concatenate([BODY_RADII_M, 0.5 * (BODY_RADII_M[_LIMB_ENDS[0]] + BODY_RADII_M[_LIMB_ENDS[1]])])
""":func:`body_spheres`' radii of a whole skeleton: the joints', then the limb midpoints' (read-only: shared by
:func:`body_spheres_of`)."""
_BODY_SPHERE_RADII_M.setflags(write=False)


MAX_MISSING_JOINTS = 0
"""A lifted person may have up to this many joints not known (the lifter's ``missing`` ones, NaN
here): each is bounded by its bones from the joints he shows (:func:`_bounded_spheres`). 0 (off)
as shipped: with 3, hard:200 seed 1 (development) had fewer person_lost halts but more retractions
for walkers (a lift from an imputed keypoint moves the rest of him by up to 0.18 m, p95, and his
tracked head with it), 255 walk-by false stops per worker-hour against 198 (reports/hrc/report.md,
session 10). A module constant, not a [zones] key: [zones] is in the validated safety hash
(firmware_sim.scenarios.hrc), and turning it on belongs with that re-validation."""
REQUIRED_JOINTS = (HIP_JOINT, R_HIP, L_HIP, SPINE, THORAX, L_SHOULDER, R_SHOULDER, HEAD_JOINT)
"""Joints a person must show for the rest to be bounded from them: his trunk (the lifter's root
and frame of reference) and his head (tracked: its velocity predicts the whole body). In COCO:
both hips, both shoulders and the ears or eyes. What may be missing: knees, one ankle, elbows,
wrists, the nose."""


def enough_joints(shown) -> bool:
    """Does a person who shows the joints ``shown`` ((17,) bool: observed or held) show enough of
    himself to be lifted and judged with the rest missing: every one of ``REQUIRED_JOINTS``, at
    least one ankle (the floor anchoring's, edge_runtime.robot.calibration), at most
    ``MAX_MISSING_JOINTS`` missing."""
    shown = np.asarray(shown, bool)
    return bool(shown[_REQUIRED_INDEX].all() and (shown[L_ANKLE] or shown[R_ANKLE])
                and (~shown).sum() <= MAX_MISSING_JOINTS)


_REQUIRED_INDEX = np.array(REQUIRED_JOINTS)
""":data:`REQUIRED_JOINTS` as an index array (a list is converted at every indexing)."""


MIRROR = (0, 4, 5, 6, 1, 2, 3, 7, 8, 9, 10, 14, 15, 16, 11, 12, 13)
"""Each H36M joint's counterpart on the other side of the body (itself on the midline): a 2D
detector swaps left and right."""


def _bounded_spheres(p: np.ndarray, known: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Spheres covering a person of whom only the ``known`` joints of ``p`` (17, 3) are known
    (robot frame; the others NaN): where a joint is not known, it is within its bones
    (``JOINT_REACH_M``) of the known joint nearest to it along the skeleton, so a sphere around that
    joint, of its own radius plus that reach, holds it (several when equally near: a knee from the
    hip and the ankle). A limb's midpoint is within half its bone of a known end.

    What a 2D detector gets wrong cannot place him farther than he is (the randomised test in
    tests/robot/test_hazard.py): each such sphere is repeated around its joint's left-right
    counterpart (a swap), and a known joint farther from its nearest consistent ancestor than the
    bones between them (a stray keypoint) is not known either. ValueError without any known joint."""
    known = _consistent_joints(p, known)
    if not known.any():
        raise ValueError("a skeleton without any known joint")
    centres, radii = [p[known]], [BODY_RADII_M[known]]

    def around(j: int, extra_m: float):
        """Spheres holding whatever is within ``extra_m`` of joint ``j``, or of his nearest known joints if ``j`` is not known."""
        if known[j]:
            ks, reach = np.array([j]), 0.0
        else:
            reach = float(JOINT_REACH_M[j][known].min())
            ks = np.flatnonzero(known & (JOINT_REACH_M[j] <= reach + 1e-9))
        ks = np.union1d(ks, [MIRROR[k] for k in ks if known[MIRROR[k]]]).astype(int)
        centres.append(p[ks])
        radii.append(np.full(len(ks), reach + extra_m))

    for j in np.flatnonzero(~known):
        around(int(j), float(BODY_RADII_M[j]))
    for i, k in LIMBS:
        r = 0.5 * (BODY_RADII_M[i] + BODY_RADII_M[k])
        if known[i] and known[k]:
            centres.append(0.5 * (p[i] + p[k])[None])
            radii.append(np.array([r]))
        else:
            around(i if known[i] or not known[k] else k, r + 0.5 * float(JOINT_REACH_M[i, k]))
    return np.concatenate(centres), np.concatenate(radii)


def _consistent_joints(p: np.ndarray, known: np.ndarray) -> np.ndarray:
    """``known`` less each joint farther from its nearest known, consistent ancestor (``PARENTS``)
    than the bones between them (``JOINT_REACH_M``): a stray keypoint. The root is taken as it is."""
    out = np.asarray(known, bool).copy()
    for j in range(1, len(PARENTS)):
        if not out[j]:
            continue
        a = PARENTS[j]
        while a >= 0 and not out[a]:
            a = PARENTS[a]
        if a >= 0 and np.linalg.norm(p[j] - p[a]) > JOINT_REACH_M[j, a]:
            out[j] = False
    return out


def separation_per_shift_m(centres_m: np.ndarray, radii_m: np.ndarray, velocity_mps: np.ndarray, shifts_s,
                           capsules) -> np.ndarray:
    """The separation (m) of the spheres moved by ``velocity_mps`` x each of ``shifts_s`` (S,)
    from the capsules: (S,)."""
    return separations_per_shift_m([(centres_m, radii_m, velocity_mps)], shifts_s, capsules)[0]


def separations_per_shift_m(bodies, shifts_s, capsules) -> list[np.ndarray]:
    """:func:`separation_per_shift_m` of each of ``bodies`` ((centres (n, 3), radii (n,), velocity (3,)) each), in
    one clearance call for all of them (numpy's per-call overhead, not the arithmetic, is the cost of a frame's
    few people; each point's clearance is its own, whatever else is in the call)."""
    return _separations_m(bodies, shifts_s, capsules)[0]


def _separations_m(bodies, shifts_s, capsules, other=None) -> tuple[list[np.ndarray], list[float] | None]:
    """(:func:`separations_per_shift_m`, and with ``other`` capsules (read-only, as :func:`arm_capsules`') each body's
    separation from them moved by the first shift, else None): both in one clearance pass
    (:func:`point_clearances_m`)."""
    shifts = np.asarray(shifts_s, float)
    if len(bodies) > 1 and len({len(c) for c, _, _ in bodies}) == 1:  # whole skeletons: one (S, P, n) array
        # np.array of equal shapes: np.stack's values, without its per-array reshaping
        centres, radii = np.array([c for c, _, _ in bodies], float), np.array([r for _, r, _ in bodies], float)
        velocities = np.array([v for _, _, v in bodies], float)  # arrays or tuples of 3: the same (P, 3) array
        # each moved centre is c + s v as below, elementwise the same arithmetic
        moved = centres[None] + shifts[:, None, None, None] * velocities[None, :, None, :]     # (S, P, n, 3)
        clear, clear_other = point_clearances_m(moved.reshape(-1, 3), capsules, other)
        seps = list((clear.reshape(moved.shape[:3]) - radii[None]).min(axis=2).T)
        if clear_other is None:
            return seps, None
        return seps, (clear_other.reshape(moved.shape[:3])[0] - radii).min(axis=1).tolist()
    moved = [(c[None] + shifts[:, None, None] * np.asarray(v, float)[None, None]).reshape(-1, 3) for c, _, v in bodies]
    clear, clear_other = point_clearances_m(np.concatenate(moved) if len(moved) > 1 else moved[0], capsules, other)
    out, out_other, k = [], [], 0
    for (c, r, _), m in zip(bodies, moved):
        d = clear[k:k + len(m)].reshape(len(shifts), len(c)) - r  # each sphere's own radius, per shift
        out.append(d.min(axis=1))
        if clear_other is not None:
            out_other.append(float((clear_other[k:k + len(c)] - r).min()))
        k += len(m)
    return out, (out_other if clear_other is not None else None)


def point_clearance_m(points_m: np.ndarray, capsules) -> np.ndarray:
    """Distance (m) of each point (N, 3) from the nearest capsule's surface: (N,)."""
    p = np.asarray(points_m, float)
    return _clearance_xyz(p[:, 0], p[:, 1], p[:, 2], capsules)


def point_clearances_m(points_m: np.ndarray, capsules, other=None) -> tuple[np.ndarray, np.ndarray | None]:
    """(:func:`point_clearance_m` of the points from ``capsules``, and from ``other`` capsules or None). Both sets
    read-only (:func:`arm_capsules`'): they are joined and measured in one pass (a pass's cost is numpy's per-call
    overhead more than its arithmetic), each point's clearance from each capsule its own whatever else is in the
    pass, and each set's nearest its own minimum (exact)."""
    if other is None:
        return point_clearance_m(points_m, capsules), None
    p = np.asarray(points_m, float)
    both = _clearance_xyz(p[:, 0], p[:, 1], p[:, 2], _joined_capsules(capsules, other), split=len(capsules[2]))
    return both[0], both[1]


def _joined_capsules(capsules, other) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``capsules`` then ``other`` as one read-only set, the same tuple for the same two (so its clearance terms are
    remembered as any read-only capsules' are, :func:`_capsule_terms`)."""
    key = (id(capsules), id(other))
    hit = _JOINED.get(key)
    if hit is not None and hit[0] is capsules and hit[1] is other:
        return hit[2]
    joined = _frozen(tuple(np.concatenate([u, v]) for u, v in zip(capsules, other)))
    return _JOINED.put(key, (capsules, other, joined))[2]  # holding both keeps their ids unique while remembered


_JOINED: Recent[tuple] = Recent(4)
""":func:`_joined_capsules` of the last few pairs, by the pair's identities."""


def _clearance_xyz(x: np.ndarray, y: np.ndarray, z: np.ndarray, capsules, split: int = 0) -> np.ndarray:
    """:func:`point_clearance_m` of the points (``x``, ``y``, ``z``: (N,) each).

    The same arithmetic as the textbook form (kept in tests/robot/test_hazard.py, which pins the two to the
    bit)::

        ab = b - a; ap = p[:, None] - a[None]; den = max((ab * ab).sum(-1), 1e-12)
        t = clip((ap * ab).sum(-1) / den, 0, 1); (norm(ap - t[..., None] * ab, axis=-1) - r).min(axis=1)

    on one (K, N) array per coordinate, every sum of three in numpy's order ((x + y) + z): numpy's reductions
    over an axis of 3 cost ten times the arithmetic (the escape plan's 1,800 points x 9 capsules), and so do
    its loops over a short inner axis (the capsules'), hence the capsules first and the points along the rows.
    ``split``: the capsules before it and from it on are two sets: (2, N), each set's clearance."""
    ax, ay, az, bx, by, bz, den, r = _capsule_terms(capsules, 1)
    apx = x - ax
    apy = y - ay
    apz = z - az
    t = apx * bx
    t += apy * by
    return _clearance_rest(apx, apy, apz, t, (bx, by, bz, den, r), split)


def _clearance_rest(apx: np.ndarray, apy: np.ndarray, apz: np.ndarray, t: np.ndarray, terms,
                    split: int = 0) -> np.ndarray:
    """:func:`_clearance_xyz` on from ``t`` = ap_x b_x + ap_y b_y: (K, ...) arrays, the capsules' ``terms`` shaped
    to broadcast with them -> (...) (``apx``, ``apz`` and ``t`` are overwritten; with ``split``, (2, ...): the
    capsules before it and from it on, each set's). ``apy`` may be broadcast (the escape plan's: the same for
    every turn), and is not written.

    The operations of ``dx = apx - t bx; dy = apy - t by; dz = apz - t bz; dx * dx + dy * dy + dz * dz`` in that
    order, each into an array already there (one scratch array, not six new ones: for the escape plan's (9, 28,
    50) arrays the allocations cost as much as the arithmetic)."""
    bx, by, bz, den, r = terms
    tmp = apz * bz
    t += tmp
    t /= den
    t.clip(0.0, 1.0, out=t)  # np.clip's own ufunc, without its dispatch
    dx = np.subtract(apx, np.multiply(t, bx, out=tmp), out=apx)
    dy = np.subtract(apy, np.multiply(t, by, out=tmp), out=tmp)
    dz = np.subtract(apz, np.multiply(t, bz, out=t), out=apz)
    dx *= dx
    dy *= dy
    dz *= dz
    dx += dy
    dx += dz
    np.sqrt(dx, out=dx)
    dx -= r
    # each set's nearest capsule (a minimum is exact, and no clearance is -0.0: sqrt(.) - r of equal values is +0.0)
    return np.minimum.reduceat(dx, (0, split), axis=0) if split else dx.min(axis=0)


def _capsule_terms(capsules, dims: int) -> tuple:
    """(a_x, a_y, a_z, ab_x, ab_y, ab_z, max(|ab|^2, 1e-12), r) of ``capsules`` (ab = b - a), as
    :func:`_clearance_xyz` uses them: each (K,) followed by ``dims`` axes of 1, to broadcast against (K, ...)
    arrays of points. Remembered for read-only capsules (:func:`arm_capsules`', the same tuple for the same
    joint angles, asked about by every person's separation now and predicted, the lost people, the backfire
    check and the escape plan of a frame)."""
    a, b, r = capsules
    frozen = isinstance(a, np.ndarray) and not (a.flags.writeable or b.flags.writeable or r.flags.writeable)
    key = (id(capsules), dims)
    if frozen and (hit := _TERMS.get(key)) is not None and hit[0] is capsules:
        return hit[1]
    ab = b - a
    den = np.maximum((ab * ab).sum(-1), 1e-12)
    shape = (-1,) + (1,) * dims
    terms = tuple(v.reshape(shape) for v in (a[:, 0], a[:, 1], a[:, 2], ab[:, 0], ab[:, 1], ab[:, 2], den,
                                             np.asarray(r, float)))
    if frozen:  # holding the capsules keeps their id unique while remembered
        _TERMS.put(key, (capsules, terms))
    return terms


_TERMS: Recent[tuple] = Recent(8)
""":func:`_capsule_terms` of read-only capsules, by the tuple's identity."""


def _gathered(people) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Everyone's spheres (``people``: (centres (n, 3), radii (n,)) each) as one list: centres, radii and where
    each person's begin (each person's spheres are contiguous)."""
    centres = np.concatenate([c for c, _ in people])
    radii = np.concatenate([r for _, r in people])
    # np.cumsum's integers, summed in Python (numpy's call on a list costs more than a frame's few people)
    return centres, radii, np.array(list(itertools.accumulate([0] + [len(r) for _, r in people[:-1]])))


def people_separations_m(people, capsules) -> np.ndarray:
    """:func:`separation_m` of each of ``people`` ((centres (n, 3), radii (n,)) each, at least one) from the
    ``capsules``: (P,), in one clearance call (each point's clearance is its own, and a minimum is exact)."""
    centres, radii, starts = _gathered(people)
    return np.minimum.reduceat(point_clearance_m(centres, capsules) - radii, starts)


def separation_m(centres_m: np.ndarray, radii_m: np.ndarray, capsules) -> float:
    """Smallest surface-to-surface distance (m) between spheres (``centres_m`` (N, 3),
    ``radii_m`` (N,)) and capsules (starts (K, 3), ends (K, 3), radii (K,)); negative when
    they overlap."""
    return float((point_clearance_m(centres_m, capsules) - radii_m).min())


# ----------------------------------------------------------------------------------------------
# People seen in 2D but not lifted: bounded by their keypoints' rays

@dataclass(frozen=True)
class PersonRays:
    """What the camera shows of a person the lifter has not lifted validly: his keypoints' rays
    in the robot frame (from the calibration's camera pose)."""

    origin_m: np.ndarray
    """(3,) the camera centre."""
    directions: np.ndarray
    """(17, 3) unit directions of his H36M keypoints; NaN rows for joints not seen."""
    floor_y_m: float
    """The floor's height in the robot frame (m)."""


BONE_MAX_M = (0.2, 0.5, 0.5, 0.2, 0.5, 0.5, 0.3, 0.3, 0.2, 0.3, 0.25, 0.4, 0.32, 0.25, 0.4, 0.32)
"""The longest bone (m) from each joint 1..16 to its parent (``skeleton.PARENTS``): a 2.0 m
person's (edge_runtime/core/skeleton.py's proportions) with a margin. A joint not seen lies
within the sum of the bones between it and a joint that is."""
RAY_MAX_SAMPLES = 48
"""Points each joint's ray segment is checked at (half their spacing is subtracted): 0.1 m apart
on a segment 4.7 m long."""
RAY_MAX_RANGE_M = 30.0
"""Ray segments end this far (ground distance, m) from the camera: further out nobody is near the arm."""
RAY_KEYPOINT_ERROR_M = 0.25
"""A keypoint's ray passes within this of its joint (m, on the body): 2.3 times a real detector's
error at the hips, its loosest joint (COCO's keypoint sigma 0.107 at a person's scale of about
1 m), more than twice its error at the ankles or head. Keypoints are not exact: a bound that takes
the rays as exact lay above the truth in 166 of 1,968 frames of people lost within 1.5 m of the
arm (hard:200 seed 1, session 12's review), by up to 2.2 m. A gross error beyond this (a keypoint on
another person) is caught where the anchors then disagree (no bound) or by a lost person's track."""
RAY_MIN_SLOPE = math.sin(math.radians(2.0))
"""A ray flatter than this (sine of its angle to the horizontal) bounds nothing: its floor or
head-height crossing is too ill-conditioned."""


def _joint_reach_m() -> np.ndarray:
    """(17, 17) the longest possible distance between two joints along the skeleton (m)."""
    d = np.full((17, 17), np.inf)
    np.fill_diagonal(d, 0.0)
    for child, parent in enumerate(PARENTS):
        if parent >= 0:
            d[child, parent] = d[parent, child] = BONE_MAX_M[child - 1]
    for k in range(17):
        d = np.minimum(d, d[:, k:k + 1] + d[k:k + 1, :])
    return d


JOINT_REACH_M = _joint_reach_m()


def ray_ground_range_m(origin_m, direction, heights_m: tuple[float, float], floor_y_m: float):
    """(near, far): the ground distances (m) from the camera at which the ray ``direction`` is
    between ``heights_m`` above the floor, or None when it never is (or is too flat to say)."""
    u = np.asarray(direction, float)
    g = math.hypot(u[0], u[2])
    if g < 1e-9 or abs(u[1]) < RAY_MIN_SLOPE:
        return None
    h_cam = float(origin_m[1]) - floor_y_m
    near, far = sorted((h - h_cam) / (u[1] / g) for h in heights_m)
    if far <= 0:
        return None
    return max(near, 0.0), far


def ray_separation_m(rays: PersonRays, capsules, zones: ZoneParams):
    """A lower bound of the separation (m) of a person from the arm's ``capsules`` from his
    keypoints' rays alone, and where he stands (the middle of his feet's segments, for Eq. 6's
    direction), or None when his rays bound nothing. Each joint he shows is within
    :data:`RAY_KEYPOINT_ERROR_M` of its ray (e below). Where he can be:

    * each ankle he shows is near its ray where the ray is between ``ray_ankle_heights_m`` above
      the floor (a foot down or in the air), each widened by e: a range of ground distance from
      the camera; so are his hips and pelvis with ``ray_hip_heights_m`` and his head with
      ``ray_head_heights_m``;
    * every joint of him is within ``ray_body_extent_m`` (ground distance) of the foot on the
      ground (and that foot within ``ray_stride_m`` of the other one when one ankle alone is
      seen), of his hips and of his head: so each joint he shows is near its own ray within the
      ranges above widened by that (where they all overlap), and every joint (shown or not)
      stands over the floor within that of each such anchor's floor points;
    * showing no ankle, hip, pelvis or head, each joint he shows is near its ray between the floor and
      ``ray_joint_heights_m`` (a raised wrist), and every joint of him within its bones of it.
      (Narrowing each joint's segment to where its neighbours' rays are within a bone of it, as
      before session 12, took the rays as exact: rays a degree off were "near" only close to the
      camera, which pulled the segments toward it; with e allowed at every bone it narrows nothing.)

    Anchors whose regions do not overlap contradict a body (a keypoint on someone or something
    else): None, nothing is bounded. The bound is the smallest of these regions' clearance from the
    capsules, less e and each joint's body radius (``BODY_RADII_M``; limb midpoints too). Where he
    stands is None without a foot anchor: a head's or hip's height band runs a metre or more along
    a ray, past him, so its middle can lie behind the arm (retracting away from it would carry the
    arm into him)."""
    u, o = rays.directions, np.asarray(rays.origin_m, float)
    e = RAY_KEYPOINT_ERROR_M
    seen = np.isfinite(u).all(axis=1)
    g = np.hypot(u[:, 0], u[:, 2])
    if (g[seen] < 1e-9).any():  # a ray straight down or up: that joint is anywhere below or above the camera
        return None

    def ray_range(j: int, heights: tuple[float, float]):
        """Ground distances of the ray points within e of the joint's heights: the joint is within e of them."""
        return ray_ground_range_m(o, u[j], (heights[0] - e, heights[1] + e), rays.floor_y_m)

    # anchors: joints whose height above the floor is known within a band, each group with the ground distance
    # every joint of him is within of it (and e: the joint is off the ray point)
    feet = [j for j in (L_ANKLE, R_ANKLE) if seen[j]]
    groups = [(feet, zones.ray_ankle_heights_m, zones.ray_body_extent_m + (zones.ray_stride_m if len(feet) == 1 else 0)),
              ([j for j in (HIP_JOINT, R_HIP, L_HIP) if seen[j]], zones.ray_hip_heights_m, zones.ray_body_extent_m),
              ([HEAD_JOINT] if seen[HEAD_JOINT] else [], zones.ray_head_heights_m, zones.ray_body_extent_m)]
    ranges, regions = {}, []
    for joints_, heights, extent in groups:
        got = {j: ray_range(j, heights) for j in joints_}
        got = {j: r for j, r in got.items() if r is not None}
        if got:
            ranges.update(got)
            regions.append((min(r[0] for r in got.values()) - extent - e, max(r[1] for r in got.values()) + extent + e,
                            list(got), extent))
    if not regions:  # no anchor: each seen joint is between the floor and a raised wrist, the rest within its bones
        for j in np.flatnonzero(seen):
            r = ray_range(j, zones.ray_joint_heights_m)
            if r is not None:
                ranges[j] = r
                reach = float(JOINT_REACH_M[j].max())
                regions.append((r[0] - reach - e, r[1] + reach + e, [j], reach))
    if not regions:  # nothing crosses the floor or its band of heights
        return None
    near, far = max(r[0] for r in regions), min(r[1] for r in regions)  # each region holds all of him
    if near > far:  # the anchors disagree: a keypoint is not his
        return None
    near, far = max(near, 0.0), min(far, RAY_MAX_RANGE_M)
    # each seen joint's ray points (distance along the ray, m): an anchor's within its own range, every joint's
    # within e of the region that holds him
    span = {}
    for j in np.flatnonzero(seen):
        lo, hi = max(near - e, 0.0), far + e
        if j in ranges:
            lo, hi = max(lo, ranges[j][0]), min(hi, ranges[j][1])
        if lo > hi:  # an anchor's ray never comes near where the others hold him
            return None
        span[j] = (lo / g[j], hi / g[j])
    joints = np.array(sorted(span))
    lo, hi = np.array([span[j] for j in joints]).T
    t = lo[:, None] + (hi - lo)[:, None] * np.linspace(0.0, 1.0, RAY_MAX_SAMPLES)[None, :]    # (J, S)
    half = 0.5 * (hi - lo) / (RAY_MAX_SAMPLES - 1) + e  # every joint is within this of a sample of its ray
    pts = o + t[..., None] * u[joints][:, None, :]                                             # (J, S, 3)
    c = point_clearance_m(pts.reshape(-1, 3), capsules).reshape(t.shape) - half[:, None]
    clear = np.full(17, -np.inf)
    clear[joints] = c.min(axis=1)
    # where he stands, for the retraction's direction: the middle of his feet's segments
    on_feet = np.isin(joints, [j for j in feet if j in ranges])
    stands = (o + 0.5 * (lo + hi)[on_feet, None] * u[joints[on_feet]]).mean(axis=0) if on_feet.any() else None
    # every joint stands over the floor within an anchor group's extent of where it stands (the arm seen from above)
    flat = np.array([1.0, 0.0, 1.0])
    a, b, r = capsules
    over = point_clearance_m(pts.reshape(-1, 3) * flat, (a * flat, b * flat, r)).reshape(t.shape) - half[:, None]
    column = max(float(over[np.isin(joints, members)].min()) - extent for _, _, members, extent in regions)
    joint = np.maximum((clear[None, :] - JOINT_REACH_M).max(axis=1), column)
    a_, b_ = np.array([i for i, _ in LIMBS]), np.array([j for _, j in LIMBS])
    limb = np.maximum(joint[a_], joint[b_]) - 0.5 * JOINT_REACH_M[a_, b_]  # a limb's midpoint: half a bone from either end
    d = min(float((joint - BODY_RADII_M).min()),
            float((limb - 0.5 * (BODY_RADII_M[a_] + BODY_RADII_M[b_])).min()))
    return d, stands


# ----------------------------------------------------------------------------------------------
# Retraction (Eq. 6): pure functions

@dataclass(frozen=True)
class RetractLimits:
    """Where the Sawyer can retract to (from the loop's [robot_loop] parameters)."""

    min_radius_m: float = 0.3
    """Targets stop short of this ground distance from the base's axis (m)."""
    max_radius_m: float = 0.45
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
    n = vector_norm(v)
    return v / n if n > 1e-9 else np.zeros_like(v)


def retract_direction(effector_m, est: HeadEstimate, params: ZoneParams = ZoneParams()) -> np.ndarray:
    """Eq. 6 in the robot frame: ``w1 unit(P_eff - P_head) + w2 unit(V_ground)``, on the
    ground (y = 0). A standing worker contributes no second term."""
    away = _unit(ground(effector_m) - ground(est.position_m))
    v_g = ground(est.velocity_mps)
    path = _unit(v_g) if vector_norm(v_g) > 0.2 else np.zeros(2)
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
    r = vector_norm(ground(target))
    if r > limits.max_radius_m:
        target[[0, 2]] *= limits.max_radius_m / r
    return _retraction(target, limits, tool_yaw_rad, held_yaw_rad)


def turned_capsules(capsules, turn_rad: float):
    """The arm's ``capsules`` turned about the base's axis (the robot frame's y) by ``turn_rad``: its
    first joint (j0) turned alone, every link with it. A positive turn raises a point's bearing
    ``atan2(x, z)`` (the tool's yaw turns with it)."""
    a, b, r = capsules
    rot = _base_rotation(turn_rad)
    return a @ rot.T, b @ rot.T, r


def _base_rotations(turns_rad) -> np.ndarray:
    """(n, 3, 3) rotations about the robot frame's y axis, each raising a bearing ``atan2(x, z)`` by its turn."""
    t = np.asarray(turns_rad, float)
    c, s_ = np.cos(t), np.sin(t)
    one, zero = np.ones_like(t), np.zeros_like(t)
    return np.stack([np.stack([c, zero, s_], -1), np.stack([zero, one, zero], -1), np.stack([-s_, zero, c], -1)], -2)


def _base_rotation(turn_rad: float) -> np.ndarray:
    """``_base_rotations([turn_rad])[0]``: the same numbers (numpy's cosine and sine of the turn), built from them
    directly instead of by nine stacks (an escape command's frame makes one)."""
    t = np.array([turn_rad], float)
    c, s_ = np.cos(t).item(), np.sin(t).item()
    return np.array([[c, 0.0, s_], [0.0, 1.0, 0.0], [-s_, 0.0, c]])


ESCAPE_FIRST_CANDIDATES = 8
""":func:`plan_escape_turn` weighs this many candidates of a direction first and the rest only when the sweep
gets past them (it often passes nearer someone within a few steps; the results are the same either way)."""
SAWYER_J0_RANGE_RAD = math.radians(170.0)
"""The escape turns the Sawyer's first joint within this of zero either way (rad): its description's
limits are +-3.0503 rad (174.8 deg), and an IK goal at the limit is refused."""


def plan_escape_turn(capsules, people, j0_rad: float | None, step_deg: float, min_gain_m: float,
                     dip_m: float, max_turn_deg: float, reach_m: float = math.inf,
                     here: np.ndarray | None = None) -> float | None:
    """The turn of the base (rad, j0 alone) that takes the arm (``capsules``, where it is now) clearest of
    everyone in ``people`` (each his body spheres, (centres (n, 3), radii (n,)), robot frame, as the
    monitor accounts for him: :meth:`HazardMonitor.escape_people`), or None when none gains
    ``min_gain_m`` of separation from the nearest. Candidates: every ``step_deg`` both ways, up to
    ``max_turn_deg`` from here and within :data:`SAWYER_J0_RANGE_RAD` of j0's zero (``j0_rad`` None: not
    known, the first bound alone). Each is scored by the smallest whole-body separation from anyone at
    its end; a direction is given up where its sweep passes more than ``dip_m`` nearer anyone than he
    is now or than ``reach_m`` (``[zones] reach_retract_m``), whichever is nearer, each person against
    his own separation (the joint-space path of a j0-only goal is that sweep: a side chosen by the
    hand's ground distance at the end alone turned the arm across a worker, hard:40 seed 5, hard_012;
    a rule on the nearest alone let the sweep close on a second one). Ties go to the sweep whose
    closest pass is clearer. ``here``: everyone's separation now from ``capsules`` when the caller has it
    (:meth:`HazardMonitor.escape_separations_m`: the same numbers), else it is measured here."""
    if not people:
        return None
    centres, radii, starts = _gathered(people)
    step = math.radians(step_deg)

    def per_person(clear: np.ndarray) -> np.ndarray:
        """(..., spheres) clearances -> (..., people) separations."""
        return np.minimum.reduceat(clear, starts, axis=-1)

    if here is None:
        here = per_person(point_clearance_m(centres, capsules) - radii)          # (P,)
    x, y, z = centres[:, 0], centres[:, 1], centres[:, 2]
    ax, ay, az, bx, by, bz, den, r = _capsule_terms(capsules, 2)
    # a turn about y leaves every height as it is: ap_y and ap_y b_y are the same for every candidate
    apy = y - ay                                                                      # (K, 1, spheres)
    apy_by = apy * by
    floor = np.minimum(here, reach_m) - dip_m
    gain = here.min() + min_gain_m

    def separations(cos: np.ndarray, sin: np.ndarray) -> np.ndarray:
        """(chunk,) cosines and sines of -turn -> (chunk, P): everyone's separation after each turn. Turning the
        arm by a is turning everyone by -a about the same axis (y), each coordinate as _base_rotations(-turns)
        applied to the centres gives it (tests pin them to the bit)."""
        c, s_ = cos[:, None], sin[:, None]
        moved_x, moved_z = c * x + s_ * z, -s_ * x + c * z                                     # (chunk, spheres)
        apx = moved_x - ax                                                                     # (K, chunk, spheres)
        t = apx * bx
        t += apy_by
        clear = _clearance_rest(apx, apy, moved_z - az, t, (bx, by, bz, den, r))               # (chunk, spheres)
        return per_person(clear - radii[None])

    sweeps = []  # each direction's candidate turns, with the cosines and sines of their negatives
    for sign in (1.0, -1.0):
        room = math.radians(max_turn_deg)
        if j0_rad is not None:
            room = min(room, SAWYER_J0_RANGE_RAD - sign * j0_rad)
        n = int(math.floor(room / step + 1e-9))
        if n >= 1:
            turns = sign * step * np.arange(1, n + 1)
            sweeps.append((turns, np.cos(-turns), np.sin(-turns)))
    if not sweeps:
        return None
    # both directions' first candidates in one pass (a pass's overhead is a few candidates' arithmetic); each
    # candidate's separations are its own whatever else is in the pass
    first = ESCAPE_FIRST_CANDIDATES
    firsts = np.split(separations(np.concatenate([cos[:first] for _, cos, _ in sweeps]),
                                  np.concatenate([sin[:first] for _, _, sin in sweeps])), [len(sweeps[0][0][:first])])
    best = None  # (end separation, closest pass, turn)
    for (turns, cos, sin), d_first in zip(sweeps, firsts):
        n = len(turns)
        prev = None  # the closest pass so far of each person, up to the chunk before
        for lo, hi in ((0, min(n, first)), (min(n, first), n)):
            if lo >= hi:
                break
            d = d_first if lo == 0 else separations(cos[lo:hi], sin[lo:hi])                  # (chunk, P)
            passed = np.minimum.accumulate(d, axis=0)
            if prev is not None:
                passed = np.minimum(passed, prev[None])
            prev = passed[-1]
            # the sweep ends before the first candidate whose way there passes nearer someone than he is now
            stop = (passed < floor).any(axis=1)
            n_ok = int(np.argmax(stop)) if stop.any() else hi - lo
            for e_k, c_k, t_k in zip(d.min(axis=1)[:n_ok].tolist(), passed.min(axis=1)[:n_ok].tolist(),
                                     turns[lo:lo + n_ok].tolist()):
                if e_k >= gain and (best is None or (e_k, c_k) > best[:2]):
                    best = (e_k, c_k, t_k)
            if n_ok < hi - lo:
                break
    return None if best is None else best[2]


def turned_retraction(effector_m, tool_yaw_rad: float, turn_rad: float) -> Retraction:
    """The hand's target and the tool's yaw of the arm turned about the base's axis by ``turn_rad``
    (:func:`turned_capsules`): the same height, the same distance from the axis."""
    return Retraction(_base_rotation(turn_rad) @ np.asarray(effector_m, float), tool_yaw_rad + turn_rad)


def radial_retraction(effector_m, zones: ZoneParams, limits: RetractLimits, tool_yaw_rad: float | None,
                      held_yaw_rad: float | None = None) -> Retraction:
    """The fallback: straight toward the base's axis (away from anyone in front of the arm),
    as far as Eq. 6's step but not inside ``min_radius_m``."""
    eff = np.asarray(effector_m, float)
    g = ground(eff)
    r = vector_norm(g)
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
