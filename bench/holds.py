"""What already holds (issue 16): the safety figures the fuzzing fixes must not break, re-measured.

Each measurement runs in this one process, in SIMULATED time where time matters (the arm and
the runtime on :class:`firmware_sim.robot.controller.SimulatedRobot`'s clock, the real link
code in between), so a loaded shared machine cannot skew a figure and a run is repeatable
from its seed::

    python -m bench.holds arm-stop --trials 20 --seed 0        # both links, link loss and pose loss
    python -m bench.holds forged --commands 200 --seed 0       # unsigned, forged, replayed at a signed arm
    python -m bench.holds tampered                             # every shipped model, three ways
    python -m bench.holds memory --wearable-hours 12 --robot-hours 3 [--robot-link sim|stand-in]

Each prints one JSON document (``--json OUT`` writes it too). What each measures:

``arm-stop``
    The runtime (``RobotLoop``, the shipped box configuration, nobody in the scene so the arm
    works its task) drives the simulated Sawyer over CAN or signed MAVLink, stepped every
    1 ms; the loop ticks every 10 ms and gets a camera frame every 1/30 s, each at a random
    phase. While the arm moves, at a random instant, either every frame between the two ends
    is lost from then on (``link``: the controller's 200 ms watchdog must stop the arm) or the
    pose stream stops (``pose``: the loop's 200 ms staleness check must send ``stop``). Per
    trial: ms from the last valid runtime frame the arm received (``link``) or the last pose
    the loop got (``pose``) to the arm's controller stopping it (``stop_ms``) and to the arm
    at rest (``rest_ms``), and ms from the loss itself to the stop (``stop_after_loss_ms``).
``forged``
    A signed MAVLink arm (the simulated controller) running, and commands that would change
    what it does (stop, red alarm, retract) written onto its line in thirds: unsigned, signed
    with another key, and genuine signed packets recorded earlier and sent again. Accepted =
    executed by the controller (its command counter, its light, its mode). A control packet
    injected the same way but signed with the arm's key must be executed.
``tampered``
    A copy of the shipped assets per case with one model file changed (one byte flipped,
    truncated to half, or swapped for another shipped model's file), loaded the way the box
    loads it (``Engine.from_manifest`` for the ConvLSTM, ``StreamingLifter.from_manifest``
    for the lifter); refused = ``ModelIntegrityError`` before anything runs. One more case,
    the model and its manifest hash replaced together (with its step model and hash), shows what a sha256 cannot prove
    (reported, not counted as refused). The untouched copy must load (the control).
``memory``
    The wearable loop (``WearableLoop`` with the int8 ConvLSTM + ``AlertPublisher`` on a
    virtual CAN bus) fed a simulated drive in 100 ms blocks for N hours of stream time, and
    the robot loop (int8 lifter + ``RobotLoop`` + the simulated Sawyer over CAN, or a recording
    stand-in link, a worker walking in and out of the zones) for M hours of simulated time, both
    as fast as they go;
    resident memory (VmRSS) and the number of live Python objects after every hour
    (``--every-h``). Growth is the last sample's against the first's.
"""
from __future__ import annotations

import argparse
import gc
import json
import shutil
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from bench.timing import rss_mb

STEP_S = 0.001
"""Simulated time step of the arm-stop trials (s): the resolution of their figures."""
TICK_S = 0.01
"""The runtime loop's control period (s), as the box runs it."""
FRAME_S = 1.0 / 30.0
"""Camera period (s)."""


def _stats(values) -> dict:
    v = np.asarray(values, float)
    if not len(v):
        return {"n": 0}
    return {"n": int(len(v)), "min": round(float(v.min()), 1), "median": round(float(np.median(v)), 1),
            "max": round(float(v.max()), 1)}


# ----------------------------------------------------------------------------------------------
# arm stop after link or pose loss

def arm_stop_trial(kind: str, loss: str, rng: np.random.Generator) -> dict:
    """One trial (see the module docstring); times in ms of simulated time."""
    from edge_runtime.robot.loop import RobotLoop
    from firmware_sim.robot.controller import SimClock, SimulatedRobot
    from firmware_sim.scenarios.hrc_world import box_config, task_start_posture

    box = box_config()
    lp = box.robot_loop
    clock = SimClock()
    sim = SimulatedRobot(kind, clock=clock,
                         q0_rad=task_start_posture(lp.task_waypoints_m[0], lp.task_pitch_rad, lp.task_yaw_rad))
    loop = RobotLoop(sim.link, zones=box.zones, tracker=box.tracker, params=lp, clock=clock)
    ctl = sim.controller
    next_tick, next_frame = rng.uniform(0, TICK_S), rng.uniform(0, FRAME_S)
    t_loss = rng.uniform(3.0, 6.0)  # after the link is up and the arm at work
    lost, last_pose, last_rx, stop_at, rest_at, speed_at_loss = False, None, None, None, None, None
    try:
        while clock() < t_loss + 2.0 and rest_at is None:
            now = clock()
            if not lost and now >= t_loss and ctl.arm.moving:  # cut only while the arm moves
                lost, t_loss, speed_at_loss = True, now, float(np.linalg.norm(ctl.arm.ee_velocity_mps()))
                if loss == "link":
                    sim.faults.drop = 1.0
            if now >= next_frame - 1e-9:
                next_frame += FRAME_S
                if not (lost and loss == "pose"):
                    loop.feed_joints(None)  # an empty scene: the arm works
                    last_pose = now
            if now >= next_tick - 1e-9:
                next_tick += TICK_S
                loop.tick()
            sim.step(STEP_S)
            if lost and stop_at is None and ctl.mode == "stopped":
                stop_at, last_rx = clock(), ctl._last_valid_rx
            if stop_at is not None and not ctl.arm.moving:
                rest_at = clock()
    finally:
        sim.close()
    if stop_at is None or rest_at is None:
        return {"link": kind, "loss": loss, "stopped": False, "t_loss_s": round(t_loss, 4)}
    ref = last_rx if loss == "link" else last_pose
    return {"link": kind, "loss": loss, "stopped": True, "t_loss_s": round(t_loss, 4),
            "speed_at_loss_mps": round(speed_at_loss, 3), "stop_ms": round((stop_at - ref) * 1000, 1),
            "rest_ms": round((rest_at - ref) * 1000, 1), "stop_after_loss_ms": round((stop_at - t_loss) * 1000, 1),
            "watchdog": bool(ctl.watchdog)}


def arm_stop(trials: int, seed: int, links=("can", "mavlink"), losses=("link", "pose")) -> dict:
    rng = np.random.default_rng(seed)
    out = {}
    for kind in links:
        for loss in losses:
            rows = [arm_stop_trial(kind, loss, rng) for _ in range(trials)]
            done = [r for r in rows if r["stopped"]]
            out[f"{kind}_{loss}"] = {"trials": len(rows), "stopped": len(done),
                                     "stop_ms": _stats([r["stop_ms"] for r in done]),
                                     "rest_ms": _stats([r["rest_ms"] for r in done]),
                                     "stop_after_loss_ms": _stats([r["stop_after_loss_ms"] for r in done]),
                                     "by_watchdog": sum(r["watchdog"] for r in done), "rows": rows}
    return out


# ----------------------------------------------------------------------------------------------
# unsigned, forged and replayed commands at a signed arm

def forged(commands: int, seed: int) -> dict:
    import io

    from edge_runtime.robot.link.protocol import (
        MAV_CMD_ALARM,
        MAV_CMD_RETRACT,
        MAV_CMD_STOP_RESUME,
        RUNTIME_COMPID,
        RUNTIME_SYSID,
        make_mavlink,
    )
    from firmware_sim.robot.controller import TEST_SIGNING_KEY, SimulatedRobot

    rng = np.random.default_rng(seed)
    other_key = bytes(rng.integers(0, 256, 32, dtype=np.uint8))
    assert other_key != TEST_SIGNING_KEY
    with SimulatedRobot("mavlink", signing_key=TEST_SIGNING_KEY) as sim:
        sim.step(0.05)
        sim.link.resume()
        sim.step(0.05)
        # genuine commands, recorded on their way out: the replay's material
        recorded: list[bytes] = []
        write = sim.link.stream.write
        sim.link.stream.write = lambda data: (recorded.append(bytes(data)), write(data))[1]
        for cmd in (lambda: sim.link.set_alarm("red", 2000.0, 70.0), lambda: sim.link.stop(),
                    lambda: sim.link.move_to((0.45, 0.25, 0.55), 0.0, 0.0)):
            cmd()
        sim.link.stream.write = write
        sim.step(0.05)
        sim.link.resume()
        sim.link.set_alarm("green", 0.0, 0.0)
        sim.step(0.1)
        before = dict(sim.controller.counters)
        state0 = (sim.controller.mode, sim.controller.light)
        port0 = dict(sim.controller.port.counters)
        kinds = {"unsigned": 0, "forged": 0, "replayed": 0}
        for i in range(commands):
            kind = ("unsigned", "forged", "replayed")[i % 3]
            kinds[kind] += 1
            if kind == "replayed":
                data = recorded[int(rng.integers(len(recorded)))]
            else:
                buf = io.BytesIO()
                mav = make_mavlink(buf, RUNTIME_SYSID, RUNTIME_COMPID, None if kind == "unsigned" else other_key,
                                   int(rng.integers(0, 256)))
                params = ((MAV_CMD_STOP_RESUME, 0, 0, 0, 0, 0),  # stop
                          (MAV_CMD_ALARM, 3, 4000, 80, 0, 0),  # red light, 4 kHz
                          (MAV_CMD_RETRACT, 0.3, 0.4, 0.3, 0, 0))[int(rng.integers(3))]
                mav.command_long_send(1, 1, params[0], 0, *params[1:], 0, 900.0 + i)  # param7: a fresh seq
                data = buf.getvalue()
            sim.link.stream.write(data)
            sim.step(0.01)
        sim.step(0.1)
        port = sim.controller.port.counters
        accepted = sim.controller.counters["commands"] - before["commands"]
        refused = {k: port.get(f"signature_{k}", 0) - port0.get(f"signature_{k}", 0) for k in kinds}
        state = {"mode": sim.controller.mode, "light": sim.controller.light}
        # the control: the same injection, signed with the arm's key, is executed (the path can accept)
        buf = io.BytesIO()
        make_mavlink(buf, RUNTIME_SYSID, RUNTIME_COMPID, TEST_SIGNING_KEY, 7).command_long_send(
            1, 1, MAV_CMD_ALARM, 0, 3, 4000, 80, 0, 0, 0, 2000.0)
        sim.link.stream.write(buf.getvalue())
        sim.step(0.05)
        control = {"accepted": int(sim.controller.counters["commands"] - before["commands"] - accepted),
                   "light": sim.controller.light}
        return {"commands": commands, "by_kind": kinds, "accepted": int(accepted),
                "refused_and_counted": refused, "state_unchanged": (state["mode"], state["light"]) == state0,
                "state": state, "recorded_genuine_packets": len(recorded),
                "control_signed_with_the_arm_key": control}


# ----------------------------------------------------------------------------------------------
# tampered models

def tampered() -> dict:
    from edge_runtime.core.manifest import ASSETS_DIR, STREAM_ARCH, load_manifest
    from edge_runtime.errors import ModelIntegrityError
    from edge_runtime.robot.lifter import LifterParams, StreamingLifter
    from edge_runtime.wearable.classifier import Engine
    from edge_runtime.wearable.stream_decider import StreamModel

    entries = load_manifest(ASSETS_DIR)["models"]

    def load(assets: Path, entry: dict) -> None:
        if entry["arch"] == "lifter":
            StreamingLifter.from_manifest(assets, LifterParams(precision=entry["precision"]))
        elif entry["arch"] == STREAM_ARCH:  # the streaming decider's classifier (issue 12)
            StreamModel.from_manifest(assets, entry["name"])
        else:  # a step model is loaded by the classifier entry that names it
            Engine.from_manifest(assets, next((e["name"] for e in entries if e.get("step_model") == entry["name"]),
                                              entry["name"]))

    def flip(data: bytes, other: bytes) -> bytes:
        mid = len(data) // 2
        return data[:mid] + bytes([data[mid] ^ 0x01]) + data[mid + 1:]

    ways = {"one byte flipped": flip, "truncated to half": lambda d, o: d[: len(d) // 2],
            "swapped for another shipped model": lambda d, o: o}
    rows = []
    with tempfile.TemporaryDirectory(prefix="holds-tampered-") as tmp:
        for entry in entries:
            other = next(e for e in entries if e["file"] != entry["file"])
            for way, change in ways.items():
                assets = Path(tmp) / f"{entry['name']}-{len(rows)}"
                shutil.copytree(ASSETS_DIR, assets)
                path = assets / entry["file"]
                path.write_bytes(change(path.read_bytes(), (assets / other["file"]).read_bytes()))
                try:
                    load(assets, entry)
                    verdict, why = "LOADED", ""
                except ModelIntegrityError as e:
                    verdict, why = "refused", str(e).split(": ", 1)[-1][:90]
                rows.append({"model": entry["name"], "tampering": way, "verdict": verdict, "error": why})
        # the control: the untouched copy loads, so a refusal above is the tampering's doing
        control = Path(tmp) / "untouched"
        shutil.copytree(ASSETS_DIR, control)
        for entry in entries:
            load(control, entry)
        # the model and its hash replaced together: integrity, not authorship (issue 16 item 6); its step model
        # too (the box refuses a step model that does not decide as the one-shot model it is loaded with)
        entry = next(e for e in entries if e["name"] == "convlstm-int8")
        by_name = {e["name"]: e for e in entries}
        swaps = {entry["name"]: "convlstm-fp32", entry.get("step_model"): by_name["convlstm-fp32"].get("step_model")}
        swaps = {by_name[k]["name"]: by_name[v] for k, v in swaps.items() if k and v}
        assets = Path(tmp) / "with-hash"
        shutil.copytree(ASSETS_DIR, assets)
        public_key = _sign_genuine(assets, Path(tmp) / "keys")  # the builder signs what he built
        manifest = json.loads((assets / "manifest.json").read_text())
        for e in manifest["models"]:
            if e["name"] in swaps:
                e["sha256"] = swaps[e["name"]]["sha256"]
                shutil.copy(assets / swaps[e["name"]]["file"], assets / e["file"])
        (assets / "manifest.json").write_text(json.dumps(manifest))
        try:
            load(assets, entry)
            with_hash = "LOADED (a sha256 proves integrity, not who built the model)"
        except ModelIntegrityError as e:
            with_hash = f"refused: {e}"
        signed = "not checked: the signed-models extra (cryptography) is not installed"
        if public_key is not None:
            try:
                Engine.from_manifest(assets, entry["name"], public_key_file=public_key)
                signed = "LOADED"
            except ModelIntegrityError as e:
                signed = f"refused: {str(e).split(': ', 1)[-1]}"
    refused = sum(r["verdict"] == "refused" for r in rows)
    return {"cases": len(rows), "refused": refused, "untouched_copy_loads": True, "rows": rows,
            "model_and_hash_replaced": with_hash, "model_and_hash_replaced_on_a_box_with_a_public_key": signed}


def _sign_genuine(assets: Path, keys: Path) -> Path | None:
    """A key pair in ``keys`` and the untouched manifest of ``assets`` signed with it (the public
    key file), or None without the signed-models extra."""
    try:
        from export.sign import keygen, sign_manifest

        private, public = keygen(keys)
    except ValueError:  # SignError: cryptography is missing
        return None
    sign_manifest(assets, private)
    return public


# ----------------------------------------------------------------------------------------------
# memory over hours

def _sample(hour: float, t0: float) -> dict:
    gc.collect()
    return {"hour": round(hour, 2), "rss_mb": round(rss_mb(), 1), "objects": len(gc.get_objects()),
            "cpu_s": round(time.process_time() - t0, 1)}


def _growth(samples: list[dict]) -> dict:
    first, last = samples[0], samples[-1]
    return {"rss_mb": round(last["rss_mb"] - first["rss_mb"], 1), "objects": last["objects"] - first["objects"],
            "from_hour": first["hour"], "to_hour": last["hour"]}


def wearable_memory(hours: float, seed: int, drive_minutes: float = 60.0, every_h: float = 1.0,
                    progress=None) -> dict:
    """The wearable loop over ``hours`` of stream time (a ``drive_minutes`` drive, repeated)."""
    from edge_runtime.canbus.bus import open_bus
    from edge_runtime.core.manifest import ASSETS_DIR
    from edge_runtime.wearable.alerts import AlertPublisher
    from edge_runtime.wearable.classifier import Engine
    from edge_runtime.wearable.loop import WearableLoop
    from edge_runtime.wearable.sources import SAMPLE_RATE_HZ, ImuBlock
    from firmware_sim.devices.wrist import simulate_drive

    acc = np.ascontiguousarray(simulate_drive(drive_minutes, seed=seed).acc_mps2, dtype=np.float32)
    engine = Engine.from_manifest(ASSETS_DIR, "int8", threads=1)
    pub = AlertPublisher(open_bus("virtual", f"holds-{id(acc)}"), heartbeat_period_s=0.1)
    decisions = {"n": 0, "alerted": 0}

    def on_decision(d) -> None:
        decisions["n"] += 1
        if d.alerted:
            decisions["alerted"] += bool(pub.on_decision(d))

    loop = WearableLoop(engine, on_decision=on_decision)
    block = int(SAMPLE_RATE_HZ // 10)  # 100 ms, as a serial source hands them over
    per_hour = int(3600 * SAMPLE_RATE_HZ)
    per_sample = int(every_h * per_hour)
    n_total = int(hours * per_hour)
    t0 = time.process_time()
    samples = []
    pub.start()
    try:
        for i in range(0, n_total, block):
            j = i % len(acc)
            chunk = acc[j: j + block]
            loop.feed(ImuBlock(i / SAMPLE_RATE_HZ, chunk, continuous=True))
            done = i + len(chunk)
            if done // per_sample != i // per_sample:
                samples.append(_sample(done / per_hour, t0))
                if progress:
                    progress(f"wearable hour {samples[-1]['hour']:g}: {samples[-1]}")
    finally:
        pub.close()
    return {"hours": hours, "drive_minutes": drive_minutes, "decisions": decisions["n"],
            "alerts_sent": decisions["alerted"], "samples": samples, "growth": _growth(samples)}


def robot_memory(hours: float, seed: int, every_h: float = 1.0, link: str = "sim", progress=None) -> dict:
    """The robot loop over ``hours`` of simulated time: int8 lifter, RobotLoop, a worker walking
    from 6 m to 1 m of the base and back, again and again; ``link`` "sim": the simulated Sawyer
    over CAN (the real link code both ways; most of the CPU goes to the simulated arm), "stand-in":
    bench.robot_cycle's recording link (the loop and the lifter alone, about 6x faster)."""
    from bench.robot_cycle import CAMERA_FROM_ROBOT, CAMERA_POSITION_M, _KnownTransform, _TimedLink
    from edge_runtime.robot.keypoints import CameraModel
    from edge_runtime.robot.lifter import StreamingLifter
    from edge_runtime.robot.loop import RobotLoop
    from firmware_sim.people.human import Body
    from firmware_sim.people.motions import walk
    from firmware_sim.robot.controller import SimClock, SimulatedRobot
    from firmware_sim.scenarios.hrc_world import box_config, task_start_posture

    box = box_config()
    lifter = StreamingLifter.from_manifest(params=box.lifter)
    cam = CameraModel.from_dict(lifter.entry["camera"])
    motion = walk(Body.from_height(1.75), ((0.0, 6.0), (0.0, 1.0), (0.0, 6.0)), speed_mps=1.2,
                  rate_hz=1.0 / FRAME_S, rng=np.random.default_rng(seed))
    p = (np.asarray(motion.joints_m, float) - np.asarray(CAMERA_POSITION_M)) @ CAMERA_FROM_ROBOT.T
    uv = p[..., :2] / p[..., 2:3] * [cam.fx_px, cam.fy_px] + [cam.cx_px, cam.cy_px]
    keypoints = np.concatenate([uv, np.ones(uv.shape[:-1] + (1,))], axis=-1)
    lp = replace(box.robot_loop, records=1000)  # the loop keeps its last frame records by design
    clock = SimClock()
    if link == "sim":
        sim = SimulatedRobot("can", clock=clock,
                             q0_rad=task_start_posture(lp.task_waypoints_m[0], lp.task_pitch_rad, lp.task_yaw_rad))
        the_link, step, close = sim.link, sim.step, sim.close
    else:
        the_link, step, close = _TimedLink(), clock.advance, lambda: None
    loop = RobotLoop(the_link, calibration=_KnownTransform(), zones=box.zones, tracker=box.tracker, params=lp,
                     clock=clock)
    ticks_per_frame = 3  # 10 ms ticks, a frame every 30 ms: 33.3 Hz, close to the camera's 30
    n_frames = int(hours * 3600 / (ticks_per_frame * TICK_S))
    per_hour = int(3600 / (ticks_per_frame * TICK_S))
    per_sample = int(every_h * per_hour)
    t0 = time.process_time()
    samples = []
    try:
        for k in range(n_frames):
            loop.feed_lifted(lifter.push(clock(), keypoints[k % len(keypoints)]))
            for _ in range(ticks_per_frame):
                loop.tick()
                step(TICK_S)
            if (k + 1) % per_sample == 0:
                samples.append(_sample((k + 1) / per_hour, t0))
                if progress:
                    progress(f"robot hour {samples[-1]['hour']:g}: {samples[-1]}")
        status = loop.status()
    finally:
        close()
    return {"hours": hours, "link": link, "frames": n_frames, "stops": status["stops"], "retracts": status["retracts"],
            "link_errors": status["link_errors"], "samples": samples, "growth": _growth(samples)}


# ----------------------------------------------------------------------------------------------

def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m bench.holds", description=__doc__.splitlines()[0])
    sub = ap.add_subparsers(dest="what", required=True)
    p = sub.add_parser("arm-stop", help="the arm stops after its link or pose stream is lost")
    p.add_argument("--trials", type=int, default=20, help="per link and kind of loss")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--link", choices=("can", "mavlink"), action="append")
    p.add_argument("--loss", choices=("link", "pose"), action="append")
    p = sub.add_parser("forged", help="unsigned, forged and replayed commands at a signed arm")
    p.add_argument("--commands", type=int, default=200)
    p.add_argument("--seed", type=int, default=0)
    sub.add_parser("tampered", help="tampered models refused")
    p = sub.add_parser("memory", help="resident memory over hours of the wearable and robot loops")
    p.add_argument("--wearable-hours", type=float, default=12.0)
    p.add_argument("--robot-hours", type=float, default=3.0)
    p.add_argument("--robot-link", choices=("sim", "stand-in"), default="sim",
                   help="the robot loop's link: the simulated Sawyer over CAN, or a recording stand-in")
    p.add_argument("--every-h", type=float, default=1.0, help="a memory sample every this many hours")
    p.add_argument("--seed", type=int, default=5)
    for p in sub.choices.values():
        p.add_argument("--json", metavar="OUT", help="also write the result here")
    a = ap.parse_args(argv)
    log = lambda line: print(line, file=sys.stderr, flush=True)  # noqa: E731
    if a.what == "arm-stop":
        out = arm_stop(a.trials, a.seed, tuple(a.link or ("can", "mavlink")), tuple(a.loss or ("link", "pose")))
    elif a.what == "forged":
        out = forged(a.commands, a.seed)
    elif a.what == "tampered":
        out = tampered()
    else:
        out = {}
        if a.wearable_hours > 0:
            out["wearable"] = wearable_memory(a.wearable_hours, a.seed, every_h=a.every_h, progress=log)
        if a.robot_hours > 0:
            out["robot"] = robot_memory(a.robot_hours, a.seed, every_h=a.every_h, link=a.robot_link, progress=log)
    out = {"command": "python -m bench.holds " + " ".join(sys.argv[1:] if argv is None else argv), **out}
    text = json.dumps(out, indent=1)
    print(text)
    if a.json:
        Path(a.json).parent.mkdir(parents=True, exist_ok=True)
        Path(a.json).write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
