"""The robot cycle at 30 Hz: keypoints in -> commands on the CAN link, in real time, in a child process.

``edge_runtime.robot.loop.RobotLoop`` is driven as ``python -m edge_runtime robot`` drives it,
with the shipped box configuration (``config.load(None)``: ``[zones]``, ``[tracker]``,
``[robot_loop]``, ``[lifter]``, ``[people]``, ``[calibration]``): a camera frame every 1/30 s
(the frame's keypoints of everyone in view -> ``PersonTracker.update`` -> ``RobotLoop.feed_people``,
which lifts each person with his own window of the shipped int8 lifter on 1 thread,
``PeopleLifter``) and a control ``tick()`` every 10 ms, each on an absolute deadline with sleeps
in between (``RobotConfig.schedule`` "grid", a tick before a frame due at the same instant, so one
frame in three waits for one; "live": the ticks paced by the frames as the robot command's camera
driver paces them, a frame first and its tick right after, :class:`_LiveSchedule`). The people are two simulated workers made by the parent (:mod:`bench.robot_scenario`):
one walks up to the arm, stands working within its reach and walks away, again and again, the
other walks across the cell and back, so that the runtime sends every kind of command the shipped
configuration sends: speed overrides (speed-and-separation monitoring), alarms, stops,
retractions, escape turns about the base and resumes.

The camera stands 7 m in front of the base looking along -z. Its keypoints come as the robot command
gets them on a box (:func:`box_camera`): in ``[camera] keypoint_format`` order (shipped: COCO), seen by
the ``[camera] intrinsics`` camera or else a 100-degree 1280 x 720 one, so the tracker and the lifter
convert to H36M and to the lifter's canonical camera as they do there. The camera -> robot
transform is the simulated camera's known pose, as a :class:`Calibration` with the box's
``[calibration]`` settings (its floor anchoring runs as on the box). Without a shipped lifter
the simulator's robot-frame joints are fed directly (``feed_joints``), and the row says so.

The link is the product's: :class:`edge_runtime.robot.link.can.CanRobotLink` on python-can's
in-process ``virtual`` bus (no network), frames encoded by the product's codec (cantools,
``robot_link.dbc``, E2E Profile 1); the bus stamps when each ``send()`` returned
(:class:`bench.arm_echo.StampedBus`). A minimal arm (:class:`bench.arm_echo.ArmEcho`) answers
every command and reports its state at 100 Hz in its own slots, :data:`ARM_OFFSET_S` after each
tick (outside the timed frames and ticks), so that, as on a box, some frames find a state to decode
in their ``poll()`` before they command (with the frames locked to the ticks here, one in three)
and every tick finds one; its CPU time is not counted in the runtime's share.

``robot_30hz``
    per camera frame, keypoints handed to the tracker -> ``feed_people`` returned
    (p50/p99/mean us); CPU share of one core over the run (frames and ticks, the arm stand-in's
    own work left out; ``cpu_share_with_arm_pct`` with it); deadline misses (a frame whose
    processing ends after the next frame is due); ``start_late_p99_us``: how late frames start
    after their due time (a tick before them, the sleep's wake-up); peak resident memory; the
    loop's command counters.
``robot_reaction``
    for the frames that caused a command: keypoints in (the loop picks the frame up) -> the
    ``send()`` of the frame's last command frame on the bus returned; overall and per kind of command (``by_kind``: n, p50,
    p99, max; :data:`KINDS`). A p99 from fewer than :data:`P99_MIN_N` samples is labelled as such
    (``p99_note``). ``from_feed``: the same frames timed from ``feed_people``'s own ``t_in_s``,
    after tracking (what ``python -m edge_runtime robot`` reports as a frame's reaction);
    ``frame_cpu``: their CPU time (the thread's, the whole frame), which preemption by other
    processes does not lengthen. ``from_due``: the same frames from when their keypoints were due
    (the frame's schedule time), so a tick or an earlier frame it waited for counts: the issue's
    "keypoints in -> command on the link" is judged on this one (``judged_on``).
    ``scenario``: :data:`SCENARIO` (``python -m bench --compare`` does not compare rows of another).
``robot_tick_command``
    the same for the control ticks that sent a command, from the tick's start: escape turns are
    planned again on a timer (``[robot_loop] escape_replan_s``), which runs out as often in a tick
    as in a frame, and a reached waypoint's next move goes out in a tick. Not keypoints -> link,
    but the same cost on the same thread.
"""
from __future__ import annotations

import importlib.util
import math
import os
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path

import numpy as np

from bench.loops import not_available
from bench.robot_scenario import CAMERA_FROM_ROBOT, CAMERA_POSITION_M, FRAME_RATE_HZ, prepare_workers
from bench.timing import CpuShare, peak_rss_mb, sleep_until, summarize
from edge_runtime.robot.link.base import LinkInterface

TICK_RATE_HZ = 100.0
ARM_OFFSET_S = 0.005
"""The arm's state goes out at 100 Hz this long after each tick: half a tick period, as a box's arm
runs on its own clock and its frames arrive at any phase of the runtime's ticks."""
SCENARIO = "two_workers_can_v2"
"""What the robot rows measure; changed whenever their meaning changes (v1: the two workers and the CAN link
with the arm answering right before each tick, session 14; before: one walker and a recording link), so that
``--compare`` does not call a change of method a regression."""
P99_MIN_N = 100
"""A p99 needs at least this many samples to say anything (one in a hundred)."""
KINDS = ("speed", "alarm", "stop", "retract", "escape", "resume", "move")
"""Kinds of command a frame can cause (the frame's last command; "escape": a retraction that is an
escape turn about the base; "resume": a task move after a stop or retraction, with its resume)."""
__all__ = ["ARM_POSTURE_RAD", "KINDS", "P99_MIN_N", "SCENARIO", "RobotConfig", "command_row", "lifter_entry",
           "measure_robot", "robot_rows", "run_cycle",
           # re-exported for bench/holds.py
           "CAMERA_FROM_ROBOT", "CAMERA_POSITION_M", "FRAME_RATE_HZ", "prepare_workers"]


@dataclass(frozen=True)
class RobotConfig:
    worker_npz: str
    """joints_robot_m (T, P, 17, 3) at 30 Hz; keypoints_px (T, P, 17, 3) when a lifter is shipped, seen by
    :func:`box_camera` (:func:`bench.robot_scenario.prepare_workers`)."""
    seconds: float = 300.0
    """Length of the real-time run (s)."""
    assets: str = ""
    """Assets directory ('' = the shipped ones)."""
    lifter: str = ""
    """Lifter manifest precision to run ('' = none shipped: feed 3D joints)."""
    arm_posture_rad: tuple = ()
    """The arm stand-in's working posture (7 joint angles; () = :data:`ARM_POSTURE_RAD`): the
    parent solves it on the task's first waypoint."""
    simulated: bool = False
    """Jump from deadline to deadline on a simulated clock instead of sleeping (tests: the same
    scenario and commands in a fraction of the time; its timings mean nothing)."""
    zones: dict = field(default_factory=dict)
    """``[zones]`` settings to use instead of the shipped ones (tests: e.g. ``stop_time_scales``)."""
    schedule: str = "grid"
    """How frames and ticks interleave (:data:`SCHEDULES`): "grid", the frames and ticks on fixed grids, a tick
    before a frame due at the same instant (:func:`_schedule`); "live", as the robot command's camera driver
    runs them (:class:`_LiveSchedule`)."""


def lifter_entry(entries: list[dict], precision: str = "int8") -> dict | None:
    """The shipped lifter of ``precision`` (or any lifter), or None."""
    lifters = [e for e in entries if e.get("arch") == "lifter"]
    return next((e for e in lifters if e["precision"] == precision), lifters[0] if lifters else None)


class _KnownTransform:
    """camera -> robot frame by the simulated camera's known pose (stands in for a Calibration)."""

    def to_robot(self, joints_cam_m, observed=None, ids=None) -> np.ndarray:
        return np.asarray(joints_cam_m, float) @ CAMERA_FROM_ROBOT + np.asarray(CAMERA_POSITION_M)


ARM_POSTURE_RAD = (0.0, -0.6, 0.0, 1.2, 0.0, 0.5, 0.0)
"""The joint angles the timed link reports: an arm at work, so that every frame's whole-body
separation measures against the arm's links (not the end effector alone)."""


class _TimedLink(LinkInterface):
    """A robot link that accepts every command and records when the last call returned.
    Its state is one fixed arm posture; every command is acknowledged at once (so the loop
    never re-sends one as unacknowledged), and the loop sends the heartbeats."""

    state = None
    link_ok = True
    heartbeats_itself = False

    def __init__(self):
        from dataclasses import replace

        from edge_runtime.robot.hazard import arm_points_m
        from edge_runtime.robot.link.protocol import blank_state

        q = np.array(ARM_POSTURE_RAD)
        self.state = replace(blank_state(), joint_positions_rad=q, ee_position_m=arm_points_m(q)[-2])
        self.last_call_s = 0.0
        self.calls = 0

    def _done(self, *args, **kwargs) -> int:
        self.calls += 1
        self.last_call_s = time.perf_counter()
        return self.calls  # the command's sequence number

    move_to = retract = stop = resume = set_alarm = set_speed = heartbeat = _done

    def poll(self) -> None:
        return None

    def result(self, seq: int) -> str | None:
        return "ok" if 0 < seq <= self.calls else None

    def set_runtime_state(self, state: str) -> None:
        """Nobody receives the heartbeat's runtime state here."""


TICK, ARM = -1, -2
"""Schedule slots that are not frames: a control tick, the arm stand-in's state."""
SCHEDULES = ("grid", "live")
"""``RobotConfig.schedule``'s values."""


def _schedule(seconds: float) -> list[tuple[float, int]]:
    """(due time from the start in s, frame index, or :data:`TICK` / :data:`ARM`), in time order (a tick
    before a frame due at the same instant)."""
    frames = [(k / FRAME_RATE_HZ, k) for k in range(int(seconds * FRAME_RATE_HZ))]
    ticks = [(j / TICK_RATE_HZ, TICK) for j in range(int(seconds * TICK_RATE_HZ))]
    arm = [(j / TICK_RATE_HZ + ARM_OFFSET_S, ARM) for j in range(int(seconds * TICK_RATE_HZ))]
    return sorted(frames + ticks + arm)


class _LiveSchedule:
    """Frames and ticks as ``edge_runtime/robot/command.py``'s ``_live_frames`` runs them on a box with a
    camera: a frame is taken the moment it is due (the camera's reader thread queues it; the driver waits in
    ``q.get(timeout=TICK_S)``), a tick follows every frame at once, and another comes ``TICK_S`` after a tick
    ended when no frame came first. So ticks are paced by the frames, not by a clock of their own, and a
    frame waits for a tick only when it falls due while one runs (as on the box). The camera (1/30 s) and the
    arm (100 Hz, :data:`ARM_OFFSET_S` after each 10 ms) keep their own clocks. Iterate for (due time from the
    start in s, frame index, or :data:`TICK` / :data:`ARM`) and call :meth:`done` after each frame and tick
    with when it ended (s from the start); a slot due at once is a frame first, as a queued frame is in
    ``q.get``. Not the product's code (a stand-in would not time its queue's hand-over from the reader
    thread), its order."""

    def __init__(self, seconds: float):
        from edge_runtime.robot.command import TICK_S  # the robot command's own (a box imports it too)

        self.tick_s = TICK_S
        self.frames = int(seconds * FRAME_RATE_HZ)
        self.arm_slots = int(seconds * TICK_RATE_HZ)
        self.next_tick_s = TICK_S  # the driver first waits TICK_S for a frame

    def done(self, end_s: float, k: int) -> None:
        self.next_tick_s = end_s if k >= 0 else end_s + self.tick_s

    def __iter__(self):
        k = j = 0
        while k < self.frames:
            frame_s = k / FRAME_RATE_HZ
            arm_s = j / TICK_RATE_HZ + ARM_OFFSET_S if j < self.arm_slots else math.inf
            if arm_s <= min(frame_s, self.next_tick_s):  # the arm's frames are on the bus before (as in _schedule)
                j += 1
                yield arm_s, ARM
            elif frame_s <= self.next_tick_s:
                k += 1
                yield frame_s, k - 1
            else:
                yield self.next_tick_s, TICK


BOX_IMAGE_PX = (1280, 720)
"""The image size the robot command assumes for a keypoint file without ``[camera] intrinsics``."""


def box_camera(box):
    """(camera model, keypoint format) the robot command uses with ``box``'s ``[camera]`` settings
    (``edge_runtime/robot/command.py``: the intrinsics file, else a 100-degree camera)."""
    from edge_runtime.robot.keypoints import CameraModel

    cam = box.camera
    model = CameraModel.from_json(cam.intrinsics) if cam.intrinsics else CameraModel.from_fov(*BOX_IMAGE_PX)
    return model, cam.keypoint_format


def _box(zones: dict | None = None):
    """The shipped box configuration with every robot section registered (as the robot command loads it),
    ``zones`` replacing some ``[zones]`` settings."""
    from dataclasses import replace

    import edge_runtime.robot.calibration  # noqa: F401 - each import registers its section
    import edge_runtime.robot.camera_source  # noqa: F401
    import edge_runtime.robot.keypoints  # noqa: F401
    import edge_runtime.robot.lifter  # noqa: F401
    import edge_runtime.robot.loop  # noqa: F401
    from edge_runtime import config

    box = config.load(None)
    return replace(box, zones=replace(box.zones, **zones)) if zones else box


def _known_calibration(params):
    """The simulated camera's known pose as a :class:`Calibration` with the box's ``[calibration]``
    settings, so the loop maps and floor-anchors every skeleton as it does on a box."""
    from edge_runtime.robot.calibration import Calibration

    return Calibration(A=CAMERA_FROM_ROBOT.T.copy(), b=np.asarray(CAMERA_POSITION_M, float), method="known pose",
                       worker_height_m=1.75, head_cam_m=np.zeros((3, 3)), ankle_cam_m=np.zeros((3, 3)),
                       params=params)


class _Frames:
    """Feeds camera frame ``k`` to the loop as the robot command does: keypoints of everyone ->
    ``PersonTracker`` -> ``RobotLoop.feed_people`` (each person lifted with his own window)."""

    def __init__(self, cfg: RobotConfig, box, data):
        from edge_runtime.core.manifest import ASSETS_DIR
        from edge_runtime.robot.keypoints import Person, PersonTracker
        from edge_runtime.robot.lifter import PeopleLifter, StreamingLifter

        if cfg.lifter:
            from dataclasses import replace

            params = replace(box.lifter, precision=cfg.lifter, threads=1)
            camera, fmt = box_camera(box)
            # as edge_runtime/robot/command.py builds them: the conversions to H36M and to the lifter's
            # canonical camera (undistortion included) are part of every frame's cost
            self.lifter = PeopleLifter(StreamingLifter.from_manifest(cfg.assets or ASSETS_DIR, params, camera=camera,
                                                                     keypoint_format=fmt))
            self.tracker = PersonTracker(box.people, keypoint_format=fmt)
            self.frames = data["keypoints_px"]
            self.person = Person
            self.what = (f"{len(self.frames[0])} simulated workers' {fmt.upper()} keypoints ({camera.width_px} x "
                         f"{camera.height_px} camera) -> PersonTracker -> lifter-{cfg.lifter} per person (1 thread) "
                         "-> RobotLoop.feed_people")
        else:
            self.lifter = None
            self.frames = data["joints_robot_m"]
            self.what = "no lifter shipped: robot-frame 3D joints of both workers fed to RobotLoop.feed_joints"

    def __call__(self, loop, k: int):
        frame = self.frames[k % len(self.frames)]
        t_s = k / FRAME_RATE_HZ
        if self.lifter is None:
            return loop.feed_joints(frame)
        people = self.tracker.update(t_s, [self.person(keypoints=kp) for kp in frame])
        return loop.feed_people(self.lifter, t_s, people)


_COUNTED = (("escape", "escapes"), ("retract", "retracts"), ("stop", "stops"), ("move", "moves"),
            ("speed", "speed_changes"))
"""Loop counters that say what a tick sent, most telling first (a tick leaves no FrameRecord)."""


def _kind(command: str | None, before: dict, after: dict, frame_ids: set, mode_id: int) -> str:
    """What a frame's (``command``: its FrameRecord's) or a tick's (None) last command was
    (:data:`KINDS`), from the loop's counters before and after it and the frames it sent."""
    grew = {kind for kind, counter in _COUNTED if after[counter] > before[counter]}
    if command is None:
        command = next((kind for kind, _ in _COUNTED if kind in grew), "alarm")
    if command == "retract" and "escape" in grew:
        return "escape"
    if command == "move" and mode_id in frame_ids:  # a task move sent with a resume before it
        return "resume"
    return command


def _counters(loop) -> dict:
    c = loop.counters
    return {counter: getattr(c, counter) for _, counter in _COUNTED}


def command_row(name: str, times_s: list[float], kinds: list[str], what: str) -> dict:
    """A row of command latencies: overall and per kind (``by_kind``: n, p50, p99, max in us), with
    the p99's sample size said (``p99_note`` when it is under :data:`P99_MIN_N`)."""
    t = np.asarray(times_s, float) * 1e9
    by_kind = {}
    for k in KINDS:
        sel = t[np.asarray([x == k for x in kinds], bool)] if kinds else t[:0]
        if sel.size:
            s = summarize(sel)
            by_kind[k] = {f: s[f] for f in ("n", "p50_us", "p99_us", "max_us")}
    row = {"name": name, **summarize(t), "by_kind": by_kind, "what": what}
    if row["n"] < P99_MIN_N:
        row["p99_note"] = f"p99 of {row['n']} samples (fewer than {P99_MIN_N}): not a p99"
    return row


class _SimClock:
    """A clock that jumps to each deadline instead of sleeping (``RobotConfig.simulated``)."""

    def __init__(self):
        self.t_s = 0.0

    def __call__(self) -> float:
        return self.t_s

    def wait_until(self, due_s: float) -> None:
        self.t_s = max(self.t_s, due_s)


@dataclass
class _Run:
    """What one run of the cycle leaves: the loop, the arm stand-in and the per-frame figures."""

    loop: object
    echo: object
    what: str
    cycle_s: list = field(default_factory=list)
    """Per frame: keypoints in -> ``feed_people`` returned (s)."""
    late_s: list = field(default_factory=list)
    """Per frame: how long after its due time it started (s)."""
    reaction_s: list = field(default_factory=list)
    frame_cpu_s: list = field(default_factory=list)
    """The same frames' CPU time (this thread's, keypoints in -> ``feed_people`` returned, s): what
    the code costs, whatever else the machine runs (a preempted frame's wall time is longer)."""
    due_reaction_s: list = field(default_factory=list)
    """The same frames from their due time (schedule time: when the keypoints were there), s."""
    feed_reaction_s: list = field(default_factory=list)
    """The same frames from ``feed_people``'s own ``t_in_s`` (after tracking), as the robot command's
    ``FrameRecord`` measures its reaction (s)."""
    kinds: list = field(default_factory=list)
    tick_s: list = field(default_factory=list)
    """Per tick that sent a command: tick start -> its last command frame's ``send()`` returned (s)."""
    tick_kinds: list = field(default_factory=list)
    misses: int = 0
    wall_s: float = 0.0
    cpu_pct: float = 0.0


def run_cycle(cfg: RobotConfig) -> _Run:
    """The frames and ticks of ``cfg.seconds`` (module docstring): in real time, or with
    ``cfg.simulated`` on a clock that jumps from deadline to deadline (the same commands when the
    machine keeps up; no timing)."""
    from bench.arm_echo import arm_on_bus

    if cfg.schedule not in SCHEDULES:
        raise ValueError(f"schedule must be one of {', '.join(SCHEDULES)}, got {cfg.schedule!r}")
    sim = _SimClock() if cfg.simulated else None
    clock, wait = (sim, sim.wait_until) if sim else (time.perf_counter, sleep_until)
    box = _box(cfg.zones)
    feed = _Frames(cfg, box, np.load(cfg.worker_npz))
    channel = f"bench-robot-{os.getpid()}-{id(cfg)}"
    with arm_on_bus(channel, cfg.arm_posture_rad or ARM_POSTURE_RAD, clock) as (bus, echo, link):
        return _cycle(cfg, clock, wait, box, feed, bus, echo, link)


def bench_loop(link, box, feed, clock):
    """The runtime's loop as the bench runs it: the box's sections (:func:`_box`), and the known calibration when
    ``feed`` lifts keypoints (joints come in the robot frame otherwise). Profiling scripts and the golden trace test
    build theirs here too, so they time and pin the loop the bench measures."""
    from edge_runtime.robot.loop import RobotLoop

    calibration = _known_calibration(box.calibration) if feed.lifter is not None else None
    return RobotLoop(link, calibration=calibration, zones=box.zones, tracker=box.tracker, params=box.robot_loop,
                     clock=clock)


def _cycle(cfg: RobotConfig, clock, wait, box, feed, bus, echo, link) -> _Run:
    """:func:`run_cycle` with its bus, arm stand-in and link open."""
    from bench.arm_echo import HEARTBEAT_FRAME, command_sent_s
    from edge_runtime.core import heap

    ids = {m.name: m.frame_id for m in link.codec.db.messages}
    heartbeat_id, mode_id = ids[HEARTBEAT_FRAME], ids["ROBOT_MODE_CMD"]
    loop = bench_loop(link, box, feed, clock)
    run = _Run(loop, echo, feed.what)
    live = _LiveSchedule(cfg.seconds) if cfg.schedule == "live" else None  # made (its import done) before the clock runs
    heap.settle()  # as `python -m edge_runtime robot` does once its loop is built
    with CpuShare() as cpu:
        t_start = clock()
        echo.serve(t_start)  # the arm's first state, so the link is up from the first frame
        for due, k in live or _schedule(cfg.seconds):
            wait(t_start + due)
            if k == ARM:  # the arm's own slot: outside every timed frame and tick
                echo.serve(clock())
                continue
            before = _counters(loop)
            cpu_in, t_in = time.thread_time(), clock()
            rec = loop.tick() if k == TICK else feed(loop, k)
            t_out, cpu_out = clock(), time.thread_time()
            if live:
                live.done(t_out - t_start, k)
            t_sent = command_sent_s(bus.sent, heartbeat_id)
            if k >= 0:
                run.cycle_s.append(t_out - t_in)
                run.late_s.append(t_in - (t_start + due))
                run.misses += t_out > t_start + due + 1.0 / FRAME_RATE_HZ
            if t_sent is not None and (k < 0 or rec.command is not None):
                kind = _kind(None if k < 0 else rec.command, before, _counters(loop),
                             {fid for _, fid in bus.sent}, mode_id)
                (run.tick_s if k < 0 else run.reaction_s).append(t_sent - t_in)
                (run.tick_kinds if k < 0 else run.kinds).append(kind)
                if k >= 0:
                    run.feed_reaction_s.append(t_sent - rec.t_in_s)
                    run.due_reaction_s.append(t_sent - (t_start + due))
                    run.frame_cpu_s.append(cpu_out - cpu_in)
            del bus.sent[:]
    run.wall_s, run.cpu_pct = cpu.wall_s, cpu.pct
    return run


def _short(times_s: list[float]) -> dict:
    """n, p50, p99 and max (us) of ``times_s``."""
    return {k: v for k, v in summarize(np.asarray(times_s) * 1e9).items() if k in ("n", "p50_us", "p99_us", "max_us")}


ON_THE_LINK = ("the send() of its last command frame on the bus returned (the product's CanRobotLink on python-can's "
               "virtual bus, frames encoded by its cantools/DBC + E2E codec; an in-process arm stand-in acknowledges "
               "them and sends its state at 100 Hz in slots of its own, outside the timed frames and ticks)")


def measure_robot(cfg: RobotConfig) -> list[dict]:
    """Run in a child process: see the module docstring."""
    r = run_cycle(cfg)
    st = r.loop.status()
    runtime_pct = round(r.cpu_pct - 100.0 * r.echo.cpu_s / max(r.wall_s, 1e-9), 2)
    late = np.asarray(r.late_s, float)
    from edge_runtime import config

    # another interleaving of frames and ticks is another measurement: --compare must not set one against the other
    scenario = SCENARIO if cfg.schedule == "grid" else f"{SCENARIO}_{cfg.schedule}"
    tag = {"scenario": scenario, "zones_changed": dict(cfg.zones)} if cfg.zones else {"scenario": scenario}
    # config.load(None) reads an installed box's own file when there is one: say which configuration ran
    source = str(config.SYSTEM_PATH) if config.SYSTEM_PATH.is_file() else "the shipped defaults"
    return [{"name": "robot_30hz", **tag, "configuration": source, "rate_hz": FRAME_RATE_HZ, "seconds": round(r.wall_s, 2), "frames": len(r.cycle_s),
             "cpu_share_pct": runtime_pct, "cpu_share_with_arm_pct": r.cpu_pct, "deadline_misses": r.misses,
             "start_late_p99_us": round(float(np.percentile(late, 99)) * 1e6, 1) if late.size else None,
             **summarize(np.asarray(r.cycle_s) * 1e9), "peak_rss_mb": peak_rss_mb(), "commands": st["commands"],
             "stops": st["stops"], "retracts": st["retracts"], "escapes": st["escapes"],
             "speed_changes": st["speed_changes"], "acked": st["acked"], "unacked": st["unacked"],
             "retries": st["retries"], "fault": st["fault"], "arm_answered": r.echo.commands,
             "arm_rejected": r.echo.rejected,
             "what": r.what + f", ticks at {TICK_RATE_HZ:g} Hz, {source}, the product's CAN link on "
                     "python-can's virtual bus (an in-process arm stand-in answers and sends its state at 100 Hz, "
                     "5 ms after each tick; its CPU left out of cpu_share_pct)"},
            {**command_row("robot_reaction", r.reaction_s, r.kinds,
                           "keypoints in (the loop picks the frame up and hands it to the tracker) -> " + ON_THE_LINK
                           + "; frames that caused a command"), **tag,
             "from_due": _short(r.due_reaction_s), "from_feed": _short(r.feed_reaction_s),
             "frame_cpu": _short(r.frame_cpu_s), "judged_on": "from_due"},
            {**command_row("robot_tick_command", r.tick_s, r.tick_kinds,
                           "a 10 ms control tick that sent a command (escape turns replanned on their timer, "
                           "waypoints, staleness): tick start -> " + ON_THE_LINK), **tag}]


def robot_rows(seconds: float, assets: Path, entries: list[dict], seed: int, workdir: Path) -> list[dict]:
    """Parent side: the robot rows (a child process), or a "not available" row when
    edge_runtime.robot.loop cannot be imported."""
    from bench.worker import ChildFailed, run_child

    if importlib.util.find_spec("edge_runtime.robot.loop") is None:
        return [not_available("robot_30hz", "edge_runtime.robot.loop is not importable")]
    lifter = lifter_entry(entries)
    npz = prepare_workers(workdir / "workers.npz", seconds, lifter, seed, *box_camera(_box()))
    try:
        return run_child("robot", asdict(RobotConfig(str(npz), seconds, str(assets),
                                                     lifter["precision"] if lifter else "", _arm_posture())))
    except ChildFailed as e:  # the robot runtime is another module's work in progress: say so, go on
        return [not_available("robot_30hz", f"the robot cycle failed: {e}")]


def _arm_posture() -> tuple:
    """The arm's joint angles on the shipped task's first waypoint (the simulated Sawyer's inverse
    kinematics; parent process only), or () to use :data:`ARM_POSTURE_RAD` when it cannot be solved."""
    try:
        from firmware_sim.scenarios.hrc_world import box_config, task_start_posture

        lp = box_config().robot_loop
        q = task_start_posture(lp.task_waypoints_m[0], lp.task_pitch_rad, lp.task_yaw_rad)
    except Exception:  # noqa: BLE001 - a posture is a nicety: the fixed one still has links to measure
        return ()
    return tuple(float(v) for v in q) if q is not None and len(q) == 7 and all(map(math.isfinite, q)) else ()
