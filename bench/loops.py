"""Wearable loop costs: the loop at 100 Hz in real time, the detector per sample, the alert latency.

The wearable measurements run in one child process (``bench.worker``) that
imports what a box imports for a replay (numpy, onnxruntime, python-can,
cantools, autosar-e2e and ``edge_runtime``), never firmware_sim or torch, so
its peak resident memory is the runtime's. The simulated drive is made by the
parent (:func:`prepare_drive`, firmware_sim) and handed over as a ``.npy`` file.

``wearable_100hz``
    The decider the box ships (``[alerts] decision``'s default, the row's ``decision``): the streaming
    decider (``edge_runtime.wearable.stream_decider.StreamLoop``, the int8 streaming classifier), or with a
    capture-path default ``edge_runtime.wearable.loop.WearableLoop`` and the int8 ConvLSTM; on 1 thread, with an
    ``AlertPublisher`` (alerts + the 10 Hz WEARABLE_STATUS heartbeat thread) on an
    in-process python-can ``virtual`` bus, fed 100 Hz samples in real time on absolute
    deadlines (sleeping in between) for ``realtime_s`` seconds, in the blocks the box's
    live source hands over: it reads the serial line every ``[imu] read_period_s``
    (``edge_runtime.wearable.mavlink_source.MavlinkImuSource.blocks``, default 0.05 s) and
    hands over what arrived meanwhile, so a block of ``read_period_s`` x 100 Hz samples
    (5) every ``read_period_s`` (one sample every 10 ms with ``read_period_s`` = 0).
    The stretch starts 2.5 s before a detector trigger of the drive so
    that a capture is classified inside it (the stream decides every hop wherever it starts). CPU share = process CPU time (all
    threads) / wall time, in % of one core. A deadline miss is a block whose
    processing ends after the next block is due.
``detector``
    ``edge_runtime.wearable.detector.StreamingDetector.push`` of one sample, timed per call
    over the drive (captures included, classification not): the capture path's, which the
    streaming decider does not run.
``alert_latency``
    The same loop fed one sample at a time as fast as it goes over the whole
    drive: from the arrival of the deciding sample (a capture's last, or a hop's; the block's
    ``rx_monotonic_s``, stamped as it is handed to ``feed``) to the return of
    ``AlertPublisher.on_decision`` (the DISTRACTION_ALERT frame handed to the
    bus), for every alerted decision, as ``python -m edge_runtime wearable``
    measures its ``latency_ms``; ``decision`` rows measure the same up to
    the decision handler for every decision, alerted or not. The loop is
    synchronous, so this is the whole latency of the product on that path.
The robot cycle at 30 Hz is in :mod:`bench.robot_cycle`.
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from bench.timing import CpuShare, peak_rss_mb, sleep_until, summarize, time_calls
from edge_runtime.wearable.sources import SAMPLE_RATE_HZ, ImuBlock

PRE_TRIGGER_S = 2.5
"""The real-time stretch starts this long before a trigger (the detector window is 2 s)."""


@dataclass(frozen=True)
class WearableConfig:
    drive_npy: str
    """(n, 3) float32 m/s^2 at 100 Hz (a simulated drive)."""
    start_index: int = 0
    """First sample of the real-time stretch."""
    realtime_s: float = 15.0
    """Length of the real-time stretch (s)."""
    assets: str = ""
    """Assets directory ('' = the shipped ones)."""
    model: str = "int8"
    """Manifest entry: a name or a precision."""
    threads: int = 1
    """onnxruntime intra-op threads."""
    read_period_s: float | None = None
    """The live source's read period the real-time stretch is fed at (None: the box's default)."""


def prepare_drive(minutes: float, seed: int, out_npy: str | Path) -> tuple[Path, int]:
    """A simulated drive saved as ``out_npy``, and a real-time start index 2.5 s before its
    first trigger (0 when it has none). Uses firmware_sim (parent process only)."""
    from edge_runtime.wearable.detector import detect_triggers
    from firmware_sim.devices.wrist import simulate_drive

    acc = np.ascontiguousarray(simulate_drive(minutes, seed=seed).acc_mps2, dtype=np.float32)
    np.save(out_npy, acc)
    pre = int(PRE_TRIGGER_S * SAMPLE_RATE_HZ)
    triggers = [int(t) for t in detect_triggers(acc) if t >= pre]
    return Path(out_npy), (triggers[0] - pre if triggers else 0)


class _Wearable:
    """The shipped decider + AlertPublisher on a virtual bus, as ``python -m edge_runtime wearable`` wires them."""

    def __init__(self, cfg: WearableConfig):
        import os

        from edge_runtime.canbus.bus import open_bus
        from edge_runtime.core.manifest import ASSETS_DIR
        from edge_runtime.wearable.alerts import AlertPublisher
        from edge_runtime.wearable.classifier import Engine
        from edge_runtime.wearable.loop import STREAM, AlertPolicy, WearableLoop
        from edge_runtime.wearable.stream_decider import StreamLoop, StreamModel

        self.pub = AlertPublisher(open_bus("virtual", f"bench-{os.getpid()}"), heartbeat_period_s=0.1)
        # the decider the box ships ([alerts] decision's default): the streaming classifier, or the capture path
        policy = AlertPolicy()
        self.decider = policy.decision
        self.streaming = self.decider == STREAM
        if self.streaming:
            self.engine = StreamModel.from_manifest(cfg.assets or ASSETS_DIR, cfg.model, threads=cfg.threads)
            self.new_loop = lambda: StreamLoop(self.engine, on_decision=self._handle)
        else:
            self.engine = Engine.from_manifest(cfg.assets or ASSETS_DIR, cfg.model, threads=cfg.threads)
            self.new_loop = lambda: WearableLoop(self.engine, policy=policy, on_decision=self._handle)
        self.loop = self.new_loop()
        self.t_fed = 0.0
        self.decision_s: list[float] = []
        self.alert_s: list[float] = []

    def _since_rx(self, d) -> float:
        """Seconds since the capture's last sample arrived: the decision's own ``rx_monotonic_s``
        (as ``python -m edge_runtime wearable`` measures it), else when it was fed."""
        rx = getattr(d, "rx_monotonic_s", None)
        return time.monotonic() - (rx if rx is not None else self.t_fed)

    def _handle(self, d) -> None:
        if d.alerted:
            d.alerted = self.pub.on_decision(d)
            if d.alerted:
                self.alert_s.append(self._since_rx(d))
        self.decision_s.append(self._since_rx(d))

    def feed(self, i: int, n: int, acc: np.ndarray) -> None:
        """Samples i .. i + n - 1 as one block, as the live source hands them over."""
        self.t_fed = time.monotonic()  # the block "arrives" now
        self.pub.beat_if_due()  # as the command's _drive does on each of its wake-ups
        self.loop.feed(ImuBlock(i / SAMPLE_RATE_HZ, acc[i : i + n], i > 0, self.t_fed))


def source_block_samples(read_period_s: float | None = None) -> int:
    """Samples per block of the box's live source: what arrives at 100 Hz in its ``[imu]
    read_period_s`` (None: the default; at least one)."""
    from edge_runtime.wearable.sources import ImuParams

    period_s = ImuParams().read_period_s if read_period_s is None else read_period_s
    return max(1, int(period_s * SAMPLE_RATE_HZ + 0.5))  # half up: 0.025 s is 3 samples, not round()'s 2


def _realtime(w: _Wearable, acc: np.ndarray, start: int, seconds: float, read_period_s: float | None = None) -> dict:
    block_samples = source_block_samples(read_period_s)
    blocks = min(int(seconds * SAMPLE_RATE_HZ), len(acc) - start) // block_samples
    period_s = block_samples / SAMPLE_RATE_HZ
    busy = np.empty(blocks, np.float64)
    late = np.empty(blocks, np.float64)
    misses = 0
    stream = w.streaming
    done0 = w.loop.hops if stream else w.loop.stats.captures
    w.pub.start()
    with CpuShare() as cpu:
        t_start = time.perf_counter()
        for k in range(blocks):
            due_s = t_start + k * period_s
            sleep_until(due_s)
            t0 = time.perf_counter()
            w.feed(start + k * block_samples, block_samples, acc)
            t1 = time.perf_counter()
            busy[k], late[k] = t1 - t0, t0 - due_s
            misses += t1 > due_s + period_s
    return {"name": "wearable_100hz", "rate_hz": SAMPLE_RATE_HZ, "seconds": round(cpu.wall_s, 2),
            "samples": blocks * block_samples, "block_samples": block_samples,
            ("hops" if stream else "captures"): (w.loop.hops if stream else w.loop.stats.captures) - done0,
            "cpu_share_pct": cpu.pct,
            "deadline_misses": int(misses), "start_late_p99_us": round(float(np.percentile(late, 99)) * 1e6, 1),
            **summarize(busy * 1e9), "peak_rss_mb": peak_rss_mb(),
            "decision": w.decider,
            "what": f"block_samples-block feed of {block_samples} sample(s) every {period_s * 1e3:g} ms, as the live source hands them "
                    + ("over (the shipped streaming decider: 25 Hz steps, a decision every hop, CAN)" if stream
                       else "over (detector + classify on capture + CAN)")
                    + f", real time, {w.engine.name} 1 thread, heartbeat thread running"}


def _detector(acc: np.ndarray) -> list[dict]:
    """The detector per sample: ``push`` of a one-sample block, and ``push_sample`` of three floats
    (what the 100 Hz loop calls for a finite sample)."""
    blocks, floats = [acc[i : i + 1] for i in range(len(acc))], acc.tolist()
    return [_detector_row("detector", "push", lambda det, k: det.push(blocks[k]), len(acc)),
            _detector_row("detector_sample", "push_sample", lambda det, k: det.push_sample(*floats[k]), len(acc))]


def _detector_row(name: str, call: str, push, n: int) -> dict:
    from edge_runtime.wearable.detector import StreamingDetector

    det, k = StreamingDetector(), iter(range(n))
    times = time_calls(lambda: push(det, next(k)), n, 0)
    return {"name": name, "rate_hz": SAMPLE_RATE_HZ, "samples": n, "triggers": len(det.triggers),
            **summarize(times), "what": f"StreamingDetector.{call}, one sample per call"}


def _latency(w: _Wearable, acc: np.ndarray) -> list[dict]:
    w.decision_s.clear()
    w.alert_s.clear()
    w.loop = w.new_loop()
    for i in range(len(acc)):
        w.feed(i, 1, acc)
    what = "from handing the deciding sample (a capture's last, or a hop's) to the loop to "
    return [{"name": "alert_latency", **summarize(np.asarray(w.alert_s) * 1e9),
             "what": what + "the DISTRACTION_ALERT frame handed to the CAN bus (alerted decisions)"},
            {"name": "decision_latency", **summarize(np.asarray(w.decision_s) * 1e9),
             "what": what + "the decision handler (every decision)"}]


def measure_wearable(cfg: WearableConfig) -> list[dict]:
    """Run in a child process: the real-time stretch first (its peak RSS is the runtime's), then
    the detector per sample and the alert latency over the whole drive."""
    acc = np.load(cfg.drive_npy).astype(np.float32)
    w = _Wearable(cfg)
    try:
        rows = [_realtime(w, acc, cfg.start_index, cfg.realtime_s, cfg.read_period_s)]
        rows += _detector(acc)
        rows += _latency(w, acc)
    finally:
        w.pub.close()
    return rows


def not_available(name: str, why: str) -> dict:
    """A loop row that could not be measured, and why."""
    return {"name": name, "available": False, "note": why}
