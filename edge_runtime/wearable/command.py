"""``python -m edge_runtime wearable``: IMU -> the decider -> alert decisions on CAN (docs/design.md section 7).

The decider is ``[alerts] decision``'s: as shipped ("stream") the streaming classifier on the last seconds of the
stream (:mod:`edge_runtime.wearable.stream_decider`); "early" or "full_window", the capture path (detector ->
ConvLSTM on the 7-s capture, :mod:`edge_runtime.wearable.loop`).

    python -m edge_runtime wearable (--replay FILE.csv | --imu serial:PATH?key=@FILE|key=env:NAME|unsigned=yes
                                     | --imu sim[?options])
        [--config BOX.toml] [--alerts OUT.jsonl] [--can-log OUT.log] [--duration S] [--realtime] [--quiet]
    python -m edge_runtime wearable [--config BOX.toml] --print-config

The command wires the parts together and drives them; it decides nothing itself. Each
block of samples goes to the loop (:mod:`edge_runtime.wearable.loop`), which classifies
the captures, sends the alerts and returns its decisions; each decision goes to the
output handlers (the ``--alerts`` JSONL log, the console), which only read it; each
change of a live sensor's state goes to the status (:mod:`edge_runtime.wearable.alerts`)
and at once onto the bus. At the end (source exhausted, ``--duration`` reached or
Ctrl-C) it prints the summary.
"""
from __future__ import annotations

import argparse
import json
import logging
import time
from contextlib import ExitStack, suppress
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, Callable, Iterable, Iterator

from edge_runtime.cli import CliError
from edge_runtime.errors import EdgeError

if TYPE_CHECKING:
    from edge_runtime.wearable.alerts import AlertPublisher, WearableStatus
    from edge_runtime.wearable.classifier import Engine
    from edge_runtime.wearable.loop import Decision, WearableLoop
    from edge_runtime.wearable.mavlink_source import MavlinkImuSource
    from edge_runtime.wearable.sources import ImuBlock, ReplayStats
    from edge_runtime.wearable.stream_decider import StreamLoop, StreamModel

log = logging.getLogger(__name__)
BAD_INPUT: tuple[type[BaseException], ...] = ()
"""Everything the wearable refuses is in the error tree already (``errors.BAD_INPUT``, ``LinkError``)."""


def add_arguments(p: argparse.ArgumentParser) -> None:
    src = p.add_mutually_exclusive_group()
    src.add_argument("--replay", metavar="FILE.csv|FILE.imu", help="a recording, CSV t,ax,ay,az (s, m/s^2) or one "
                     "written by --record, processed as fast as possible")
    src.add_argument("--imu", metavar="serial:PATH?key=@FILE|key=env:NAME|unsigned=yes | sim[?minutes=M&seed=S&...]",
                     help="a live IMU: MAVLink HIGHRES_IMU/SCALED_IMU on a serial line, signed with the MAVLink 2 "
                          "key in FILE or in the environment variable NAME (unsigned only when the spec says "
                          "unsigned=yes, with a warning), or 'sim': the simulated IMU firmware on a "
                          "pseudo-terminal (development checkouts)")
    p.add_argument("--duration", type=float, metavar="S", help="stop a live source after S seconds")
    p.add_argument("--can-log", metavar="OUT.log|.asc|.blf|.csv", help="write every CAN frame sent (python-can formats)")
    p.add_argument("--alerts", metavar="OUT.jsonl", help="write one JSON object per classifier decision")
    p.add_argument("--record", metavar="OUT.imu", help="write every sample the loop is fed as an IMU recording "
                   "(float32 m/s^2; --replay reads it much faster than CSV)")
    p.add_argument("--config", metavar="BOX.toml", help="the box configuration (see edge_runtime/box.example.toml)")
    p.add_argument("--print-config", action="store_true", help="print the effective configuration as TOML and exit")
    p.add_argument("--assets", metavar="DIR", help="model directory with manifest.json [model] assets")
    p.add_argument("--model", help="manifest entry of the decider's model: a name, or a precision (int8, fp32) "
                   "[stream] model with decision stream, else [model] name")
    p.add_argument("--threads", type=int, help="onnxruntime intra-op threads [model] threads")
    p.add_argument("--min-confidence", type=float, help="capture path: below this a full-window decision is "
                   "'uncertain' [alerts] min_confidence (and the S = 6 entry of min_confidence_by_steps)")
    p.add_argument("--decision", choices=("stream", "early", "full_window"),
                   help="without captures every hop on the last seconds of the stream ([stream], the default), or the "
                        "capture path: after each sub-window the capture allows (preliminary, then confirmed, revised "
                        "or withdrawn), or once on the full 7-s window [alerts] decision")
    p.add_argument("--threshold", type=float, help="capture path: detector threshold (m/s^2) [detector] threshold_mps2")
    p.add_argument("--realtime", action="store_true", help="pace a replay at its own sample rate")
    p.add_argument("--quiet", action="store_true", help="print only the summary")


def effective_config(args: argparse.Namespace):
    """The config file, then the command-line flags on top, validated as one: the sections of
    the components imported here (the robot's sections in the same file are left to it)."""
    from edge_runtime import config
    from edge_runtime.wearable import alerts, classifier, detector, loop, sources, stream_decider  # noqa: F401 - their sections

    cfg = config.load(args.config)
    cfg = config.override(cfg, "alerts", decision=getattr(args, "decision", None))
    stream = cfg.alerts.decision == loop.STREAM
    # a flag the decider would not read is refused, not ignored: the user asked for something that would not happen
    unread = [flag for flag, v in (("--min-confidence", args.min_confidence), ("--threshold", args.threshold))
              if v is not None]
    if stream and unread:
        raise CliError(f"{', '.join(unread)}: the capture path's; [alerts] decision = \"stream\" (the default) has no "
                       "detector and no capture (add --decision early or full_window)")
    cfg = config.override(cfg, "model", assets=args.assets, name=None if stream else args.model, threads=args.threads)
    cfg = config.override(cfg, "stream", model=args.model if stream else None)
    by_steps = None
    if args.min_confidence is not None:  # the flag is the full window's threshold, before the manifest's
        by_steps = [*cfg.alerts.min_confidence_by_steps[:-1], args.min_confidence]
    cfg = config.override(cfg, "alerts", min_confidence=args.min_confidence, min_confidence_by_steps=by_steps)
    return config.override(cfg, "detector", threshold_mps2=args.threshold)


def cmd(args: argparse.Namespace) -> int:
    cfg = effective_config(args)
    if args.print_config:
        print(cfg.to_toml(), end="")
        return 0
    if not (args.replay or args.imu):
        raise CliError("wearable: give a source: --replay FILE.csv, --imu serial:PATH or --imu sim")
    source = _open_source(args, cfg)  # bad input is reported before the model loads
    with ExitStack() as stack:
        stack.callback(source.close)
        engine = _load_classifier(cfg)
        for note in source.replay_stats.notices:
            log.info("%s", note, extra={"event": "replay_notice"})
        outputs = _outputs(stack, args.alerts, args.quiet)
        record = _recorder(stack, args.record)
        pub = _open_publisher(cfg, args.can_log, _status_of(engine), data_clock=source.live is None)
        stack.callback(pub.close)
        loop = make_loop(cfg, engine, pub)
        t_wall = time.perf_counter()
        with suppress(KeyboardInterrupt):
            _drive(source, loop, outputs, record)
    _print_summary(loop, source, cfg, args.can_log, time.perf_counter() - t_wall)
    return 0


# ---------------------------------------------------------------------------- wiring


@dataclass
class _Source:
    """Where the samples come from: the events that drive the loop (ImuBlocks, and a live
    source's SourceStatus events), the live source if it is one, what reading a recording found."""

    events: Iterable[Any]
    replay_stats: ReplayStats
    live: MavlinkImuSource | None = None

    def close(self) -> None:
        if self.live is not None:
            self.live.close()

    def health(self) -> tuple[int, int]:
        """(saturated, dropped) samples so far, the source's own counts for the status."""
        if self.live is not None:
            return self.live.stats.saturated, self.live.stats.dropped
        return self.replay_stats.saturated, 0


def _open_source(args: argparse.Namespace, cfg) -> _Source:
    from edge_runtime.wearable.recording import open_replay
    from edge_runtime.wearable.sources import ReplayStats

    stats = ReplayStats()
    if args.replay:
        blocks = open_replay(args.replay, stats, range_mps2=cfg.imu.range_mps2)
        if args.realtime:
            blocks = (b for block in blocks for b in _paced(block, cfg.imu.sample_rate_hz))
        return _Source(blocks, stats)
    live = _open_live_source(args.imu, cfg)
    return _Source(live.blocks(args.duration), stats, live)


def _open_live_source(spec: str, cfg) -> MavlinkImuSource:
    """``serial:PATH[?key=HEX]`` -> a MAVLink IMU source on that serial line;
    ``sim[?options]`` -> the simulated IMU firmware as a child process on a pseudo-terminal."""
    if spec == "sim" or spec.startswith("sim?"):
        from edge_runtime.wearable.sim_source import SimImuSource, SimSourceError

        try:
            return SimImuSource(spec, silence_timeout_s=cfg.imu.silence_timeout_s, range_mps2=cfg.imu.range_mps2,
                                read_period_s=cfg.imu.read_period_s)
        except SimSourceError as e:
            raise CliError(str(e)) from None
    from edge_runtime.core.serial_line import KEY_FORMS, parse_link_spec

    try:
        line = parse_link_spec(spec)
    except ValueError as e:
        raise CliError(f"--imu: {e}") from None
    if line.key_inline:  # argv is readable by every user of the box (ps, /proc, shell history)
        raise CliError(f"--imu: a signing key on the command line is visible to every user; give {KEY_FORMS}")
    if line.key is None and not line.unsigned:
        raise CliError(f"--imu serial:{line.path}: no signing key; give {KEY_FORMS}, "
                       "or add ?unsigned=yes if an unsigned IMU line is intended")
    if line.unsigned:
        log.warning("--imu serial:%s is unsigned (unsigned=yes): any device on the line can inject or replay "
                    "IMU samples", line.path, extra={"event": "imu_unsigned"})
    from edge_runtime.wearable.mavlink_source import MavlinkImuSource

    try:
        return MavlinkImuSource(line.path, signing_key=line.key, silence_timeout_s=cfg.imu.silence_timeout_s,
                                range_mps2=cfg.imu.range_mps2, read_period_s=cfg.imu.read_period_s)
    except ValueError as e:
        raise CliError(str(e)) from None


def _paced(block: ImuBlock, rate_hz: float) -> Iterator[ImuBlock]:
    """A recorded block one sample period at a time, on a monotonic clock (no busy waiting)."""
    from edge_runtime.wearable.sources import ImuBlock

    start = time.monotonic()
    for i in range(len(block.acc_mps2)):
        delay = start + (i + 1) / rate_hz - time.monotonic()  # sample i is complete one period later
        if delay > 0:
            time.sleep(delay)
        yield ImuBlock(block.t0_s + i / rate_hz, block.acc_mps2[i : i + 1], block.continuous or i > 0,
                       rx_monotonic_s=time.monotonic())


def make_loop(cfg, classifier, publisher: AlertPublisher | None) -> WearableLoop | StreamLoop:
    """The decider ``[alerts] decision`` selects, on ``classifier`` (:func:`_load_classifier`'s): the capture loop,
    or with "stream" the streaming decider. Every decider's alerts go out through ``publisher``."""
    from edge_runtime.wearable.loop import STREAM, WearableLoop

    if cfg.alerts.decision == STREAM:
        from edge_runtime.wearable.stream_decider import StreamLoop

        return StreamLoop(classifier, cfg.stream, sample_rate_hz=cfg.imu.sample_rate_hz, publisher=publisher)
    return WearableLoop(classifier, cfg.detector, cfg.alerts, sample_rate_hz=cfg.imu.sample_rate_hz,
                        publisher=publisher)


def _load_classifier(cfg) -> Engine | StreamModel:
    from edge_runtime.config import ConfigError
    from edge_runtime.wearable.classifier import Engine
    from edge_runtime.wearable.loop import STREAM

    if cfg.alerts.decision == STREAM:  # the streaming classifier; [alerts]' capture keys do not apply
        from edge_runtime.wearable.stream_decider import StreamModel

        return StreamModel.from_params(cfg.stream, cfg.model)
    engine = Engine.from_params(cfg.model)
    unknown = sorted(set(cfg.alerts.never_alert) - set(engine.classes))
    if unknown:
        raise ConfigError(f"[alerts] never_alert: {unknown} are not classes of {engine.name} ({', '.join(engine.classes)})")
    return engine


def _status_of(engine: Engine) -> WearableStatus:
    from edge_runtime.wearable.alerts import WearableStatus

    # ModelVersion (8 bits): the first byte of the model file's sha256, as listed in manifest.json
    return WearableStatus(model_version=int(engine.entry.get("sha256", "00")[:2], 16))


def _open_publisher(cfg, can_log: str | None, status: WearableStatus, data_clock: bool = False) -> AlertPublisher:
    """The CAN side: the configured python-can bus, alerts and the WEARABLE_STATUS heartbeat, started.
    ``data_clock`` (a replay): frames go out, and are logged, at the recording's time (``Clock.DATA``); on the
    in-process virtual bus the bus opens when a frame must go out (``DeferredBus``: with nobody on it, none does)."""
    from edge_runtime.canbus.bus import DeferredBus, open_bus
    from edge_runtime.wearable.alerts import AlertPublisher, Clock

    c = cfg.can

    def bus_factory():
        return open_bus(c.interface, c.channel, c.bitrate, host=c.host, port=c.port)

    deferred = data_clock and c.interface == "virtual"
    bus = DeferredBus(bus_factory, c.channel) if deferred else bus_factory()
    try:
        pub = AlertPublisher(bus, heartbeat_period_s=c.heartbeat_period_s, log_path=can_log,
                             bus_factory=bus_factory, status=status, clock=Clock.DATA if data_clock else Clock.WALL)
    except BaseException as e:  # a live box parses the DBC here: the bus it opened is shut, the error is one line
        bus.shutdown()
        if isinstance(e, ValueError) and not isinstance(e, EdgeError):  # python-can's Logger: unknown file suffix
            raise CliError(f"--can-log {can_log}: {e}") from None
        raise
    return pub.start()


def _recorder(stack: ExitStack, path: str | None) -> Callable[[ImuBlock], None] | None:
    """``--record``: each block fed to the loop goes to an IMU recording (closed with ``stack``)."""
    if not path:
        return None
    from edge_runtime.wearable.recording import RecordingWriter

    writer = RecordingWriter(path)
    stack.callback(writer.close)
    return writer.write


def _outputs(stack: ExitStack, alerts_path: str | None, quiet: bool) -> list[Callable[[Decision], None]]:
    """The output handlers, in order: the ``--alerts`` JSONL log (closed with ``stack``), the console."""
    handlers: list[Callable[[Decision], None]] = []
    if alerts_path:
        log = stack.enter_context(open(alerts_path, "w"))
        handlers.append(lambda d: log.write(json.dumps(d.to_json()) + "\n"))
    if not quiet:
        handlers.append(_print_decision)
    return handlers


# ---------------------------------------------------------------------------- running


def replay(cfg, classifier, acc_mps2, outputs: Iterable[Callable[[Decision], None]] = (), t0_s: float = 0.0
           ) -> WearableLoop:
    """A recording already in memory, (n, 3) m/s^2 at ``[imu] sample_rate_hz``, through the path of
    ``--replay``: the loop with its publisher on the configured bus and the data clock, each decision
    to ``outputs``. For evaluations that would otherwise write and parse CSV files (``firmware_sim
    drive-eval``); the loop (its stats and status) is returned."""
    from edge_runtime.wearable.alerts import WearableStatus
    from edge_runtime.wearable.sources import ImuBlock, ReplayStats

    status = _status_of(classifier) if hasattr(classifier, "entry") else WearableStatus()
    pub = _open_publisher(cfg, None, status, data_clock=True)
    try:
        loop = make_loop(cfg, classifier, pub)
        _drive(_Source([ImuBlock(t0_s, acc_mps2)], ReplayStats()), loop, list(outputs))
    finally:
        pub.close()
    return loop


def _drive(source: _Source, loop: WearableLoop, outputs: list[Callable[[Decision], None]],
           record: Callable[[ImuBlock], None] | None = None) -> None:
    """Every event of the source: a block goes to ``record`` (``--record``), then to the loop and
    its decisions to the outputs; a live sensor's state goes to the status. A disconnected sensor
    ends the run."""
    from edge_runtime.core.service import keepalive
    from edge_runtime.wearable.sources import ImuBlock

    status = loop.status
    for event in source.events:
        if loop.publisher is not None:  # a dead heartbeat thread ends the run: no keep-alive for a silent box
            loop.publisher.check_running()
            loop.publisher.beat_if_due()  # on this thread's wake-up, when live: see AlertPublisher.beat_if_due
        keepalive()  # READY, then the watchdog's keep-alives, only while this loop turns
        status.set_source_counts(*source.health())
        if not isinstance(event, ImuBlock):  # a live source's SourceStatus
            _sensor_state(loop.publisher, event.state, f" ({event.since_s:.2f} s since the last sample)")
            if event.state == "disconnected":
                break
            continue
        _sensor_state(loop.publisher, "ok")
        if record is not None:
            record(event)
        for block in _data_clock_steps(loop, event) if source.live is None else (event,):
            for decision in loop.feed(block):
                for output in outputs:
                    output(decision)
        if source.live is None:
            loop.publisher.advance_to(event.t0_s + (len(event.acc_mps2) - 1) / loop.rate_hz)


def _data_clock_steps(loop: WearableLoop, block: ImuBlock) -> Iterator[ImuBlock]:
    """A recorded block as the loop is fed it, the publisher's data clock moved to its start:
    every heartbeat goes out at its data time and reports the samples fed by then.

    A block of finite samples is fed whole: within it only the sample count grows, and a
    heartbeat reads that only to tell "starting" (nothing fed yet), so each heartbeat says what
    it said when the block went in pieces, at a fraction of the calls (the loop's decisions do
    not depend on how a stream is split). A block with non-finite samples goes in pieces of one
    heartbeat period, so the heartbeat after a bad sample, and only that one, says degraded."""
    import numpy as np

    from edge_runtime.wearable.sources import ImuBlock

    pub = loop.publisher
    if np.isfinite(block.acc_mps2).all():
        pub.advance_to(block.t0_s)
        yield block
        return
    step = max(1, round(pub.period * loop.rate_hz))
    for i in range(0, len(block.acc_mps2), step):
        t0_s = block.t0_s + i / loop.rate_hz
        pub.advance_to(t0_s)
        yield ImuBlock(t0_s, block.acc_mps2[i : i + step], block.continuous or i > 0, rx_monotonic_s=block.rx_monotonic_s)


def _sensor_state(pub: AlertPublisher, state: str, detail: str = "") -> None:
    """A change of the sensor's state is printed and reported at once, not at the next heartbeat period."""
    if pub.status.set_sensor(state):
        log.log(logging.INFO if state == "ok" else logging.WARNING, "sensor %s%s", state, detail,
                extra={"event": "sensor_state"})
        pub.send_heartbeat()


def _print_decision(d: Decision) -> None:
    from edge_runtime.wearable.stream_decider import STREAM_STEPS

    mark = ("ALERT" if d.status == "alert" else d.status.upper()) if d.alerted else d.status
    after = "" if d.steps == 6 else f"  (stream, t={d.t_alert_s:.2f}s)" if d.steps == STREAM_STEPS else \
        f"  (after {d.steps} of 6 sub-windows, t={d.t_alert_s:.2f}s)"
    print(f"t={d.t_trigger_s:9.2f}s  {d.label:<12} p={d.confidence:.2f}  {mark}{after}")


def _print_summary(loop: WearableLoop, source: _Source, cfg, can_log: str | None, wall_s: float) -> None:
    s, h, r, engine = loop.stats, loop.status.counts(), source.replay_stats, loop.classifier
    stream_s = h.samples / loop.rate_hz
    print(
        f"summary: {stream_s:.1f} s of IMU data ({h.samples} samples) in {wall_s:.3f} s "
        f"({stream_s / max(wall_s, 1e-9):,.0f}x real time); model {engine.name} ({engine.precision})"
        + (f", steps by {engine.step_model.call_path}" if getattr(engine, "step_model", None) is not None else "")
        + "\n"
        + (f"  hops {loop.hops}" if hasattr(loop, "hops") else f"  captures {s.captures}")
        + f" ({loop.decision_mode}): alert events {s.events}; decisions "
        + ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in sorted(s.statuses.items())) + "\n"
        "  by class: " + (", ".join(f"{k} {v}" for k, v in sorted(s.labels.items())) or "none") + "\n"
        f"  bad samples: non-finite or out of range {h.non_finite} (out of range "
        f"{r.out_of_range if source.live is None else source.live.stats.out_of_range}), saturated {h.saturated}, "
        f"dropped (time not advancing) {r.dropped_non_monotonic}, gaps {r.gaps}, detector restarts {h.detector_restarts}"
    )
    c = loop.publisher.summary()
    print(f"  CAN {cfg.can.interface}:{cfg.can.channel}: frames sent {c['frames_sent']} (alerts {c['alerts_sent']} "
          f"+ copies {c['alert_copies_sent']}, heartbeats {c['heartbeats_sent']}"
          + (f"; {c['frames_unheard']} of them not encoded: nobody on the bus to hear them" if c["frames_unheard"]
             else "") + f"), send errors {c['send_errors']}, "
          f"reconnects {c['reconnects']}"
          + (f"; logged to {can_log}" if can_log else ""))
    if c["alerts_held"] or c["alerts_lost"]:
        print(f"  alerts the bus did not take at first {c['alerts_held']}: sent late {c['alerts_sent_late']}, "
              f"lost {c['alerts_lost']} (WEARABLE_STATUS said degraded)")
    latencies_ms = loop.status.alert_latencies_ms()
    if latencies_ms:
        import numpy as np

        print(f"  alert latency (last capture sample arrived -> frame handed to the bus): median "
              f"{np.median(latencies_ms):.2f} ms, p99 {np.percentile(latencies_ms, 99):.2f} ms, "
              f"max {max(latencies_ms):.2f} ms over {len(latencies_ms)} alerts")
    if source.live is not None:
        print("  serial link: " + ", ".join(f"{k.replace('_', ' ')} {v}" for k, v in vars(source.live.stats).items()))
