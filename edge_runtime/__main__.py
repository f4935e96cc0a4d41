"""``python -m edge_runtime <command>``: the programs that run on the box.

wearable   IMU -> detector -> ConvLSTM -> alert decisions on CAN (DESIGN.md section 7)
lift       2D keypoints -> streaming pose lifter -> 3D joints
robot      camera keypoints -> lifter -> hazard zones -> commands to the arm (CAN or MAVLink)

Commands other than ``wearable`` live in their own module, which defines
``add_arguments(parser)``, ``cmd(args)`` and ``BAD_INPUT`` (the exception types
that mean "the user's input was bad": one line, exit 2).
"""
from __future__ import annotations

import argparse
import json
import sys
import time

from edge_runtime.cli import CliError, add_module_commands, make_parser, run
from edge_runtime.core.manifest import ASSETS_DIR


def _add_wearable(sub: argparse._SubParsersAction) -> None:
    p = sub.add_parser("wearable", help="run the wearable distraction loop")
    src = p.add_mutually_exclusive_group()
    src.add_argument("--replay", metavar="FILE.csv", help="a recording t,ax,ay,az (s, m/s^2), processed as fast as possible")
    src.add_argument("--imu", metavar="serial:PATH[?key=HEX] | sim[?minutes=M&seed=S&...]",
                     help="a live IMU: MAVLink HIGHRES_IMU/SCALED_IMU on a serial line (key: MAVLink 2 signing "
                          "key), or 'sim': the simulated IMU firmware on a pseudo-terminal (development checkouts)")
    p.add_argument("--duration", type=float, metavar="S", help="stop a live source after S seconds")
    p.add_argument("--can-log", metavar="OUT.log|.asc|.blf|.csv", help="write every CAN frame sent (python-can formats)")
    p.add_argument("--alerts", metavar="OUT.jsonl", help="write one JSON object per classifier decision")
    p.add_argument("--config", metavar="BOX.toml", help="the box configuration (see edge_runtime/box.example.toml)")
    p.add_argument("--print-config", action="store_true", help="print the effective configuration as TOML and exit")
    p.add_argument("--assets", metavar="DIR", help="model directory with manifest.json [model] assets")
    p.add_argument("--model", help="manifest entry: a name, or a precision (int8, fp32) [model] name")
    p.add_argument("--threads", type=int, help="onnxruntime intra-op threads [model] threads")
    p.add_argument("--min-confidence", type=float, help="below this the decision is 'uncertain' [alerts] min_confidence")
    p.add_argument("--threshold", type=float, help="detector threshold (m/s^2) [detector] threshold_mps2")
    p.add_argument("--realtime", action="store_true", help="pace a replay at its own sample rate")
    p.add_argument("--quiet", action="store_true", help="print only the summary")
    p.set_defaults(func=run_wearable)


def effective_config(args: argparse.Namespace):
    """The config file, then the command-line flags on top, validated as one."""
    from edge_runtime import config

    cfg = config.load(args.config)
    cfg = config.override(cfg, "model", assets=args.assets, name=args.model, threads=args.threads)
    cfg = config.override(cfg, "alerts", min_confidence=args.min_confidence)
    return config.override(cfg, "detector", threshold_mps2=args.threshold)


def run_wearable(args: argparse.Namespace) -> int:
    from edge_runtime.wearable.detector import DetectorConfig
    from edge_runtime.wearable.loop import AlertPolicy, WearableLoop
    from edge_runtime.wearable.sources import ImuBlock, ReplayStats, read_imu_csv

    cfg = effective_config(args)
    if args.print_config:
        print(cfg.to_toml(), end="")
        return 0
    if not (args.replay or args.imu):
        raise CliError("wearable: give a source: --replay FILE.csv, --imu serial:PATH or --imu sim")
    policy = AlertPolicy(min_confidence=cfg.alerts.min_confidence, never_alert=cfg.alerts.never_alert)
    d = cfg.detector
    det_cfg = DetectorConfig(window_frames=d.window_frames, threshold_mps2=d.threshold_mps2,
                             pre_frames=d.pre_frames, post_frames=d.post_frames)
    stats = ReplayStats()
    if args.replay:
        blocks = read_imu_csv(args.replay, stats)  # bad input is reported before the model loads
    else:
        live = _open_live_source(args.imu, cfg)
        blocks = live.blocks(args.duration)
    from edge_runtime.wearable.classifier import Engine

    engine = Engine.from_manifest(cfg.model.assets or ASSETS_DIR, cfg.model.name, threads=cfg.model.threads)
    unknown = sorted(set(cfg.alerts.never_alert) - set(engine.classes))
    if unknown:
        from edge_runtime.config import ConfigError

        raise ConfigError(f"[alerts] never_alert: {unknown} are not classes of {engine.name} ({', '.join(engine.classes)})")
    for note in stats.notices:
        print(f"notice: {note}", file=sys.stderr)

    out = open(args.alerts, "w") if args.alerts else None
    health = {"sensor": "ok", "non_finite": 0, "gaps": 0, "saturated": 0}
    latencies_ms: list[float] = []

    def handle(d):
        if d.alerted:  # 'alerted' means: a DISTRACTION_ALERT frame went out for it
            d.alerted = pub.on_decision(d)
            d.status = "alert" if d.alerted else "alert_not_sent"
            if d.alerted and d.rx_monotonic_s is not None:
                d.latency_ms = (time.monotonic() - d.rx_monotonic_s) * 1e3
                latencies_ms.append(d.latency_ms)
        if out:
            out.write(json.dumps(d.to_json()) + "\n")
        if not args.quiet:
            mark = "ALERT" if d.alerted else d.status
            print(f"t={d.t_trigger_s:9.2f}s  {d.label:<12} p={d.confidence:.2f}  {mark}")

    loop = WearableLoop(engine, det_cfg, policy, on_decision=handle, sample_rate_hz=cfg.imu.sample_rate_hz)
    source_stats = None if args.replay else live.stats
    pub = _open_publisher(cfg, args.can_log, engine, lambda: _status(loop, health, source_stats))
    sensor_state = "ok"
    pub.set_status(state="running")
    t_wall = time.perf_counter()
    try:
        for block in blocks:
            if not isinstance(block, ImuBlock):  # a live source's status event
                if block.state != sensor_state:
                    print(f"sensor: {block.state} ({block.since_s:.2f} s since the last sample)", file=sys.stderr)
                    sensor_state = health["sensor"] = block.state
                    pub.send_heartbeat()  # a change of state is reported at once, not at the next period
                if block.state == "disconnected":
                    break
                continue
            if sensor_state != "ok":
                print("sensor: ok", file=sys.stderr)
                sensor_state = health["sensor"] = "ok"
                pub.send_heartbeat()
            if args.realtime and args.replay:
                _feed_paced(loop, block)
            else:
                loop.feed(block)
    except KeyboardInterrupt:
        pass
    finally:
        pub.close()
        if out:
            out.close()
        if not args.replay:
            live.close()
    wall = time.perf_counter() - t_wall
    s = loop.stats
    stream_s = s.samples / loop.rate_hz
    print(
        f"summary: {stream_s:.1f} s of IMU data ({s.samples} samples) in {wall:.3f} s "
        f"({stream_s / max(wall, 1e-9):,.0f}x real time); model {engine.name} ({engine.precision})\n"
        f"  captures {s.captures}: alerts {s.statuses['alert']}, uncertain {s.statuses['uncertain']}, "
        f"not alerted {s.statuses['not_alerted']}\n"
        f"  by class: " + (", ".join(f"{k} {v}" for k, v in sorted(s.labels.items())) or "none") + "\n"
        f"  bad samples: non-finite {s.non_finite}, dropped (time not advancing) {stats.dropped_non_monotonic}, "
        f"gaps {stats.gaps}, detector restarts {s.detector_resets}"
    )
    c = pub.summary()
    print(f"  CAN {cfg.can.interface}:{cfg.can.channel}: frames sent {c['frames_sent']} (alerts {c['alerts_sent']}, "
          f"heartbeats {c['heartbeats_sent']}), send errors {c['send_errors']}, reconnects {c['reconnects']}"
          + (f"; logged to {args.can_log}" if args.can_log else ""))
    if latencies_ms:
        import numpy as np

        print(f"  alert latency (last capture sample arrived -> frame handed to the bus): median "
              f"{np.median(latencies_ms):.2f} ms, p99 {np.percentile(latencies_ms, 99):.2f} ms, "
              f"max {max(latencies_ms):.2f} ms over {len(latencies_ms)} alerts")
    if not args.replay:
        print("  serial link: " + ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in vars(live.stats).items()))
    return 0


def _open_publisher(cfg, can_log, engine, status_provider):
    """The CAN side: the configured python-can bus, alerts and the WEARABLE_STATUS heartbeat."""
    from edge_runtime.canbus.bus import open_bus
    from edge_runtime.wearable.alerts import AlertPublisher

    c = cfg.can

    def bus_factory():
        return open_bus(c.interface, c.channel, c.bitrate, host=c.host, port=c.port)

    try:
        pub = AlertPublisher(bus_factory(), heartbeat_period_s=c.heartbeat_period_s, log_path=can_log,
                             bus_factory=bus_factory, status_provider=status_provider)
    except ValueError as e:  # python-can's Logger: unknown file suffix
        raise CliError(f"--can-log {can_log}: {e}") from None
    # ModelVersion (8 bits): the first byte of the model file's sha256, as listed in manifest.json
    pub.set_status(model_version=int(engine.entry.get("sha256", "00")[:2], 16))
    return pub.start()


def _status(loop, health: dict, source_stats=None) -> dict:
    """WEARABLE_STATUS fields from the loop's (and the live source's) counters; called by
    the heartbeat thread. A counter that grew since the last heartbeat marks the sensor
    degraded for that period."""
    s = loop.stats
    saturated = getattr(source_stats, "saturated", 0)
    dropped = s.non_finite + getattr(source_stats, "dropped", 0)
    if health["sensor"] != "ok":
        state, sensor = "sensor_silent", "silent"
    elif s.samples == 0:
        state, sensor = "starting", "ok"  # no sample yet: nothing to vouch for
    elif s.non_finite > health["non_finite"]:
        state, sensor = "degraded", "nan_samples"
    elif saturated > health["saturated"]:
        state, sensor = "degraded", "saturated"
    elif s.detector_resets > health["gaps"]:
        state, sensor = "degraded", "gaps"
    else:
        state, sensor = "running", "ok"
    health["non_finite"], health["gaps"], health["saturated"] = s.non_finite, s.detector_resets, saturated
    return {"state": state, "sensor_health": sensor, "dropped_samples": min(dropped, 65535)}


def _open_live_source(spec: str, cfg):
    """``serial:PATH[?key=HEX]`` -> a MAVLink IMU source on that serial line;
    ``sim[?options]`` -> the simulated IMU firmware as a child process on a pseudo-terminal."""
    if spec == "sim" or spec.startswith("sim?"):
        from edge_runtime.wearable.sim_source import SimImuSource, SimSourceError

        try:
            return SimImuSource(spec, silence_timeout_s=cfg.imu.silence_timeout_s)
        except SimSourceError as e:
            raise CliError(str(e)) from None
    from edge_runtime.core.serial_line import parse_serial_spec

    try:
        path, key = parse_serial_spec(spec)
    except ValueError as e:
        raise CliError(f"--imu: {e}") from None
    from edge_runtime.wearable.mavlink_source import MavlinkImuSource

    try:
        return MavlinkImuSource(path, signing_key=key, silence_timeout_s=cfg.imu.silence_timeout_s)
    except ValueError as e:
        raise CliError(str(e)) from None


def _feed_paced(loop, block) -> None:
    """Feed one sample period at a time on a monotonic clock (no busy waiting)."""
    start = time.monotonic()
    from edge_runtime.wearable.sources import ImuBlock

    for i in range(len(block.acc_mps2)):
        delay = start + (i + 1) / loop.rate_hz - time.monotonic()  # sample i is complete one period later
        if delay > 0:
            time.sleep(delay)
        loop.feed(ImuBlock(block.t0_s + i / loop.rate_hz, block.acc_mps2[i : i + 1], block.continuous or i > 0,
                           rx_monotonic_s=time.monotonic()))


def build_parser() -> argparse.ArgumentParser:
    parser, sub = make_parser("python -m edge_runtime", __doc__.splitlines()[0])
    _add_wearable(sub)
    add_module_commands(sub, __package__, _MODULE_COMMANDS)
    return parser


_MODULE_COMMANDS = (
    ("lift", "robot.lift_command", "lift 2D keypoints (JSON lines, camera or simulator) to 3D joints"),
    ("robot", "robot.command", "the robot-side safety loop against a real or simulated arm"),
)


def main(argv: list[str] | None = None) -> int:
    from edge_runtime.config import ConfigError
    from edge_runtime.core.manifest import ModelIntegrityError
    from edge_runtime.errors import InputError

    args = build_parser().parse_args(argv)
    from edge_runtime.canbus.bus import CanLinkError

    bad = (InputError, ModelIntegrityError, ConfigError, CanLinkError, *getattr(args, "bad_input", ()))
    return run(lambda: args.func(args), bad_input=bad)


if __name__ == "__main__":
    sys.exit(main())
