"""The robot cycle at 30 Hz: keypoints in -> command out, in real time, in a child process.

``edge_runtime.robot.loop.RobotLoop`` is driven as a box drives it: a camera
frame every 1/30 s (``StreamingLifter.push`` on the shipped int8 lifter, 1
thread, then ``RobotLoop.feed_lifted``) and a control ``tick()`` every 10 ms,
each on an absolute deadline with sleeps in between. The worker is a simulated
person (firmware_sim.people.human/motions, made by the parent, :func:`prepare_worker`)
walking from 4 m straight at the arm's base to 0.9 m and back, again and again,
so the zones are entered and left and commands go out.

The camera stands 7 m in front of the base (robot frame: x, y up, z toward the
work side) 1.0 m above the base top (1.9 m above the floor), looking along -z; its pixels are the
lifter's canonical camera (the manifest's ``camera``), so no undistortion is
needed, and the known camera -> robot transform stands in for a calibration.
Without a shipped lifter the simulator's robot-frame joints are fed directly
(``feed_joints``), and the row says so.

The link is a stand-in that only records when each call returns (the command
"on the link"), so the figures are the runtime's own cost, not a bus's:

``robot_30hz``
    per camera frame, keypoints handed to the lifter -> ``feed_lifted`` returned
    (p50/p99/mean us); CPU share of one core over the run (frames and ticks);
    deadline misses (a frame whose processing ends after the next frame is due);
    peak resident memory.
``robot_reaction``
    for the frames that caused a command: keypoints in -> the link call returned.
"""
from __future__ import annotations

import importlib.util
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from bench.loops import not_available
from bench.timing import CpuShare, peak_rss_mb, sleep_until, summarize
from edge_runtime.robot.link.base import LinkInterface

FRAME_RATE_HZ = 30.0
TICK_RATE_HZ = 100.0
CAMERA_POSITION_M = (0.0, 1.0, 7.0)
"""Robot-frame camera position (m): 7 m in front of the base, 1.0 m above its top (1.9 m above the
floor), so the whole worker stays in the 100-degree canonical image from 3 to 6 m away."""
CAMERA_FROM_ROBOT = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
"""Rotation robot -> OpenCV camera axes for a camera looking along the robot's -z."""
WALK_XZ_M = ((0.0, 4.0), (0.0, 0.9), (0.0, 4.0))
"""The worker's floor path (robot x, z; m): toward the base and back."""


@dataclass(frozen=True)
class RobotConfig:
    worker_npz: str
    """joints_robot_m (T, 17, 3) at 30 Hz; keypoints_px (T, 17, 3) when a lifter is shipped."""
    seconds: float = 10.0
    """Length of the real-time run (s)."""
    assets: str = ""
    """Assets directory ('' = the shipped ones)."""
    lifter: str = ""
    """Lifter manifest precision to run ('' = none shipped: feed 3D joints)."""


def lifter_entry(entries: list[dict], precision: str = "int8") -> dict | None:
    """The shipped lifter of ``precision`` (or any lifter), or None."""
    lifters = [e for e in entries if e.get("arch") == "lifter"]
    return next((e for e in lifters if e["precision"] == precision), lifters[0] if lifters else None)


def prepare_worker(out_npz: str | Path, lifter: dict | None, seed: int = 0) -> Path:
    """The walking worker's robot-frame joints at 30 Hz and, for ``lifter`` (a manifest entry),
    their pixels in its canonical camera (score 1). Uses firmware_sim (parent process only)."""
    from edge_runtime.robot.keypoints import CameraModel
    from firmware_sim.people.human import Body
    from firmware_sim.people.motions import walk

    motion = walk(Body.from_height(1.75), WALK_XZ_M, speed_mps=1.2, rate_hz=FRAME_RATE_HZ,
                  rng=np.random.default_rng(seed))
    joints = np.asarray(motion.joints_m, np.float64)
    data = {"joints_robot_m": joints}
    if lifter is not None:
        cam = CameraModel.from_dict(lifter["camera"])
        p = (joints - np.asarray(CAMERA_POSITION_M)) @ CAMERA_FROM_ROBOT.T
        uv = p[..., :2] / p[..., 2:3] * [cam.fx_px, cam.fy_px] + [cam.cx_px, cam.cy_px]
        data["keypoints_px"] = np.concatenate([uv, np.ones(uv.shape[:-1] + (1,))], axis=-1)
    np.savez(out_npz, **data)
    return Path(out_npz)


class _KnownTransform:
    """camera -> robot frame by the simulated camera's known pose (stands in for a Calibration)."""

    def to_robot(self, joints_cam_m) -> np.ndarray:
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


def _schedule(seconds: float) -> list[tuple[float, int]]:
    """(due time from the start in s, frame index or -1 for a tick), in time order."""
    frames = [(k / FRAME_RATE_HZ, k) for k in range(int(seconds * FRAME_RATE_HZ))]
    ticks = [(j / TICK_RATE_HZ, -1) for j in range(int(seconds * TICK_RATE_HZ))]
    return sorted(frames + ticks)


def measure_robot(cfg: RobotConfig) -> list[dict]:
    """Run in a child process: see the module docstring."""
    from edge_runtime.core.manifest import ASSETS_DIR
    from edge_runtime.robot.loop import RobotLoop

    data = np.load(cfg.worker_npz)
    link = _TimedLink()
    if cfg.lifter:
        from edge_runtime.robot.lifter import LifterParams, StreamingLifter

        lifter = StreamingLifter.from_manifest(cfg.assets or ASSETS_DIR, LifterParams(precision=cfg.lifter))
        frames = data["keypoints_px"]
        loop = RobotLoop(link, calibration=_KnownTransform(), clock=time.perf_counter)
        feed = lambda k: loop.feed_lifted(lifter.push(k / FRAME_RATE_HZ, frames[k % len(frames)]))  # noqa: E731
        what = f"lifter-{cfg.lifter} (1 thread) + RobotLoop.feed_lifted"
    else:
        frames = data["joints_robot_m"]
        loop = RobotLoop(link, calibration=None, clock=time.perf_counter)
        feed = lambda k: loop.feed_joints(frames[k % len(frames)])  # noqa: E731
        what = "no lifter shipped: robot-frame 3D joints fed to RobotLoop.feed_joints"
    cycle, reaction, misses = [], [], 0
    with CpuShare() as cpu:
        t_start = time.perf_counter()
        for due, k in _schedule(cfg.seconds):
            sleep_until(t_start + due)
            if k < 0:
                loop.tick()
                continue
            t_in = time.perf_counter()
            rec = feed(k)
            t_out = time.perf_counter()
            cycle.append(t_out - t_in)
            misses += t_out > t_start + due + 1.0 / FRAME_RATE_HZ
            if rec.command is not None:
                reaction.append(link.last_call_s - t_in)
    st = loop.status()
    return [{"name": "robot_30hz", "rate_hz": FRAME_RATE_HZ, "seconds": round(cpu.wall_s, 2), "frames": len(cycle),
             "cpu_share_pct": cpu.pct, "deadline_misses": int(misses), **summarize(np.asarray(cycle) * 1e9),
             "peak_rss_mb": peak_rss_mb(), "commands": link.calls, "stops": st["stops"], "retracts": st["retracts"],
             "what": what + f", ticks at {TICK_RATE_HZ:g} Hz, a recording link stand-in"},
            {"name": "robot_reaction", **summarize(np.asarray(reaction) * 1e9),
             "what": "keypoints in -> command call on the link returned (frames that caused a command)"}]


def robot_rows(seconds: float, assets: Path, entries: list[dict], seed: int, workdir: Path) -> list[dict]:
    """Parent side: the robot rows (a child process), or a "not available" row when
    edge_runtime.robot.loop cannot be imported."""
    from bench.worker import ChildFailed, run_child

    if importlib.util.find_spec("edge_runtime.robot.loop") is None:
        return [not_available("robot_30hz", "edge_runtime.robot.loop is not importable")]
    lifter = lifter_entry(entries)
    npz = prepare_worker(workdir / "worker.npz", lifter, seed)
    try:
        return run_child("robot", asdict(RobotConfig(str(npz), seconds, str(assets),
                                                     lifter["precision"] if lifter else "")))
    except ChildFailed as e:  # the robot runtime is another module's work in progress: say so, go on
        return [not_available("robot_30hz", f"the robot cycle failed: {e}")]
