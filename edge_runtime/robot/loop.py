"""The robot-side safety loop: poses in, hazard decisions, commands out on the robot link.

Per camera frame::

    2D keypoints -> StreamingLifter -> joints (camera frame)  \\
                          or 3D joints given directly (camera or robot frame)
    -> calibration (camera -> robot frame; each skeleton re-anchored on the floor when
       the calibration's ground_anchor is on) -> head tracker (per worker)
    -> HazardMonitor (zones, hysteresis, fail-safe) -> in level 2 the retraction
       (:mod:`edge_runtime.robot.hazard`) -> commands on the LinkInterface

``RobotLoop`` never sleeps and never reads the wall clock itself: time comes from the
injectable ``clock`` (``time.monotonic`` by default; a scenario runner passes its
simulated clock). Its driver calls

* ``feed_joints(...)`` / ``feed_lifted(...)`` / ``feed_people(...)`` (every tracked person
  lifted with his own window; ``feed_poses`` for people lifted already: one person's invalid
  lift is judged on him, not the whole frame) for every camera frame, and
* ``tick()`` at the control rate (e.g. every 10 ms): link polling, the 200 ms staleness
  check, the task motion and the heartbeat.

Commands go out only when what the arm should do changes (plus ``heartbeat()`` every
``heartbeat_period_s``; the controller's watchdog stops the arm after 200 ms without
one), so the link is never flooded. What the arm should do:

=========  =====================================================  ==================
state      motion                                                 beacon
=========  =====================================================  ==================
NORMAL     the task: cycle through ``task_waypoints_m``            green
LEVEL1     ``stop()``                                              red, 2000 Hz 70 dB
LEVEL2     ``retract(P_eff + L)`` on entry (Eq. 6; again when it  red, 4000 Hz 80 dB
           is done and the worker still comes closer), planned
           by :mod:`edge_runtime.robot.hazard`; if the
           controller reports it unreachable, one retraction
           straight toward the base, and if that is refused too:
           ``stop()`` (``retract_unreachable``); someone within
           reach of the folded or stopped arm: a turn about the
           base to where it is clearest (planned again while
           level 2 lasts, ``escape_*``)
FAULT      ``stop()`` (pose stale / invalid / no pose yet, or a    yellow
           person in view never lifted validly)
=========  =====================================================  ==================

The link is a :class:`edge_runtime.robot.link.base.LinkInterface` (a ``RobotLink``, or a
stand-in). A ``RobotLink`` never raises on a transport fault; it
reports ``link_ok`` and reconnects by itself. The loop reads ``link_ok`` at every poll:
a drop is counted (``link_errors``) and reported (status ``link``: ``connecting``, ``ok``,
``lost``; ``link_error`` from the link), and when the link is back the current motion
and beacon are sent again (``resume()`` first: the controller's watchdog has latched
a stop meanwhile). A link object that does raise is handled the same way, with a
heartbeat tried every ``link_retry_s``. A command the link refuses as invalid
(``ValueError``) or that the controller answers ``unreachable``/``refused``/``invalid``
is counted (``refused``); for a retraction the arm is stopped instead, and a task
waypoint is skipped. The beacon is sent just before the motion, because the controller
reports the answer to its latest command only.

Heartbeats: a link that ``heartbeats_itself`` sends them from ``poll()``; otherwise the
loop calls ``heartbeat()`` every ``heartbeat_period_s``.

Every frame leaves a ``FrameRecord`` with ``t_in_s`` (the clock when the frame
arrived) and ``t_command_s`` (the clock after the link call it caused returned, or
None), so the reaction time keypoints-in -> command-on-link can be measured, and
``people``: per person, what the runtime believed (``head_robot_m``, ``predicted_head_m``,
the body point nearest the end effector and its distance), so a recorded shift can be
audited (``python -m edge_runtime robot --link none``).
"""
from __future__ import annotations

import enum
import math
import time
from collections import deque
from dataclasses import InitVar, dataclass, field
from typing import TYPE_CHECKING, Callable, Protocol

import numpy as np

from edge_runtime import config
from edge_runtime.core.memo import Recent
from edge_runtime.core.skeleton import HEAD, JOINTS, NO_JOINTS
from edge_runtime.robot.hazard import (
    Decision,
    HazardMonitor,
    PersonRays,
    Retraction,
    RetractLimits,
    State,
    TrackerParams,
    ZoneParams,
    arm_capsules,
    effector_capsule,
    enough_joints,
    eq6_retraction,
    ground,
    plan_escape_turn,
    radial_retraction,
    turned_retraction,
)
from edge_runtime.robot.hazard import vector_norm as _norm3  # the task's waypoint check runs at every control tick
from edge_runtime.robot.rays import lifter_rays

if TYPE_CHECKING:  # the caller makes the lifter (onnxruntime) and the link (python-can, pymavlink): the
    # loop only calls them, so importing it (as the box configuration does) stays light
    from edge_runtime.robot.lifter import LiftedPose, PeopleLifter, StreamingLifter
    from edge_runtime.robot.link.base import LinkInterface


@config.section("robot_loop")
@dataclass(frozen=True)
class LoopParams:
    """The loop's timing and the arm's normal work ([robot_loop] in the box configuration)."""

    heartbeat_period_s: float = config.setting(0.05, ("a number in [0.005, 0.15] (the arm's watchdog is 200 ms)", lambda v: 0.005 <= v <= 0.15))
    """heartbeat() period (s); the controller's watchdog stops the arm after 200 ms without
    a valid command or heartbeat."""
    link_retry_s: float = config.setting(0.5, config.POSITIVE)
    """A link whose calls raise is retried this often (s); a latched watchdog is cleared
    at most this often."""
    task_waypoints_m: tuple[tuple[float, float, float], ...] = config.setting(
        ((0.45, 0.14, 0.55), (0.0, 0.14, 0.8), (-0.45, 0.14, 0.55)),
        ("at least one [x, y, z] waypoint", lambda v: len(v) >= 1))
    """The task: robot-frame end-effector positions (m) the arm cycles through while NORMAL
    (y = 0.14 m is 1.055 m above the floor, the dissertation's P0)."""
    task_pitch_rad: float = 0.0
    """Tool pitch during the task (rad)."""
    task_yaw_rad: float = 0.0
    """Tool yaw during the task (rad; 0 points the tool along +z, the work side)."""
    waypoint_tolerance_m: float = config.setting(0.03, config.POSITIVE)
    """A waypoint counts as reached within this distance (m)."""
    min_height_m: float = -0.3
    """Retraction targets are kept at or above this robot-frame height (m)."""
    retract_min_radius_m: float = config.setting(0.3, config.NON_NEGATIVE)
    """A retraction stops short of this ground distance from the base's axis (m): closer in,
    the Sawyer cannot hold its tool pointed at the base (its IK refuses the target)."""
    re_retract_m: float = config.setting(0.15, config.POSITIVE)
    """In level 2, the arm retracts again (Eq. 6 from where it is) once its retraction is done
    and the worker has come this much closer (m) since it began."""
    retract_max_turn_deg: float = config.setting(45.0, config.within(0, 180))
    """The tool turns toward the base while retracting (the dissertation's Sec. 3.2.4.4) by
    at most this much (deg); 180 turns it all the way. A large turn makes the hand swing
    through joint space: in the simulated Sawyer a full turn swept it 0.3 m toward the
    worker, which 45 deg avoids."""
    retract_backfire_m: float = config.setting(0.1, config.POSITIVE)
    """whole_body: a retraction under way that has brought the arm this much closer (m) to someone
    within the retraction's reach (``body_retract_distance_m`` + ``retract_lead_s`` x
    ``lost_person_speed_mps``), by its own motion (his body now against the arm where it is and
    where the retraction began), is replaced by the retraction straight toward the base, and that
    one by a stop: the controller moves its joints along a straight line to its IK solution, and a
    far solution swings the hand through the cell (hard:200 seed 3, hard_109: toward a passing
    worker, 0.081 m). An escape turn that does so is stopped and planned again from where it stopped
    (holding it to ``escape_dip_m`` instead stopped turns as they began, over and over, and left the
    arm half folded by a worker: hard:200 seed 13, hard_064)."""
    radial_retract_stops: bool = False
    """whole_body: the retraction straight toward the base that replaces a backfiring one (``retract_backfire_m``)
    is itself stopped when it backfires too (true, shipped until session 21). False: it runs to its end, since it
    only folds the arm in along its bearing; stopped, it left the arm half retracted 0.8-0.9 m from the base's
    axis between two passing workers, where a third reached into it (hard:200 seed 29, hard_143: 0.059 m, and
    hard_044 with another lifter)."""
    escape_step_deg: float = config.setting(5.0, config.within(0.5, 30, "deg"))
    """whole_body: the escape turn (``[zones] escape_deg``) weighs turns of the base every this many
    degrees both ways (deg): at 1 m from the axis 5 deg is 0.09 m of sweep between two candidates."""
    escape_min_gain_m: float = config.setting(0.05, config.within(0, 1, "m"))
    """whole_body: the arm turns only to where its separation from everyone is at least this much (m)
    larger than now: a smaller gain is within keypoint noise and not worth moving for."""
    escape_dip_m: float = config.setting(0.02, config.within(0, 0.2, "m"))
    """whole_body: an escape turn may pass at most this much (m) nearer anyone than he is from the arm
    now on its way (candidates are weighed every ``escape_step_deg``, so a sweep's closest pass is
    known to a few cm); a turn that would pass nearer is not taken."""
    escape_turn_max_deg: float = config.setting(30.0, config.within(1, 180, "deg"))
    """whole_body: one escape command turns the base at most this far (deg) toward the planned end; the
    rest is planned again from where the arm then is. The controller reaches a turned hand target by
    its own IK, and the larger the turn the further that strays from turning the first joint alone
    (0.05-0.08 m of arm at 30 deg, 0.2-0.28 m at 90 deg; a +165 deg target was reached by turning
    -128 deg, the other way round)."""
    escape_replan_s: float = config.setting(0.5, config.within(0.05, 5, "s"))
    """whole_body: while level 2 lasts and someone is within ``[zones] reach_retract_m``, the escape is
    planned again from where the arm is once its last turn or retraction is done or it was stopped,
    at most this often (s), whether or not the last plan found a turn: an arm stopped half folded on a
    worker's side stood there while he reached into it (hard:40 seed 5, hard_012), where turned about
    its base it cleared him."""
    retract_max_radius_m: float = config.setting(0.45, config.POSITIVE)
    """Retraction targets further than this from the base's axis (ground distance, m) are
    pulled in to it, so that a retracted arm is tucked in: with the hand at 0.45 m and the tool
    toward the base the simulated Sawyer's links and tool stay within about 0.65 m of the axis, at 0.7 m
    (the value until session 20) within 0.89 m, where workers passing 1.1-1.3 m from the base swung a hand
    into the tool or walked into it (hard:200 seed 23, hard_107 0.086 m, hard_112 0.055 m; random:200 seed
    23, random_101 0.076 m; hard:200 seed 15, hard_094, hard_110: all clear at 0.45, 0.25-0.60 m:
    reports/hrc/s20_contact/)."""
    records: int = config.setting(100_000, config.AT_LEAST_1)
    """Frames whose reaction time (keypoints in -> command sent) the run's summary keeps (the oldest
    are dropped). A frame's whole record goes to ``on_record`` (the ``--log``) and is not kept: a
    shift's worth of records, each with its people's dicts and lists, made every full pass of the
    garbage collector walk them, inside a frame (76 ms after 300 s in the bench, growing with the
    run; reports/bench/s17_final.md)."""
    ack_timeout_s: float = config.setting(0.1, ("a number in (0, 0.2) (the arm's watchdog is 200 ms)",
                                                 lambda v: 0 < v < 0.2))
    """A motion command (stop, retract, move) the arm has not acknowledged within this long
    (s), or a stop it refused, raises the command alarm, is sent again and is counted
    (``unacked``, ``retries``); a refused move or retraction raises it too (the next waypoint
    or the fallback retraction follows)."""
    ack_retries: int = config.setting(3, config.AT_LEAST_1)
    """More motion commands than this in a row not acknowledged (unanswered or refused): the
    loop reports a ``fault`` (``python -m edge_runtime robot`` then ends, the arm left to its
    watchdog)."""
    link_up_timeout_s: float = config.setting(2.0, config.POSITIVE)
    """No state from the arm this long (s) after the loop started: the link never came up,
    a ``fault`` (wrong channel, nothing answering, a signing key the arm does not share)."""

    def __post_init__(self):
        if not 0 <= self.retract_min_radius_m < self.retract_max_radius_m:
            raise ValueError("retract_max_radius_m: must be above retract_min_radius_m (and both >= 0)")

    @property
    def retract_limits(self) -> RetractLimits:
        return RetractLimits(self.retract_min_radius_m, self.retract_max_radius_m, self.min_height_m,
                             self.retract_max_turn_deg)


class CameraToRobot(Protocol):
    """What the loop uses of :class:`edge_runtime.robot.calibration.Calibration`."""

    def to_robot(self, joints_cam_m, observed=None, ids=None) -> np.ndarray:
        """Robot-frame joints (P, 17, 3) of camera-frame ones (P, 17, 3); ``observed`` (P, 17)
        the joints seen in this frame (the floor anchoring prefers their rays); ``ids`` (P,) the
        tracker's ids (the anchoring is filtered per person)."""


class MotionKind(enum.Enum):
    MOVE = "move"
    RETRACT = "retract"
    STOP = "stop"


@dataclass(frozen=True)
class Motion:
    """One motion command (the arm's position m and tool pitch/yaw rad for a move or retraction)."""

    kind: MotionKind
    position_m: tuple[float, float, float] | None = None
    pitch_rad: float = 0.0
    yaw_rad: float = 0.0


STOP = Motion(MotionKind.STOP)
INVALID = "invalid"
"""What ``_call`` returns for a command the link refused as invalid (ValueError)."""
NO_PERSON = "no_person"
"""The lifter's reason code for a frame in which nobody was detected."""


@dataclass
class FrameRecord:
    """One camera frame through the loop (times on the loop's clock, seconds)."""

    t_in_s: float
    t_command_s: float | None
    state: str
    reason: str
    distance_m: float
    command: str | None
    people_of: InitVar[Callable[[], list] | None] = None
    """What makes ``people`` when it is first read (None: nobody seen). The loop's per-person beliefs decide
    nothing and the robot command reads them only with ``--log``: a frame makes none of them unless asked
    (0.2-0.3 ms of a frame's CPU, on every frame of a run without a log)."""
    people: list = field(init=False)
    """Per person seen (valid frames): ``id``, ``head_robot_m``, ``predicted_head_m`` (Eq. 3),
    ``nearest_joint``, ``nearest_point_m`` (his joint nearest the end effector) and
    ``nearest_distance_m`` (3D, m); robot frame. Made on first reading (``asdict``, ``==`` and ``repr`` read it)."""

    def __post_init__(self, people_of):
        if people_of is None:
            self.people = []
        else:
            self._people_of = people_of

    def __getattr__(self, name: str):
        # only reached for an attribute not set: ``people`` before its first reading
        make = self.__dict__.pop("_people_of", None) if name == "people" else None
        if make is None:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        self.people = make()
        return self.people

    def __getstate__(self):
        self.people  # noqa: B018 - made before a copy or pickle: what makes it (a closure) cannot be pickled
        return self.__dict__


@dataclass
class LoopCounters:
    frames: int = 0
    invalid: int = 0
    stale: int = 0
    stops: int = 0
    retracts: int = 0
    moves: int = 0
    unreachable: int = 0
    refused: int = 0
    link_errors: int = 0
    heartbeats: int = 0
    commands: int = 0
    acked: int = 0
    """Motion commands (stop, retract, move) the arm acknowledged."""
    unacked: int = 0
    """Motion commands with no acknowledgement within ``ack_timeout_s``."""
    retries: int = 0
    """Motion commands sent again (unacknowledged, or a stop refused)."""
    speed_changes: int = 0
    """Speed overrides sent (whole-body speed scaling)."""
    unseen: int = 0
    """People in a frame whose lift was invalid (each judged from his last valid pose)."""
    bounds_refused: int = 0
    """Lost people's ray bounds not heard because their track says they cannot be that far
    (``HazardMonitor.bounds_refused``)."""
    backfired: int = 0
    """Retractions (escape turns included) replaced by a stop because they carried the arm toward someone
    (``retract_backfire_m``)."""
    escapes: int = 0
    """whole_body: escape turns about the base commanded (``[zones] escape_deg``)."""
    escapes_stopped: int = 0
    """Escape turns stopped because they carried the arm toward someone (``retract_backfire_m``) or the arm
    refused them."""


@dataclass
class PendingCommand:
    """A motion command on its way: sent, not yet acknowledged."""

    kind: str
    """"stop", "retract" or "move"."""
    seq: int
    sent_s: float
    earlier: tuple[int, ...] = ()
    """The sequence numbers of its earlier sends (it is a retry): a late answer to one of
    them confirms it too, since the arm then did carry it out."""


def _measured(pose) -> np.ndarray:
    """A lifted pose's joints with its ``missing`` ones NaN (``LiftedPose.missing``: guesses, not measured); a
    stand-in pose without that flag gives its joints as they are."""
    missing = getattr(pose, "missing", None)
    # ndarray.any is np.any's reduction without its dispatch (a lifter's flags are an array; a stand-in's may not be);
    # the shared mask of no joint needs none
    if missing is None or missing is NO_JOINTS or not (missing.any() if isinstance(missing, np.ndarray)
                                                        else np.any(missing)):
        return pose.joints_cam_m
    return np.where(np.asarray(missing, bool)[:, None], np.nan, pose.joints_cam_m)


def _rounded(v) -> list[float]:
    """A robot-frame point for the log: metres to 0.1 mm."""
    return [round(x, 4) for x in np.asarray(v, float).reshape(3).tolist()]  # tolist: float(x) of each, at once


def _vec3(v) -> tuple[float, float, float]:
    return tuple(float(x) for x in np.asarray(v, float).reshape(3))


def _stacked(arrays: list) -> np.ndarray:
    """``np.stack(arrays)``: np.array of equal-shape arrays makes the same array in a third of the time (no per-array
    checks); arrays of unequal shapes get np.stack itself (and its error)."""
    shape = arrays[0].shape
    return np.array(arrays) if all(a.shape == shape for a in arrays) else np.stack(arrays)


class RobotLoop:
    """See the module docstring.

    ``calibration``: an ``edge_runtime.robot.calibration.Calibration`` mapping camera-frame
    joints to the robot frame (each skeleton re-anchored on the floor when its
    ``ground_anchor`` is on), or None when the joints given are in the robot frame
    already (the simulator's true joints)."""

    def __init__(self, link: LinkInterface, calibration: CameraToRobot | None = None, zones: ZoneParams = ZoneParams(),
                 tracker: TrackerParams = TrackerParams(), params: LoopParams = LoopParams(),
                 clock: Callable[[], float] = time.monotonic,
                 on_record: Callable[[FrameRecord], None] | None = None):
        if not params.task_waypoints_m:
            raise ValueError("task_waypoints_m: at least one waypoint")
        self.link = link
        self.calibration = calibration
        self.zones = zones
        self.params = params
        self.clock = clock
        self.on_record = on_record
        self.monitor = HazardMonitor(zones, tracker)
        self.counters = LoopCounters()
        self.reactions_s: deque[float] = deque(maxlen=params.records)
        """Each recorded frame that sent a command: keypoints in -> its last command sent (s)."""
        self.link_state = "connecting"
        self.link_error = ""
        self._raised = False  # the last link call raised: retry at link_retry_s
        self._auto_heartbeat = link.heartbeats_itself
        self._waypoint = 0
        self._task_motions: dict[int, tuple] = {}  # _task_target's, per waypoint, for _task_motions_of
        self._task_motions_of: LoopParams | None = None
        self._sent_motion: Motion | None = None
        self._sent_alarm = None
        self._sent_runtime_state = None
        self._retract: Motion | None = None
        self._retract_seq: int | None = None
        self._retract_fallback = False
        self._retract_distance_m = math.inf
        self._retract_q0: np.ndarray | None = None  # the arm's joint angles when the retraction under way began
        self._q0_capsules: tuple | None = None  # (_retract_q0, its capsules): _start_capsules
        self._escape_s = -math.inf  # when this level 2 last planned an escape turn (clock, s)
        self._escaping = False  # the retraction under way is an escape turn
        self._separations: Recent[tuple] = Recent(32)  # _separations_of's memory
        self._move_seq: int | None = None
        self._unreachable = False
        self._last_hb_s = -math.inf
        self._next_retry_s = -math.inf
        self._last_watchdog_fix_s = -math.inf
        self._last_effector: np.ndarray | None = None
        self._last_q: np.ndarray | None = None  # the arm's joint angles as last reported (whole-body separation)
        self._sent_speed: float | None = None  # the speed override the arm acknowledged or was last sent (m/s)
        self._speed_pending: PendingCommand | None = None
        self._last_yaw: float | None = None
        self._seen_state = None  # the link's state report _last_effector, _last_q and _last_yaw were taken from
        self._pending: PendingCommand | None = None
        self._unconfirmed = 0  # motion commands in a row the arm did not acknowledge
        self._retry_of: PendingCommand | None = None  # the unacknowledged command being sent again
        self._resending = False  # the motion now sent is a retry of an unacknowledged one
        self._t_start_s: float | None = None
        self.command_alarm = ""
        """Why the last motion command is not confirmed ("" when it is): the arm may not be doing
        what the runtime asked. Cleared by the next acknowledged one."""
        self.fault = ""
        """Why the loop cannot keep the arm safe through this link ("" while it can): the link
        never came up, or ``ack_retries`` + 1 motion commands in a row were not acknowledged."""

    # -- inputs ---------------------------------------------------------------------------

    def feed_joints(self, joints_m, valid: bool = True, reason: str = "", ids=None,
                    t_in_s: float | None = None, observed=None, unseen: dict | None = None,
                    rays: dict | None = None) -> FrameRecord:
        """One frame of 3D joints: (17, 3) for one worker, (P, 17, 3) for several, (0, 17, 3)
        or None for nobody seen. ``valid``/``reason``: the lifter's verdict; an invalid frame
        stops the arm, except ``no_person`` (nobody detected): that is an empty scene, judged
        like any frame without workers (a worker lost inside a zone holds the arm). ``ids``:
        a stable id per person (default: their index) so each keeps his own tracker.
        ``t_in_s``: when the frame's input arrived (default: now). ``observed`` ((P, 17) bool,
        optional): the joints seen in this frame, for the floor anchoring. ``unseen``: id -> reason
        for people in this frame whose lift is invalid (``HazardMonitor.observe``); ``rays``: id ->
        (17, 3) camera-frame rays of such a person's keypoints (:mod:`edge_runtime.robot.rays`), which
        bound where he is once the calibration puts them in the robot frame."""
        t_in = self.clock() if t_in_s is None else t_in_s
        if not valid and reason.split(":", 1)[0] == NO_PERSON:
            joints_m, valid = None, True
        self.counters.frames += 1
        self._poll_link()
        persons = np.empty((0, 17, 3)) if joints_m is None else np.asarray(joints_m, float)
        if persons.ndim == 2:
            persons = persons[None]
        shaped = persons.ndim == 3 and persons.shape[1:] == (17, 3)
        if self.calibration is not None and shaped and len(persons):
            # a stand-in calibration may take the joints only: pass the mask and the tracker's ids
            # (each person keeps his own floor anchoring) when there are any
            persons = (self.calibration.to_robot(persons) if observed is None and ids is None
                       else self.calibration.to_robot(persons, observed, ids))
        keys = list(range(len(persons))) if ids is None else list(ids)
        people = None
        # the head zones need the head; whole-body separation every joint, or enough of them that the rest is
        # bounded by its bones from those (lifter.enough_joints; hazard.body_spheres)
        if self.zones.separation == "whole_body":
            # everyone showing every joint (the usual frame) shows enough of himself
            enough = shaped and (np.isfinite(persons).all()
                                 or all(enough_joints(f) for f in np.isfinite(persons).all(axis=2)))
        else:
            enough = np.isfinite(persons[:, HEAD, :] if shaped else persons).all()
        if not valid or not shaped or not enough:
            self.counters.invalid += 1
            why = reason if not valid else "non-finite joints" if shaped else f"joints of shape {persons.shape}"
            decision = self.monitor.invalid(t_in, why)
        else:
            self.counters.unseen += len(unseen or ())
            effector = self.effector_m()
            decision = self.monitor.observe(t_in, dict(zip(keys, persons)), effector, self._last_q,
                                            unseen, self._robot_rays(rays), self._backfire_start())
            # the log's per-person beliefs, made once the commands are out (they decide nothing), against the
            # effector the frame was judged with (before the command: its fallback is the last position sent)
            people = (keys, persons, effector)
        return self._act(t_in, decision, record=True, people=people)

    def feed_people(self, lifter: PeopleLifter, t_frame_s: float, people) -> FrameRecord:
        """One frame of tracked people (``Person`` objects with stable ids, from
        ``keypoints.PersonTracker``), each lifted with his own window by ``lifter`` and judged by
        :meth:`feed_poses`. ``t_in_s`` is taken before lifting."""
        t_in = self.clock()
        poses = lifter.push(t_frame_s, people)
        rays = {pid: lifter_rays(lifter.template, person.keypoints)
                for (pid, pose), person in zip(poses, people) if not pose.valid}
        return self.feed_poses(poses, t_in_s=t_in, rays=rays)

    def feed_poses(self, poses, t_in_s: float | None = None, rays: dict | None = None) -> FrameRecord:
        """One frame of lifted people, ``[(id, LiftedPose)]``. The valid ones are judged; one lifted
        invalidly (hidden joints, a lift out of range) is ``unseen`` in this frame: judged by his
        reachable set from his last valid pose and by his keypoints' rays (``rays``: id -> (17, 3)
        camera-frame rays, :func:`edge_runtime.robot.rays.lifter_rays`), or, never lifted validly and
        without rays that bound him, a stop (the hazard module). ``no_person`` (nothing of him
        detected) is simply not there. An empty list is an empty scene."""
        valid = [(pid, p) for pid, p in poses if p.valid]
        unseen = {pid: str(p.reason or "invalid") for pid, p in poses
                  if not p.valid and str(p.reason or "").split(":", 1)[0] != NO_PERSON}
        if not valid:
            return self.feed_joints(None, t_in_s=t_in_s, unseen=unseen, rays=rays)
        return self.feed_joints(_stacked([_measured(p) for _, p in valid]), ids=[pid for pid, _ in valid],
                                t_in_s=t_in_s, observed=_stacked([p.observed for _, p in valid]), unseen=unseen,
                                rays=rays)

    def _robot_rays(self, rays: dict | None) -> dict:
        """Camera-frame keypoint rays (id -> (17, 3)) as :class:`PersonRays` in the robot frame,
        through the calibration (its camera centre, its rotation, and its floor); none without a
        calibration that gives them (the joints are in the robot frame already: no camera known)."""
        cal = self.calibration
        floor = getattr(getattr(cal, "params", None), "floor_y_m", None)
        if not rays or cal is None or floor is None or not hasattr(cal, "apply"):
            return {}
        origin = np.asarray(cal.apply(np.zeros(3)), float)
        out = {}
        for pid, r in rays.items():
            d = np.asarray(cal.apply(np.asarray(r, float)), float) - origin
            n = np.linalg.norm(d, axis=1, keepdims=True)
            out[pid] = PersonRays(origin, d / np.where(n > 1e-12, n, np.nan), float(floor))
        return out

    def _people_of(self, keys, persons: np.ndarray, eff: np.ndarray) -> Callable[[], list[dict]]:
        """:meth:`_people` of this frame, for when the record's ``people`` is read: of copies of the frame's
        joints and effector and of its head estimates (the monitor replaces its dict at each frame), so a
        record read later still says what this frame believed."""
        persons, eff, estimates = np.array(persons, float), np.array(eff, float), self.monitor.estimates
        return lambda: self._people(keys, persons, eff, estimates)

    def _people(self, keys, persons: np.ndarray, eff: np.ndarray, estimates: dict | None = None) -> list[dict]:
        """What the runtime believes about each person (robot frame), the end effector at ``eff``:
        FrameRecord.people. ``estimates``: the monitor's head estimates of the frame (default: its last)."""
        estimates = self.monitor.estimates if estimates is None else estimates
        persons = np.asarray(persons, float)
        # everyone at once (numpy's per-call overhead is the cost of a frame's few people; each row's norm is
        # the per-person call's), the nearest joint as np.nanargmin finds it (NaN taken as +inf, then the
        # first smallest; a person with no finite gap gets joint 0 as before)
        gaps = np.linalg.norm(persons - eff, axis=-1)                                    # (P, 17)
        nearest = np.argmin(np.where(np.isnan(gaps), np.inf, gaps), axis=1)
        rows = np.arange(len(persons))
        # tolist: float(x) of each, at once; rounded as _rounded rounds
        heads, points = persons[:, HEAD].tolist(), persons[rows, nearest].tolist()
        out = []
        for key, head, j, point, gap in zip(keys, heads, nearest.tolist(), points, gaps[rows, nearest].tolist()):
            est = estimates.get(key)
            out.append({"id": key.item() if isinstance(key, np.generic) else key,
                        "head_robot_m": [round(x, 4) for x in head],
                        "predicted_head_m": None if est is None else _rounded(est.predicted_m),
                        "nearest_joint": JOINTS[j], "nearest_point_m": [round(x, 4) for x in point],
                        "nearest_distance_m": round(gap, 4)})
        return out

    def feed_lifted(self, out: LiftedPose, t_in_s: float | None = None) -> FrameRecord:
        """A StreamingLifter output (``joints_cam_m`` (17, 3), ``valid``, ``reason``), judged
        as in ``feed_joints``."""
        return self.feed_joints(out.joints_cam_m, bool(out.valid), str(out.reason or ""), t_in_s=t_in_s)

    def feed_keypoints(self, lifter: StreamingLifter, t_frame_s: float, keypoints) -> FrameRecord:
        """One frame of 2D keypoints (one person, or None for nobody) through ``lifter``
        (``StreamingLifter.push(t_s, keypoints)``). The frame's ``t_in_s`` is taken before
        lifting, so the reaction time includes the lifter."""
        t_in = self.clock()
        return self.feed_lifted(lifter.push(t_frame_s, keypoints), t_in_s=t_in)

    def tick(self) -> None:
        """A control cycle: link poll, staleness, task progress, heartbeat."""
        now = self.clock()
        self._poll_link()
        self._act(now, self.monitor.check(now), record=False)
        due = now - self._last_hb_s >= self.params.heartbeat_period_s - 1e-6
        if not self._auto_heartbeat and not self._raised and due and self._call(self.link.heartbeat) is not None:
            self.counters.heartbeats += 1
            self._last_hb_s = now

    # -- state ----------------------------------------------------------------------------

    def effector_m(self) -> np.ndarray:
        """The end effector's robot-frame position: the controller's last report, else the
        last position commanded, else the first task waypoint."""
        if self._last_effector is not None:
            return self._last_effector
        if self._sent_motion is not None and self._sent_motion.position_m is not None:
            return np.array(self._sent_motion.position_m)
        return np.array(self.params.task_waypoints_m[0], float)

    def _reason(self) -> str:
        """Why the arm does what it does (``status()["reason"]``)."""
        m = self.monitor
        return "retract_unreachable" if self._unreachable and m.state == State.LEVEL2 else m.reason

    def status(self) -> dict:
        m = self.monitor
        self.counters.stale = m.stale_events
        self.counters.bounds_refused = m.bounds_refused
        return {"state": m.state.name, "reason": self._reason(), "link": self.link_state,
                "link_error": self.link_error, "command_alarm": self.command_alarm, "fault": self.fault,
                "waypoint": self._waypoint, **vars(self.counters)}

    # -- internals ------------------------------------------------------------------------

    def _poll_link(self) -> None:
        """Read the controller's state (end effector, watchdog, answers) and the link's health."""
        if self._t_start_s is None:
            self._t_start_s = self.clock()
        self._check_link_up()
        if self._raised:
            if self.clock() < self._next_retry_s or self._call(self.link.heartbeat) is None:
                return
            self._raised = False
        try:
            self.link.poll()
        except Exception as e:  # noqa: BLE001 - a link that raises is a lost link
            self._link_raised("poll", e)
            return
        self._check_health()
        state = self.link.state
        if state is None:
            return
        if state is not self._seen_state:  # a new report (the same one, as in most frames and ticks, gives the same)
            self._seen_state = state
            # np.isfinite(...).all() of a few numbers, on Python floats (a new state comes 100 times a second)
            pos = np.asarray(state.ee_position_m, float)
            if all(map(math.isfinite, pos.ravel().tolist())):
                self._last_effector = pos.reshape(3)
            q = np.asarray(state.joint_positions_rad, float)
            self._last_q = q.reshape(7) if q.size == 7 and all(map(math.isfinite, q.ravel().tolist())) else None
            self._last_yaw = float(state.yaw_rad) if math.isfinite(state.yaw_rad) else None
        now = self.clock()
        if state.watchdog and self._sent_motion is not None and self._sent_motion.kind is MotionKind.MOVE \
                and now - self._last_watchdog_fix_s >= self.params.link_retry_s:
            self._last_watchdog_fix_s = now  # the controller latched a stop: send everything again
            self._sent_motion = self._sent_alarm = None
        self._check_ack(now)
        self._check_speed_ack(now)
        if self._retract_seq is not None and self._refused(self._retract_seq):
            self._retract_refused()
        if self._move_seq is not None and self._refused(self._move_seq):
            self._skip_waypoint()

    # -- acknowledgements ---------------------------------------------------------------------

    def _expect_ack(self, kind: str, seq) -> None:
        """Motion command ``kind`` ("stop", "retract", "move") went out as ``seq``: wait for the
        arm's answer (``_check_ack``)."""
        retry_of, self._retry_of = self._retry_of, None
        if isinstance(seq, int) and seq > 0:
            earlier = (retry_of.seq, *retry_of.earlier) if retry_of is not None and retry_of.kind == kind else ()
            self._pending = PendingCommand(kind, seq, self.clock(), earlier)

    def _check_ack(self, now: float) -> None:
        """The last motion command: acknowledged (the command alarm clears), or not confirmed:
        no answer within ``ack_timeout_s`` (it is sent again), a stop refused (sent again after
        ``ack_timeout_s``) or a move or retraction refused (their own handling picks the next
        waypoint or the fallback retraction). Each is counted and raises the command alarm;
        more than ``ack_retries`` in a row without an acknowledgement is a ``fault``."""
        p = self._pending
        if p is None:
            return
        if self.link_state != "ok":  # nothing can answer: the arm's watchdog holds it; re-sent on reconnection
            p.sent_s = now
            return
        result = self.link.result(p.seq)
        if result == "ok" or any(self.link.result(seq) == "ok" for seq in p.earlier):
            self.counters.acked += 1
            self._pending, self._unconfirmed, self.command_alarm = None, 0, ""
            return
        handled = result is not None and p.kind != "stop"
        if not handled and now - p.sent_s < self.params.ack_timeout_s:
            return
        self._pending = None
        if result is None:
            self.counters.unacked += 1
            why = f"not acknowledged within {self.params.ack_timeout_s * 1000:.0f} ms"
        else:
            self.counters.refused += p.kind == "stop"  # a refused move or retraction is counted by _refused
            why = f"answered {result!r}"
        self._unconfirmed += 1
        self.command_alarm = f"{p.kind} (seq {p.seq}) {why}"
        if self._unconfirmed > self.params.ack_retries:
            self.fault = f"the arm did not confirm {p.kind}: {why}, {self._unconfirmed} commands in a row"
            return
        if not handled:
            self.counters.retries += 1
            self._sent_motion = None  # _act sends the motion again, as a retry
            self._resending, self._retry_of = True, p

    def _check_speed_ack(self, now: float) -> None:
        """The last speed override: acknowledged, or (no answer within ``ack_timeout_s``, or
        refused) counted, alarmed and sent again like a motion command."""
        p = self._speed_pending
        if p is None or self.link_state != "ok":
            return
        result = self.link.result(p.seq)
        if result == "ok":
            self.counters.acked += 1
            self._speed_pending = None
            return
        if result is None and now - p.sent_s < self.params.ack_timeout_s:
            return
        self._speed_pending, self._sent_speed = None, None  # _act sends it again
        self.counters.unacked += result is None
        self.counters.refused += result is not None
        self.counters.retries += 1
        self.command_alarm = f"speed (seq {p.seq}) " + ("not acknowledged" if result is None else f"answered {result!r}")

    def _check_link_up(self) -> None:
        """No state from the arm ``link_up_timeout_s`` after the start: the link never came up."""
        if self.link_state == "connecting" and not self.fault \
                and self.clock() - self._t_start_s > self.params.link_up_timeout_s:
            self.fault = (f"no state from the arm in {self.params.link_up_timeout_s:g} s"
                          + (f" ({self.link_error})" if self.link_error else ""))

    def _skip_waypoint(self) -> None:
        """A task waypoint the arm cannot reach (counted in ``refused``): go on to the next."""
        self._move_seq = None
        self._waypoint = (self._waypoint + 1) % len(self.params.task_waypoints_m)

    def _refused(self, seq: int) -> bool:
        """Did the controller refuse command ``seq``? (counted)"""
        refused = self.link.refused(seq)
        self.counters.refused += refused
        return refused

    def _check_health(self) -> None:
        ok = self.link.link_ok
        if ok and self.link_state != "ok":
            self.link_state, self.link_error = "ok", ""
            self._sent_motion = self._sent_alarm = self._sent_speed = None  # (re)connected: send the current commands
        elif not ok:
            if self.link_state == "ok":
                self.counters.link_errors += 1
                self.link_state = "lost"
            self.link_error = str(self.link.last_error or "no state from the robot yet")

    def _link_raised(self, name: str, e: Exception) -> None:
        if self.link_state != "lost":
            self.counters.link_errors += 1
        self.link_state, self.link_error = "lost", f"{name}: {type(e).__name__}: {e}"
        self._raised = True
        self._next_retry_s = self.clock() + self.params.link_retry_s

    def _desired_motion(self, state: State, decision: Decision) -> Motion:
        if state == State.NORMAL:
            self._end_level2()
            return self._task_motion()
        if state == State.LEVEL2:
            escape = self._escape(decision)
            if escape is not None or self._retract is None or self._retract_again(decision):
                self._retract = escape or self._retract_motion(decision)
                self._escaping = escape is not None
                self._retract_fallback = False
                self._retract_distance_m = decision.distance_m
                self._retract_q0 = self._last_q
            elif self._retract_backfires():
                self.counters.backfired += 1
                if self._escaping:
                    # the turn carried the arm toward someone (the controller's IK need not turn the first
                    # joint alone, or he moved): stopped where it is, planned again from there (_escape)
                    self.counters.escapes_stopped += 1
                    self._retract, self._escaping = STOP, False
                else:
                    # the straight way toward the base once (the unreachable retraction's fallback), then a
                    # stop. The tool keeps the given-up retraction's yaw: holding the yaw it had on the way
                    # gave the controller another fold, which swung the elbow out and stopped the arm half
                    # folded between two workers passing it (hard:200 seed 13 hard_023, seed 11 hard_106)
                    self._retract = STOP if self._retract_fallback else self._radial_retract()
                    self._retract_fallback, self._retract_q0 = True, self._last_q
            return self._retract
        self._end_level2()
        return STOP

    def _end_level2(self) -> None:
        """Level 2 is over: no retraction, escape or refusal carries over to the next one."""
        self._retract, self._retract_seq, self._unreachable, self._escape_s = None, None, False, -math.inf
        self._escaping = False

    def _task_motion(self) -> Motion:
        p = self.params
        target = p.task_waypoints_m[self._waypoint]
        s = self._sent_motion
        if (s is not None and s.kind is MotionKind.MOVE and s.position_m == tuple(target)
                and self._last_effector is not None
                and _norm3(self._last_effector - self._task_target(p)[1]) <= p.waypoint_tolerance_m):
            self._waypoint = (self._waypoint + 1) % len(p.task_waypoints_m)
        return self._task_target(p)[0]

    def _task_target(self, p: LoopParams) -> tuple[Motion, np.ndarray]:
        """The current waypoint's move and its position as an array, each made once per waypoint (a frozen value,
        compared by value; an array subtracted as the waypoint's tuple would be, without converting it: the
        control tick asks for them 100 times a second)."""
        if self._task_motions_of is not p:  # (for these parameters)
            self._task_motions, self._task_motions_of = {}, p
        made = self._task_motions.get(self._waypoint)
        if made is None:
            target = p.task_waypoints_m[self._waypoint]
            made = self._task_motions[self._waypoint] = (
                Motion(MotionKind.MOVE, _vec3(target), p.task_pitch_rad, p.task_yaw_rad), np.array(target, float))
        return made

    def _retract_again(self, decision: Decision) -> bool:
        """Retract once more when the last retraction is done, the worker has come
        ``re_retract_m`` closer since it began and he still keeps coming at the arm where it is now
        (``Decision.coming``), and there is still room to go (the new
        target differs from where the hand is)."""
        r = self._retract
        if r is None or r.kind is not MotionKind.RETRACT or self._last_effector is None or decision.head is None:
            return False
        done = _norm3(self._last_effector - r.position_m) <= self.params.waypoint_tolerance_m
        closer = decision.distance_m < self._retract_distance_m - self.params.re_retract_m
        # a worker who no longer keeps coming at the retracted arm (he passes it, or stands) is waited
        # for where it is: a repeat Eq. 6 step along his walk made the hand follow a passing worker
        # round the base (random:200 seed 1, random_183: 0.104 m)
        if not (done and closer and decision.coming):
            return False
        nxt = self._retract_motion(decision)
        return nxt.kind is MotionKind.RETRACT and _norm3(np.subtract(nxt.position_m, r.position_m)) > 0.05

    def _escape(self, decision: Decision) -> Motion | None:
        """whole_body: someone within ``reach_retract_m`` of an arm whose retraction (or escape turn) is
        done (Eq. 6 takes it no further: it stops short of the base's axis) or that was stopped makes
        the arm turn about its base to where it is clearest of everyone accounted for, on its own
        model (:func:`edge_runtime.robot.hazard.plan_escape_turn`: the links from the joint angles it
        reports, the end effector alone before it has reported any): a worker who stands at the cell
        and reaches for the tool reached the folded arm in front of him (hard:200 seed 3, hard_101
        0.033 m, hard_195 0.061 m). One command turns it at most ``escape_turn_max_deg`` toward the planned
        end; planned again while level 2 lasts, at most every ``escape_replan_s`` (a plan that found
        nothing too: each costs milliseconds of the frame). None otherwise (nothing gains
        ``escape_min_gain_m``, or someone known only by his rays is within reach:
        :meth:`edge_runtime.robot.hazard.HazardMonitor.escape_people`)."""
        r, z, p = self._retract, self.zones, self.params
        if (z.separation != "whole_body" or z.escape_deg <= 0 or r is None or self._unreachable
                or self._last_effector is None or self._last_yaw is None or decision.head is None
                or decision.distance_m > z.reach_retract_m):
            return None
        # after a retraction or turn that is done, or one that was stopped (it carried the arm toward someone)
        if r.kind is MotionKind.RETRACT and _norm3(self._last_effector - r.position_m) > p.waypoint_tolerance_m:
            return None
        now = self.clock()
        if now - self._escape_s < p.escape_replan_s:
            return None
        self._escape_s = now
        q = self._last_q
        caps = arm_capsules(q) if q is not None else effector_capsule(self._last_effector)
        most = math.radians(p.escape_turn_max_deg)
        a, b, radii = caps  # the arm's farthest point from the base's axis, and how far one turn carries it
        arm_radius_m = float(np.linalg.norm(ground(np.vstack([a, b])), axis=1).max() + radii.max())
        people = self.monitor.escape_people(sweep_m=2.0 * arm_radius_m * math.sin(0.5 * most))
        if not people:
            return None
        turn = plan_escape_turn(caps, people, None if q is None else float(q[0]), p.escape_step_deg,
                                p.escape_min_gain_m, p.escape_dip_m, z.escape_deg, z.reach_retract_m,
                                self.monitor.escape_separations_m(caps))
        if turn is None:
            return None
        self.counters.escapes += 1
        return self._retraction(turned_retraction(self._last_effector, self._last_yaw, min(max(turn, -most), most)))

    def _retract_backfires(self) -> bool:
        """Has the retraction (or escape turn) under way brought the arm ``retract_backfire_m`` closer to anyone
        within the retraction's reach, by its own motion? (Everyone the monitor accounts for, at his
        last valid body, against the arm where it is now and where the retraction began.)"""
        start_caps = self._backfire_start()
        if start_caps is None:
            return False
        z, q = self.zones, self._last_q
        reach = z.body_retract_distance_m + z.retract_lead_s * z.lost_person_speed_mps
        people = self.monitor.people_spheres()
        if not people:
            return False
        # Python floats (the same doubles) and plain loops: a tick's check is a few comparisons, which numpy's calls
        # (or generators) would outweigh
        now = self._separations_of(people, arm_capsules(q))
        start = None
        for k, d in enumerate(now):
            if d < reach:
                if start is None:
                    start = self._separations_of(people, start_caps)
                if d < start[k] - self.params.retract_backfire_m:
                    return True
        return False

    def _backfire_start(self):
        """The capsules of where the retraction under way began (:meth:`_start_capsules`) when
        :meth:`_retract_backfires` has one to check, else None. A frame hands them to the monitor, which measures
        everyone's separation from them in its own pass (``HazardMonitor.observe``'s ``also_capsules``), so the
        frame's backfire check finds them measured (the same numbers)."""
        r, q0, q = self._retract, self._retract_q0, self._last_q
        if r is None or r.kind is not MotionKind.RETRACT or q0 is None or q is None \
                or self.zones.separation != "whole_body":
            return None
        if self._retract_fallback and not self._escaping and not self.params.radial_retract_stops:
            return None  # the straight retraction toward the base runs to its end
        return self._start_capsules(q0)

    def _start_capsules(self, q0: np.ndarray):
        """:func:`arm_capsules` of ``q0``, where the retraction under way began, kept while it lasts: the same
        capsules (the same arrays) at every check, so :meth:`_separations_of` remembers their separations from
        the same bodies however many new arm states have gone through arm_capsules' small memory since."""
        kept = self._q0_capsules
        if kept is None or kept[0] is not q0:
            kept = self._q0_capsules = (q0, arm_capsules(q0))
        return kept[1]

    def _separations_of(self, people: list, caps) -> list[float]:
        """:meth:`edge_runtime.robot.hazard.HazardMonitor.people_separations_m`: the separations of everyone's body
        spheres (``people``, the monitor's :meth:`~edge_runtime.robot.hazard.HazardMonitor.people_spheres`, made
        once per frame) from the arm's capsules (:func:`edge_runtime.robot.hazard.arm_capsules`'s, the same for
        the same joint angles), all read-only: remembered, since the backfire check asks at every tick (100 Hz)
        for the same bodies (30 Hz) against the same few arm states (where the retraction began, where the arm
        is); everyone in one call (numpy's per-call overhead, not the arithmetic, is the cost)."""
        key = (*map(id, people), id(caps))
        hit = self._separations.get(key)
        if hit is None:
            # holding them keeps their ids unique while remembered: the same ids are the same objects
            hit = self._separations.put(key, (people, caps, self.monitor.people_separations_m(caps).tolist()))
        return hit[2]

    def _retract_motion(self, decision: Decision) -> Motion:
        """Eq. 6's retraction from the effector (:func:`edge_runtime.robot.hazard.eq6_retraction`)."""
        if decision.head is None:  # level 2 held without a current head (should not happen): stop
            return STOP
        return self._retraction(eq6_retraction(self.effector_m(), decision.head, self.zones,
                                               self.params.retract_limits, self._last_yaw, self._held_yaw()))

    def _radial_retract(self) -> Motion:
        """The fallback retraction, straight toward the base's axis
        (:func:`edge_runtime.robot.hazard.radial_retraction`)."""
        return self._retraction(radial_retraction(self.effector_m(), self.zones, self.params.retract_limits,
                                                  self._last_yaw, self._held_yaw()))

    def _held_yaw(self) -> float | None:
        """The tool yaw of the retraction under way (a repeat one keeps it), or None."""
        r = self._retract
        return r.yaw_rad if r is not None and r.kind is MotionKind.RETRACT else None

    def _retraction(self, r: Retraction) -> Motion:
        return Motion(MotionKind.RETRACT, _vec3(r.position_m), self.params.task_pitch_rad, r.yaw_rad)

    def _retract_refused(self) -> None:
        """The controller (or the link) refused the retraction: try the radial fallback once,
        then stop (reason ``retract_unreachable``). A refused escape turn is a stop, and the turn is
        planned again from there (:meth:`_escape`): it is not the retraction that got nowhere."""
        self.counters.unreachable += 1
        self._retract_seq = None
        if self._escaping:
            self.counters.escapes_stopped += 1
            self._retract, self._escaping = STOP, False
        elif self._retract_fallback:
            self._unreachable = True
            self._retract = STOP
        else:
            self._retract_fallback = True
            self._retract = self._radial_retract()

    def _act(self, t_s: float, decision: Decision, record: bool, people: tuple | None = None) -> FrameRecord | None:
        """What ``decision`` asks of the arm, sent (beacon, speed, motion); then, with ``record``, the frame's
        FrameRecord, its ``people`` made from ``people`` ((keys, persons, effector) for :meth:`_people`, or None)
        when first read, after the commands are on the link: the log is not on the way from keypoints to command."""
        state = decision.state
        motion = self._desired_motion(state, decision)
        alarm = self.monitor.alarm(state)
        t_cmd, sent = None, None
        # the beacon first: the controller reports the answer to its latest command only,
        # and the motion's answer (unreachable?) is the one that matters
        if alarm != self._sent_alarm and not self._raised \
                and self._call(self.link.set_alarm, alarm.light, alarm.tone_hz, alarm.tone_db) is not None:
            self._sent_alarm = alarm
            t_cmd, sent = self.clock(), "alarm"
        # the speed before the motion: a retraction must not crawl at the approach's slow speed
        speed = self._desired_speed(state, decision)
        if speed is not None and speed != self._sent_speed and not self._raised and self._send_speed(speed):
            t_cmd, sent = self.clock(), "speed"
        if motion != self._sent_motion and not self._raised and self._send_motion(motion):
            t_cmd, sent = self.clock(), motion.kind.value
        self._report_runtime_state(state)
        if not record:
            return None
        rec = FrameRecord(t_s, t_cmd, state.name, self._reason(), decision.distance_m, sent,
                          None if people is None else self._people_of(*people))
        if t_cmd is not None:
            self.reactions_s.append(t_cmd - t_s)
        if self.on_record:
            self.on_record(rec)
        return rec

    def _desired_speed(self, state: State, decision: Decision) -> float | None:
        """The hand's speed limit (m/s) to command, or None to leave it: only with whole-body
        speed scaling; NORMAL at the decision's share of full speed, a retraction at full speed,
        and a stop leaves the limit where it is (the arm is held anyway)."""
        z = self.zones
        if z.separation != "whole_body" or not z.speed_scaling:
            return None
        if state == State.NORMAL:
            return round(decision.speed_scale * z.iso_robot_speed_mps, 4)
        return z.iso_robot_speed_mps if state == State.LEVEL2 else None

    def _send_speed(self, limit_mps: float) -> bool:
        seq = self._call(self.link.set_speed, limit_mps)
        if seq is None or seq is INVALID:
            return False
        self.counters.speed_changes += 1
        self._sent_speed = limit_mps
        if isinstance(seq, int) and seq > 0:
            self._speed_pending = PendingCommand("speed", seq, self.clock())
        return True

    def _send_motion(self, motion: Motion) -> bool:
        c = self.counters
        retry, self._resending = self._resending, False
        if motion.kind is MotionKind.STOP:
            seq = self._call(self.link.stop)
            ok = seq is not None
            c.stops += ok and not retry
            self._move_seq = None
            self._expect_ack("stop", seq)
        else:
            moving = self._sent_motion is not None and self._sent_motion.kind is MotionKind.MOVE
            if motion.kind is MotionKind.MOVE and not moving and self._call(self.link.resume) is None:
                return False
            send = self.link.move_to if motion.kind is MotionKind.MOVE else self.link.retract
            seq = self._call(send, motion.position_m, pitch_rad=motion.pitch_rad, yaw_rad=motion.yaw_rad)
            ok = seq is not None
            self._expect_ack(motion.kind.value, seq)
            if motion.kind is MotionKind.RETRACT:
                c.retracts += ok and not retry
                self._retract_seq, self._move_seq = seq, None
                if seq is INVALID:  # refused before it left: the fallback now
                    self._retract_refused()
                    return self._send_motion(self._retract)
            else:
                c.moves += ok
                self._move_seq = seq
                if seq is INVALID:  # a waypoint the link will not take: the next one
                    self._skip_waypoint()
        if ok:
            self._sent_motion = motion
        return ok

    def _call(self, command: Callable, *args, **kwargs):
        """``command`` (a method of the link) called: its result, ``INVALID`` when the link
        refused the arguments (ValueError), or None when it raised (the link is then lost)."""
        try:
            result = command(*args, **kwargs)
        except ValueError:
            self.counters.refused += 1
            return INVALID
        except Exception as e:  # noqa: BLE001 - any link failure is a lost link, never a crash
            self._link_raised(command.__name__, e)
            return None
        self.counters.commands += 1
        return result

    def _report_runtime_state(self, state: State) -> None:
        """What the link's heartbeat says about the runtime: degraded while in FAULT."""
        want = "degraded" if state == State.FAULT else "running"
        if want != self._sent_runtime_state:
            self.link.set_runtime_state(want)
            self._sent_runtime_state = want
