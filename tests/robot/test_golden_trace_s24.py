"""A golden trace of the robot runtime (session 24): ten seconds of the bench's robot scenario recorded as keypoints
(two simulated workers seen by the box's camera: one reaching into the arm's cell, one passing; tests/robot/data,
made by reports/bench/s24_react/golden24.py from frames 1500-1799 of its 60 s run), run through the tracker, the int8 lifter, the calibration, the hazard
monitor and the loop onto the CAN link with the bench's arm stand-in answering, on a simulated clock. What it decided
in every frame (state, reason, command, distance to a micrometre) and every command frame it put on the bus (id and
bytes, E2E counter and CRC included) must stay as recorded: a change meant to make a frame cheaper must not change a
decision (reports/bench/s24_react/report.md). A change meant to change decisions regenerates it, and says so."""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from edge_runtime.core.manifest import ASSETS_DIR

DATA = Path(__file__).resolve().parent / "data"
INPUT, GOLDEN = DATA / "golden_s24_keypoints.npz", DATA / "golden_s24_trace.json"

pytestmark = pytest.mark.skipif(not (ASSETS_DIR / "manifest.json").exists(), reason="no shipped lifter")


def golden_trace(input_npz: Path, zones: dict | None = None) -> dict:
    """The runtime's decisions and commands for the recorded keypoints (module docstring), as the bench's robot
    cycle drives it (bench.robot_cycle: the shipped box configuration, ``zones`` replacing some [zones] settings)."""
    import bench.robot_cycle as rc
    from bench.arm_echo import HEARTBEAT_FRAME, arm_on_bus
    from edge_runtime.core.manifest import load_manifest
    from edge_runtime.robot.loop import RobotLoop

    data = np.load(input_npz)
    xy = data["xy"].astype(np.float64)
    keypoints = np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1)
    seconds = len(keypoints) / rc.FRAME_RATE_HZ
    lifter = rc.lifter_entry(load_manifest(ASSETS_DIR)["models"])
    cfg = rc.RobotConfig("", seconds, "", lifter["precision"], tuple(data["arm_posture_rad"].tolist()),
                         simulated=True, zones=zones or {})
    box = rc._box(cfg.zones)
    feed = rc._Frames(cfg, box, {"keypoints_px": keypoints})
    sim = rc._SimClock()
    frames, commands = [], []
    with arm_on_bus(f"golden-s24-{id(cfg)}", cfg.arm_posture_rad, sim) as (bus, echo, link):
        ids = {m.name: m.frame_id for m in link.codec.db.messages}
        put = bus.send

        def send(msg, timeout=None):  # every command frame the runtime hands to the bus, with its bytes
            if msg.arbitration_id != ids[HEARTBEAT_FRAME]:
                commands.append([len(frames), msg.arbitration_id, bytes(msg.data).hex()])
            return put(msg, timeout)

        bus.send = send
        loop = RobotLoop(link, calibration=rc._known_calibration(box.calibration), zones=box.zones,
                         tracker=box.tracker, params=box.robot_loop, clock=sim)
        echo.serve(sim())
        for due, k in rc._schedule(seconds):
            sim.wait_until(due)
            if k == rc.ARM:
                echo.serve(sim())
                continue
            before = rc._counters(loop)
            rec = loop.tick() if k == rc.TICK else feed(loop, k)
            sent = {fid for _, fid in bus.sent}
            del bus.sent[:]
            if k != rc.TICK:
                kind = None if rec.command is None else rc._kind(rec.command, before, rc._counters(loop), sent,
                                                                    ids["ROBOT_MODE_CMD"])
                d = rec.distance_m
                frames.append({"state": rec.state, "reason": rec.reason, "kind": kind,
                               "distance_um": round(d * 1e6) if math.isfinite(d) else str(d)})
        counters = {k: v for k, v in loop.status().items() if isinstance(v, int)}
    return {"frames": frames, "commands": commands, "counters": counters}


def _first_difference(got: dict, want: dict) -> str:
    for key in ("frames", "commands"):
        for i, (g, w) in enumerate(zip(got[key], want[key])):
            if g != w:
                return f"{key}[{i}]: got {g}, recorded {w}"
        if len(got[key]) != len(want[key]):
            return f"{key}: {len(got[key])} entries, recorded {len(want[key])}"
    return f"counters: got {got['counters']}, recorded {want['counters']}"


def test_the_runtime_decides_and_commands_as_recorded():
    want = json.loads(GOLDEN.read_text())
    got = golden_trace(INPUT)
    assert got == want, _first_difference(got, want)
    # the recording has the commands that matter: frames that retract, scale the speed and resume, and escape turns
    # (planned again on their timer, these went out in ticks)
    assert {"retract", "speed", "resume"} <= {f["kind"] for f in want["frames"]} and want["counters"]["escapes"] >= 2


def test_another_decision_rule_is_caught():
    """The comparison sees a change of decisions: the same keypoints with the arm working at full speed until it
    must stop (stop-only, ``[zones] speed_scaling`` off) give another trace."""
    got = golden_trace(INPUT, zones={"speed_scaling": False})
    assert got != json.loads(GOLDEN.read_text())
