"""``python -m edge_runtime robot``: the robot-side safety loop against a real or simulated arm.

    python -m edge_runtime robot --config BOX.toml --link can|mavlink [link options]
        (--keypoints KP.jsonl | --camera DEV --pose-model POSE.onnx | --joints J.jsonl)
        [--calibration CAL.json] [--duration S] [--log OUT.jsonl]
    python -m edge_runtime robot --link none [--fast] (--keypoints KP.jsonl | --joints J.jsonl)
        [--calibration CAL.json] --log OUT.jsonl
    python -m edge_runtime robot --joints|--keypoints RECORDING.jsonl --calibrate CAL.json [--calibration-method rigid|eq2|pnp]
    python -m edge_runtime robot --config BOX.toml --print-config

Inputs (one of):

* ``--keypoints KP.jsonl``: 2D keypoints (:func:`edge_runtime.robot.keypoints.read_keypoints_jsonl`;
  [camera] keypoint_format, [camera] intrinsics or ``--intrinsics CAM.json``): every person is
  tracked (:class:`edge_runtime.robot.keypoints.PersonTracker`, [people]) and lifted to 3D with
  his own window by the shipped lifter ([lifter]); each goes to the hazard monitor.
* ``--camera DEV --pose-model POSE.onnx``: a camera through a 2D pose model
  (:mod:`edge_runtime.robot.camera_source`), then the lifter.
* ``--joints J.jsonl``: 3D joints, one JSON object per frame::

      {"t": 0.033, "joints_cam_m": [[x, y, z] x 17], "valid": true, "reason": null}
      {"t": 0.066, "joints_robot_m": [[x, y, z] x 17]}
      {"t": 0.1, "people": [{"id": 3, "joints_cam_m": [...]}, ...]}

  ``joints_cam_m`` are camera-frame metres (what ``python -m edge_runtime lift --out``
  writes, so its output can be fed back here) and need ``--calibration``;
  ``joints_robot_m`` are robot-frame metres (a simulator's true joints) and are used as
  they are. ``valid``/``reason`` are optional (the lifter's verdict); ``marker`` (1, 2, 3)
  optionally labels the frames of a calibration recording. A ``{"summary": ...}`` line
  is skipped.

A recording is replayed in real time (frame timestamps) and the loop is ticked every
10 ms between frames; a camera is read by a thread (which also runs the pose model)
while this thread ticks the loop and feeds each frame as it arrives, so a stalled
camera stops the arm through the 200 ms staleness check. Keypoints are lifted inside
the loop's frame (``RobotLoop.feed_keypoints``), so the reaction time includes the
lifter. The arm gets its commands over the configured link ([robot_link], or the
flags; the link sends its own heartbeat and reconnects by itself). At the end (input
exhausted, ``--duration`` reached or Ctrl-C) the arm is stopped, and a summary is
printed: frames, states, stops, retracts, link errors, the link's own counters and the
reaction time from a frame's arrival to its command on the link; the link is called ``ok``
only when the arm sent its state and acknowledged the motion commands. The run ends early,
with one ``error:`` line and exit status 3 (:data:`EXIT_LINK_FAULT`), when the loop cannot keep
the arm safe through the link (``RobotLoop.fault``): no state from the arm within
``[robot_loop] link_up_timeout_s`` (a link that never comes up, a wrong channel, a signing key
the arm does not share), or more than ``[robot_loop] ack_retries`` motion commands in a row
unacknowledged (100 ms, ``ack_timeout_s``) or refused; the arm is then left to its watchdog,
which stops it. ``--log`` writes one
JSON object per frame (``t_in_s``, ``t_command_s``, ``state``, ``reason``,
``distance_m``, ``command``) and a final ``{"summary": ...}`` line. ``--sizing
iso15066`` sizes the stop zone by ISO/TS 15066's protective separation distance
([zones]).

``--link none`` runs the same chain with no arm (:mod:`edge_runtime.robot.replay`): the
commands go to a stand-in that carries them nowhere, and the summary says that no arm was
connected; ``--fast`` replays the recording on its own timestamps as fast as it goes (the
log's ``t_in_s`` are then recording time). Each log line then also holds, per person,
``head_robot_m``, ``predicted_head_m``, the nearest body point and its distance
(``FrameRecord.people``).

``--calibrate OUT.json`` runs the 3-marker procedure of :mod:`edge_runtime.robot.calibration`
on a recording of the worker standing on markers 1, 2 and 3 (camera-frame joints or
keypoints), writes the calibration and prints its residuals; no link is opened.
"""
from __future__ import annotations

import argparse
import itertools
import json
import logging
import queue
import sys
import threading
import time
from contextlib import closing
from dataclasses import asdict, dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from edge_runtime.cli import CliError, positive_float
from edge_runtime.core import strict_json
from edge_runtime.core.manifest import ManifestError
from edge_runtime.errors import InputError
from edge_runtime.robot.calibration import METHODS, Calibration, CalibrationError
from edge_runtime.robot.keypoints import timestamp_s
from edge_runtime.robot.link.options import add_bus_arguments

if TYPE_CHECKING:  # imported when the loop runs, not for every command's options
    from collections.abc import Callable

    from edge_runtime.robot.link.base import RobotLink
    from edge_runtime.robot.loop import FrameRecord, RobotLoop

log = logging.getLogger(__name__)
TICK_S = 0.01
"""Control cycle of the real-time driver (s)."""
EXIT_LINK_FAULT = 3
"""Exit status when the arm could not be reached or did not confirm a safety command."""
NO_LINK = "none"
"""``--link none``: no arm (:mod:`edge_runtime.robot.replay`)."""


class JointsInputError(InputError):
    """A malformed joints file; the message names the file and line."""


BAD_INPUT = (CalibrationError, JointsInputError, ManifestError)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    src = parser.add_mutually_exclusive_group()
    src.add_argument("--keypoints", metavar="FILE.jsonl", help="2D keypoints per frame, lifted by the shipped lifter")
    src.add_argument("--camera", metavar="DEV",
                     help="a camera (device index, file or URL) through --pose-model [camera] device")
    src.add_argument("--joints", metavar="FILE.jsonl", help="3D joints per frame (joints_cam_m or joints_robot_m)")
    parser.add_argument("--pose-model", metavar="M.onnx", help="2D pose ONNX model for --camera [camera] pose_model")
    parser.add_argument("--config", metavar="BOX.toml", help="the box configuration (edge_runtime/box.example.toml)")
    parser.add_argument("--print-config", action="store_true", help="print the effective configuration and exit")
    link = parser.add_argument_group("robot link (override [robot_link])")
    link.add_argument("--link", choices=("can", "mavlink", NO_LINK),
                      help=f"[robot_link] kind; {NO_LINK}: no arm, an offline replay that sends nothing")
    add_bus_arguments(link, config_section="robot_link")
    link.add_argument("--serial", metavar="serial:PATH[?key=HEX]", help="MAVLink serial line [robot_link] serial")
    parser.add_argument("--fast", action="store_true", help="with --link none: replay the recording as fast as it "
                        "goes, on its own timestamps")
    parser.add_argument("--intrinsics", metavar="CAM.json", help="the keypoints' camera model [camera] intrinsics")
    parser.add_argument("--calibration", metavar="CAL.json", help="camera -> robot calibration for camera-frame joints")
    parser.add_argument("--calibrate", metavar="OUT.json", help="run the 3-marker calibration on the recording, write it")
    parser.add_argument("--calibration-method", choices=METHODS,
                        help="the --calibrate fit [calibration] method (pnp: the camera pose from the rays alone)")
    parser.add_argument("--sizing", choices=("eq45", "iso15066"), help="zone sizing [zones] sizing")
    parser.add_argument("--duration", type=positive_float, metavar="S", help="stop after S seconds")
    parser.add_argument("--log", metavar="OUT.jsonl", help="one JSON object per frame, then a summary")
    parser.add_argument("--quiet", action="store_true", help="print only the summary")


def effective_config(args):
    """The config file, then the command-line flags on top, validated as one: the sections of
    the components imported here (the wearable's sections in the same file are left to it)."""
    from edge_runtime import config
    from edge_runtime.robot import calibration, camera_source, hazard, lifter, loop  # noqa: F401 - their sections
    from edge_runtime.robot.link import options  # noqa: F401 - [robot_link]

    cfg = config.load(args.config)
    kind = None if args.link == NO_LINK else args.link  # no arm: the configured link is not opened
    cfg = config.override(cfg, "robot_link", kind=kind, interface=args.can_interface, channel=args.can_channel,
                          host=args.can_host, port=args.can_port, serial=args.serial)
    cfg = config.override(cfg, "camera", pose_model=args.pose_model, intrinsics=args.intrinsics)
    cfg = config.override(cfg, "calibration", method=args.calibration_method)
    return config.override(cfg, "zones", sizing=args.sizing)


# ---------------------------------------------------------------------------- inputs


@dataclass
class JointsFrame:
    t_s: float
    joints_m: np.ndarray | None
    """(P, 17, 3), or None when nobody was seen."""
    frame: str
    """"camera" or "robot"."""
    valid: bool = True
    reason: str = ""
    ids: list | None = None
    marker: int = 0


MAX_JOINT_M = 100.0
"""A joint coordinate beyond +-this (m) is refused: no camera of a robot cell sees that far,
and zone distances are computed from these numbers."""


def _array17(value, where: str) -> np.ndarray:
    """17 [x, y, z] rows of finite numbers within +-MAX_JOINT_M (null: not seen)."""
    return strict_json.number_array(value, (17, 3), where, JointsInputError, -MAX_JOINT_M, MAX_JOINT_M, nulls=True)


def _pick_joints(obj: dict, where: str) -> tuple[np.ndarray | None, str | None]:
    keys = [k for k in ("joints_cam_m", "joints_robot_m") if k in obj]
    if len(keys) > 1:
        raise JointsInputError(f"{where}: give joints_cam_m or joints_robot_m, not both")
    if not keys:
        return None, None
    value = obj[keys[0]]
    frame = "camera" if keys[0] == "joints_cam_m" else "robot"
    return (None if value is None else _array17(value, f"{where}: {keys[0]}")), frame


def parse_joints_line(line: str | bytes, where: str) -> JointsFrame | None:
    """One line of a joints file (None: blank or a summary line); every field checked here."""
    if not line.strip():
        return None
    obj = strict_json.loads(line, where, JointsInputError)
    if not isinstance(obj, dict):
        raise JointsInputError(f"{where}: expected a JSON object per line")
    if "summary" in obj:
        return None
    t_s, valid, reason, marker = _frame_fields(obj, where)
    if "people" in obj:
        joints, frame, ids = _people(obj["people"], where)
        return JointsFrame(t_s, joints, frame, valid, reason, ids, marker)
    joints, frame = _pick_joints(obj, where)
    if frame is None:
        raise JointsInputError(f"{where}: no joints_cam_m, joints_robot_m or people")
    if joints is None and valid:
        raise JointsInputError(f"{where}: joints are null in a frame marked valid")
    return JointsFrame(t_s, None if joints is None else joints[None], frame, valid, reason, None, marker)


def _frame_fields(obj: dict, where: str) -> tuple[float, bool, str, int]:
    """A joints line's t (s), valid, reason and marker, checked."""
    t = timestamp_s(obj.get("t", obj.get("t_s")), f"{where}: t", JointsInputError)
    valid = obj.get("valid", True)
    if not isinstance(valid, bool):
        raise JointsInputError(f"{where}: valid: expected true/false, got {valid!r}")
    marker = strict_json.integer(obj.get("marker", 0), f"{where}: marker", JointsInputError, 0, 3)
    reason = obj.get("reason") or ""
    if not isinstance(reason, str):
        raise JointsInputError(f"{where}: reason: expected a string, got {reason!r}"[:200])
    return t, valid, reason, marker


def _people(people, where: str) -> tuple[np.ndarray | None, str, list]:
    """A ``people`` list: joints (P, 17, 3) or None for nobody, their frame and their ids."""
    if not isinstance(people, list):
        raise JointsInputError(f"{where}: people: expected a list")
    picked = [_pick_joints(p if isinstance(p, dict) else {}, f"{where}: people[{i}]") for i, p in enumerate(people)]
    if any(j is None for j, _ in picked):
        raise JointsInputError(f"{where}: every person needs joints_cam_m or joints_robot_m")
    frames = {f for _, f in picked}
    if len(frames) > 1:
        raise JointsInputError(f"{where}: people mix camera- and robot-frame joints")
    joints = np.stack([j for j, _ in picked]) if picked else None
    ids = [p.get("id", i) for i, p in enumerate(people)]
    for i, pid in enumerate(ids):
        if not isinstance(pid, str):
            strict_json.integer(pid, f"{where}: people[{i}].id", JointsInputError, -2**63, 2**63 - 1)
    return joints, frames.pop() if frames else "robot", ids


def read_joints_jsonl(path: str) -> list[JointsFrame]:
    """Every frame of a joints file, checked in full (times must increase)."""
    try:
        f = open(path, "rb")  # decoded line by line, so that bad bytes are named by their line
    except OSError as e:
        raise JointsInputError(f"{path}: cannot open ({e.strerror or e})") from None
    frames: list[JointsFrame] = []
    kind = None  # the frame of the first joints seen: a file holds one kind only
    with f:
        for n, line in enumerate(f, 1):
            fr = parse_joints_line(line, f"{path}:{n}")
            if fr is None:
                continue
            if frames and fr.t_s <= frames[-1].t_s:
                raise JointsInputError(f"{path}:{n}: t {fr.t_s} does not increase (previous {frames[-1].t_s})")
            if fr.joints_m is not None:
                if kind is not None and fr.frame != kind:
                    raise JointsInputError(f"{path}:{n}: mixes camera- and robot-frame joints")
                kind = fr.frame
            frames.append(fr)
    if not frames:
        raise JointsInputError(f"{path}: no frames")
    return frames


@dataclass
class KeypointSource:
    """2D keypoints of the people per frame, and the lifter for them."""

    frames: Any
    """Iterator of (t_s, people: a list of ``keypoints.Person``, as detected)."""
    lifter: Any
    """The shipped StreamingLifter (one person's window; ``PeopleLifter`` makes one per person)."""
    live: bool
    """A camera (frames come in real time) rather than a recording (replayed at its timestamps)."""
    tracking: Any = None
    """The [people] parameters of the PersonTracker."""

    def followed(self):
        """(t_s, keypoints (17, 3) or None): the largest person of each frame (a calibration
        recording has one worker)."""
        from edge_runtime.robot.keypoints import PersonSelector

        selector = PersonSelector()
        for t_s, people in self.frames:
            person = selector.select(people)
            yield t_s, None if person is None else person.keypoints

    def tracked(self):
        """(t_s, people with stable ids) for every frame (``keypoints.PersonTracker``)."""
        from edge_runtime.robot.keypoints import PersonTracker

        tracker = PersonTracker(self.tracking)
        for t_s, people in self.frames:
            yield t_s, tracker.update(t_s, people)


def _keypoint_source(args, cfg) -> KeypointSource:
    """--keypoints or --camera, with the shipped lifter ([lifter]) and the camera model
    ([camera] intrinsics; else a 100 degree camera at the video's size, or 1280 x 720)."""
    from edge_runtime.core.manifest import ASSETS_DIR
    from edge_runtime.robot.keypoints import CameraModel, read_keypoints_jsonl
    from edge_runtime.robot.lifter import StreamingLifter

    cam = cfg.camera
    camera = CameraModel.from_json(cam.intrinsics) if cam.intrinsics else None
    source = None
    if args.keypoints:
        frames = [(f.t_s, f.people) for f in read_keypoints_jsonl(args.keypoints, cam.keypoint_format, cam.rate_hz)]
    else:
        from edge_runtime.robot.camera_source import CameraKeypointSource, PoseModel

        if not cam.pose_model:
            raise CliError("--camera needs --pose-model POSE.onnx (or [camera] pose_model)")
        model = PoseModel(cam.pose_model, keypoint_format=cam.keypoint_format, threads=cfg.lifter.threads)
        source = CameraKeypointSource(args.camera, model, cfg.camera_source)
        frames = _camera_frames(source)
    if camera is None:
        size = source.frame_size() if source is not None else None
        camera = CameraModel.from_fov(*(size or (1280, 720)))
    lifter = StreamingLifter.from_manifest(ASSETS_DIR, cfg.lifter, camera=camera, keypoint_format=cam.keypoint_format)
    return KeypointSource(frames, lifter, live=source is not None, tracking=cfg.people)


def _camera_frames(source):
    """(t_s, people) from a camera source; its status changes are logged (event camera_state)."""
    from edge_runtime.robot.camera_source import CameraFrame

    try:
        for item in source.frames():
            if isinstance(item, CameraFrame):
                yield item.t_s, item.people
            else:
                item.log()
    finally:
        source.close()


# ---------------------------------------------------------------------------- calibration


def run_calibrate(args, cfg) -> int:
    from edge_runtime.robot.calibration import from_recording

    if args.joints:
        frames = [f for f in read_joints_jsonl(args.joints) if f.joints_m is not None and f.valid]
        if any(f.frame != "camera" for f in frames):
            raise CliError(f"--calibrate needs camera-frame joints (joints_cam_m); {args.joints} has robot-frame joints")
        t = np.array([f.t_s for f in frames])
        joints = np.stack([f.joints_m[0] for f in frames]) if frames else np.empty((0, 17, 3))
        labels = np.array([f.marker for f in frames])
        marker = labels if labels.any() else None
    elif args.keypoints:
        src = _keypoint_source(args, cfg)
        lifted = [(t, p) for t, p in ((t, src.lifter.push(t, kp)) for t, kp in src.followed()) if p.valid]
        t = np.array([x[0] for x in lifted])
        joints = np.stack([x[1].joints_cam_m for x in lifted]) if lifted else np.empty((0, 17, 3))
        marker = None
    else:
        raise CliError("--calibrate needs a recording: --joints FILE.jsonl or --keypoints FILE.jsonl")
    if len(t) == 0:
        raise CalibrationError("the recording has no valid frames")
    cal = from_recording(t, joints, cfg.calibration, marker=marker)
    try:
        cal.save(args.calibrate)
    except OSError as e:
        raise CliError(f"--calibrate {args.calibrate}: cannot write ({e.strerror or e})") from None
    r = cal.residuals_m()
    print(f"calibration ({cal.method}, scale {cal.scale:.3f}, worker height {cal.worker_height_m:.2f} m, "
          f"frames per marker {list(cal.frames)}) written to {args.calibrate}\n"
          f"  residuals (m): head {r['head']}, ankle {r['ankle']}")
    return 0


# ---------------------------------------------------------------------------- the live loop


def _open_link(cfg) -> RobotLink:
    """The configured robot link (``edge_runtime.robot.link.base.open_link``). The link sends its
    own heartbeat from poll() and reconnects by itself."""
    from edge_runtime.robot.link.base import open_link

    r = cfg.robot_link
    if r.kind == "can":
        options = {"interface": r.interface, "channel": r.channel, "bitrate": r.bitrate,
                   "host": r.host if r.interface == "socketcand" else None,
                   "port": r.port if r.interface == "socketcand" else None}
    else:
        if not r.serial:
            raise CliError("--link mavlink needs --serial serial:PATH[?key=HEX] (or [robot_link] serial)")
        options = {"serial": r.serial, "baud": r.baud}  # serial:PATH[?key=HEX], parsed by the link
    try:
        return open_link(r.kind, **options)
    except ValueError as e:
        raise CliError(f"robot link {r.kind}: {e}") from None


def _frames(args, cfg, calibration):
    """(frames, camera_frame, live): ``frames`` yields (t_s, feed) pairs, ``feed(loop)``
    hands one frame to the loop; ``camera_frame`` says whether the joints need the
    calibration; ``live``: a camera, not a recording."""
    if args.joints:
        frames = read_joints_jsonl(args.joints)
        camera_frame = any(f.frame == "camera" and f.joints_m is not None for f in frames)
        if camera_frame and calibration is None:
            raise CliError(f"{args.joints} holds camera-frame joints (joints_cam_m): give --calibration CAL.json")
        return ((f.t_s, (lambda loop, f=f: loop.feed_joints(f.joints_m, f.valid, f.reason, f.ids)))
                for f in frames), camera_frame, False
    if calibration is None:
        raise CliError("lifted joints are in the camera frame: give --calibration CAL.json")
    from edge_runtime.robot.lifter import PeopleLifter

    src = _keypoint_source(args, cfg)
    people_lifter = PeopleLifter(src.lifter)
    return ((t_s, (lambda loop, t_s=t_s, people=people: loop.feed_people(people_lifter, t_s, people)))
            for t_s, people in src.tracked()), True, src.live


def run_loop(args, cfg) -> int:
    from edge_runtime.core import heap
    from edge_runtime.core.service import keepalive
    from edge_runtime.robot.loop import RobotLoop
    from edge_runtime.robot.replay import NO_ARM_VERDICT, NoArm, ReplayClock, fast_frames

    calibration = Calibration.load(args.calibration) if args.calibration else None
    no_arm = args.link == NO_LINK
    if args.fast and not no_arm:
        raise CliError("--fast replays without an arm: it needs --link none")
    frames, camera_frame, live = _frames(args, cfg, calibration)
    if args.fast and live:
        raise CliError("--fast replays a recording (--keypoints or --joints), not a camera")
    if not live:
        frames = _first_read(frames)  # a bad file is reported before the link opens
    log = _open_log(args.log)
    clock = ReplayClock() if args.fast else time.monotonic
    link = NoArm(clock, cfg.robot_loop.task_waypoints_m[0]) if no_arm else _open_link(cfg)
    loop = RobotLoop(link, calibration if camera_frame else None, cfg.zones, cfg.tracker, cfg.robot_loop,
                     clock=clock, on_record=(lambda r: log.write(json.dumps(asdict(r)) + "\n")) if log else None)
    progress = _Progress(loop, args.quiet)
    heap.settle()  # no collection of start-up objects inside a frame
    start = time.monotonic()
    recording_s = 0.0
    try:
        if args.fast:
            timed = lambda loop, frames, start, duration: fast_frames(loop, clock, frames, duration)  # noqa: E731
        else:
            timed = _live_frames if live else _replayed_frames
        with closing(timed(loop, frames, start, args.duration)) as due_frames:
            for t_rel_s, feed in due_frames:
                keepalive()  # READY, then the watchdog's keep-alives, only while this loop turns
                progress.show(t_rel_s, feed(loop))
                recording_s = t_rel_s
                if loop.fault:
                    break
    except KeyboardInterrupt:
        pass
    finally:
        _safe_stop(link)
        summary = _summary(loop, link, progress.states, time.monotonic() - start)
        if no_arm:
            summary.update(link_verdict=NO_ARM_VERDICT, recording_s=round(recording_s, 3),
                           x_real_time=round(recording_s / max(summary["wall_s"], 1e-9), 1), fast=bool(args.fast))
        if log:
            log.write(json.dumps({"summary": summary}) + "\n")
            log.close()
        link.close()
    print(_summary_text(summary, args.log))
    if loop.fault:
        print(f"error: {_fault_line(loop, link, cfg)}", file=sys.stderr)
        return EXIT_LINK_FAULT
    return 0


def _first_read(frames):
    """``frames`` with its first frame read now (CliError when there is none)."""
    first = next(frames, None)
    if first is None:
        raise CliError("no frames")
    return itertools.chain([first], frames)


def _open_log(path: str | None):
    try:
        return open(path, "w", encoding="utf-8") if path else None
    except OSError as e:
        raise CliError(f"--log {path}: cannot write ({e.strerror or e})") from None


@dataclass
class _Progress:
    """The states of the frames (for the summary) and, unless ``quiet``, a line on stderr
    whenever the state, its reason or the link changes."""

    loop: RobotLoop
    quiet: bool
    states: dict[str, int] = field(default_factory=dict)
    _last: tuple | None = None

    def show(self, t_rel_s: float, rec: FrameRecord) -> None:
        self.states[rec.state] = self.states.get(rec.state, 0) + 1
        loop = self.loop
        now = (rec.state, rec.reason, loop.link_state, loop.link_error)
        if not self.quiet and now != self._last:
            print(f"t={t_rel_s:8.2f}s  {rec.state:<7} {rec.reason}  d={rec.distance_m:.2f} m  link {loop.link_state}"
                  + (f" ({loop.link_error})" if loop.link_error else ""), file=sys.stderr)
            self._last = now


def _replayed_frames(loop: RobotLoop, frames, start: float, duration: float | None,
                     clock: Callable[[], float] = time.monotonic, sleep: Callable[[float], None] = time.sleep):
    """A recording at its own pace: yields (t from the first frame s, feed) at each frame's
    timestamp (on ``clock``, from ``start``), ticking the loop right after each frame and every
    TICK_S in between (:func:`_tick_until`)."""
    t0 = None
    for t_s, feed in frames:
        t0 = t_s if t0 is None else t0
        due = start + (t_s - t0)
        if duration and due - start > duration:
            return
        _tick_until(loop, due, clock, sleep)
        yield t_s - t0, feed
    loop.tick()  # the last frame's tick, and one more TICK_S later for the arm's answers to it
    sleep(TICK_S)
    loop.tick()


def _live_frames(loop: RobotLoop, frames, start: float, duration: float | None):
    """A camera: a reader thread pulls frames (and runs the pose model) while this thread
    ticks the loop every TICK_S and yields (t since start s, feed) for each frame as it
    arrives, so a stalled camera is noticed by the staleness check, not by a blocked loop."""
    q: queue.Queue = queue.Queue(maxsize=2)
    stop = threading.Event()
    threading.Thread(target=_read_frames, args=(frames, q, stop), name="robot-camera", daemon=True).start()
    try:
        while not (duration and time.monotonic() - start > duration):
            try:
                item = q.get(timeout=TICK_S)
            except queue.Empty:
                loop.tick()
                continue
            if item is _END:
                return
            yield time.monotonic() - start, item[1]
            loop.tick()
    finally:
        stop.set()


_END = object()
"""What the camera reader queues after the last frame."""


def _read_frames(frames, q: queue.Queue, stop: threading.Event) -> None:
    """The camera reader: frames into ``q``, then _END. When the loop is behind, the newest
    frame matters: the oldest waiting one is dropped."""
    try:
        for item in frames:
            if stop.is_set():
                break
            try:
                q.put_nowait(item)
            except queue.Full:
                q.get_nowait()
                q.put_nowait(item)
    finally:
        q.put(_END)


def _tick_until(loop: RobotLoop, due: float, clock: Callable[[], float] = time.monotonic,
                sleep: Callable[[float], None] = time.sleep) -> None:
    """Tick the loop now and every TICK_S after until ``clock`` reaches ``due``, and return at ``due``
    without ticking there: the frame due then goes first (a tick in front of it would count in its
    reaction), as the live driver takes a frame the moment it is queued. The frame is that instant's
    control cycle (its own link poll and decision, and a fresh pose for the staleness check), and its
    tick follows it: this function's first, called after the frame. So a tick or a frame still comes
    at least every TICK_S, and a tick right after every frame, as before; two ticks may be up to TICK_S
    and a frame's time apart, as in the live driver."""
    while True:
        loop.tick()
        left = due - clock()
        if left <= 0:
            return
        sleep(min(TICK_S, left))
        if left <= TICK_S:
            return


def _safe_stop(link: RobotLink) -> None:
    try:
        link.stop()
    except Exception as e:  # noqa: BLE001 - reported, the controller's watchdog stops the arm anyway
        log.warning("final stop not sent (%s: %s); the arm's watchdog stops it", type(e).__name__, e,
                    extra={"event": "final_stop_not_sent"})


def _summary(loop: RobotLoop, link: RobotLink, states: dict, wall_s: float) -> dict:
    react = [1e3 * r_s for r_s in loop.reactions_s]
    rt = {"median": round(float(np.median(react)), 3) if react else None,
          "p99": round(float(np.percentile(react, 99)), 3) if react else None, "n": len(react)}
    return {**loop.status(), "states": states, "wall_s": round(wall_s, 3), "reaction_ms": rt,
            "link_verdict": _link_verdict(loop), "robot_link": link.summary()}


def _link_verdict(loop: RobotLoop) -> str:
    """What the link did, in words: "ok" only when the arm reported its state and acknowledged
    the motion commands it was sent."""
    c = loop.counters
    if loop.link_state == "connecting":
        return "never up: no state from the arm"
    if c.acked == 0:
        return f"up, but the arm acknowledged none of the motion commands ({c.unacked} unacknowledged)"
    if c.unacked or c.retries:
        return f"degraded: {c.unacked} motion commands unacknowledged in time, {c.retries} sent again"
    return "ok"


def _fault_line(loop: RobotLoop, link: RobotLink, cfg) -> str:
    """The one line for a run ended by ``loop.fault``: which link, what failed, the likely cause."""
    r = cfg.robot_link
    where = (f"{r.interface}:{r.host}:{r.port}:{r.channel}" if r.interface == "socketcand" else
             f"{r.interface}:{r.channel}") if r.kind == "can" else r.serial.split("?", 1)[0]
    stats = link.summary()
    hints = []
    failures = getattr(link, "signature_failures", {})
    if failures:
        hints.append(f"{sum(failures.values())} packets from the arm failed the signature check "
                     f"({', '.join(sorted(failures))}): a different signing key?")
    elif not stats.get("states"):
        hints.append("nothing answered: is the arm on this " + ("channel" if r.kind == "can" else "line") + "?")
    arm_rejected = (link.state.counters or {}).get("integrity_errors", 0) if link.state is not None else 0
    if arm_rejected and stats.get("states"):
        hints.append(f"the arm discarded {arm_rejected} of the runtime's frames (signing or E2E mismatch?)")
    return (f"robot link {r.kind} {where}: {loop.fault}" + "".join(f"; {h}" for h in hints)
            + "; the arm is left to its watchdog")


def _summary_text(s: dict, log_path: str | None) -> str:
    rt = s["reaction_ms"]
    return (f"summary: {s['frames']} frames in {s['wall_s']:.1f} s; states {s['states']}\n"
            f"  stops {s['stops']}, retracts {s['retracts']}, unreachable {s['unreachable']}, invalid frames "
            f"{s['invalid']}, stale {s['stale']}; link errors {s['link_errors']}\n"
            f"  reaction (frame in -> command on the link): median {rt['median']} ms, p99 {rt['p99']} ms "
            f"over {rt['n']} commands\n"
            f"  motion commands acknowledged {s['acked']}, unacknowledged {s['unacked']}, sent again {s['retries']}; "
            f"link {s['link_verdict']}\n"
            "  robot link: " + ", ".join(f"{k} {v}" for k, v in s["robot_link"].items() if k != "link_ok")
            + (f"\n  replayed {s['recording_s']:.1f} s of recording at {s['x_real_time']:g}x real time"
               if "x_real_time" in s else "")
            + (f"\n  log: {log_path}" if log_path else ""))


def cmd(args) -> int:
    cfg = effective_config(args)
    if args.print_config:
        print(cfg.to_toml(), end="")
        return 0
    if args.calibrate:
        return run_calibrate(args, cfg)
    if not (args.keypoints or args.camera or args.joints) and cfg.camera.device:
        args.camera = cfg.camera.device  # the box's own camera ([camera] device)
    if not (args.keypoints or args.camera or args.joints):
        raise CliError("robot: give an input: --keypoints FILE.jsonl, --camera DEV --pose-model M.onnx "
                       "or --joints FILE.jsonl")
    return run_loop(args, cfg)
