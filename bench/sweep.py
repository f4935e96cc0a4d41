"""One bench run: every manifest entry x runtime x threads, then the loop costs.

Configurations are not timed side by side in one process (peak memory would
mix) but each in a child process (``bench.worker``). To share the machine's
noise between configurations anyway, the sweep is repeated in ``rounds``
rounds, each timing ``n / rounds`` calls per configuration after its own
warm-up; the rows pool the rounds' calls (p50/p99/mean over all ``n``) and keep
the highest peak memory.
"""
from __future__ import annotations

import sys
import tempfile
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Callable

from bench.inference import RUNTIMES, InferenceConfig
from bench.loops import WearableConfig, not_available, prepare_drive
from bench.machine import machine_info, torch_version
from bench.report import profiles
from bench.robot_cycle import robot_rows
from bench.timing import summarize
from bench.worker import ChildFailed, run_child


@dataclass(frozen=True)
class BenchOptions:
    assets: str = ""
    """Assets directory with manifest.json ('' = edge_runtime's shipped assets)."""
    threads: tuple[int, ...] = (1, 2)
    """Intra-op thread counts."""
    n: int = 2000
    """Timed single inferences per configuration (over all rounds)."""
    warmup: int = 200
    """Untimed calls per configuration and round."""
    rounds: int = 2
    """Sweeps over all configurations (see the module docstring)."""
    use_torch: bool = True
    """Time torch eager too (when torch is importable)."""
    use_openvino: bool = True
    """Time OpenVINO too (each row skipped with a note when openvino is not installed)."""
    models: tuple[str, ...] = ()
    """Only these archs or manifest entry names (empty = all)."""
    loops: bool = True
    """Measure the loop costs."""
    drive_minutes: float = 30.0
    """Length of the simulated drive for the detector and alert-latency figures (min)."""
    realtime_s: float = 15.0
    """Length of the real-time 100 Hz wearable stretch (s)."""
    robot_s: float = 300.0
    """Length of the real-time 30 Hz robot stretch (s): long enough for at least 300 frames that cause a
    command (``bench.robot_scenario``'s workers; the shipped configuration sends a command only when
    what the arm should do changes, about 1.6 a second here)."""
    read_period_s: float | None = None
    """The live IMU source's read period the 100 Hz wearable stretch is fed at (None: the box's
    ``[imu] read_period_s``; 0: one sample at a time)."""
    seed: int = 1
    """Seed of the simulated drive and of the input values."""
    command: str = field(default="python -m bench", compare=False)
    """How this run was started (recorded in the report)."""

    def __post_init__(self) -> None:
        if not self.threads or any(t < 1 for t in self.threads):
            raise ValueError(f"threads: each must be at least 1, got {list(self.threads)}")
        if self.n < 1 or self.rounds < 1 or self.warmup < 0:
            raise ValueError("n and rounds must be at least 1, warmup at least 0")
        from edge_runtime.wearable.mavlink_source import READ_TIMEOUT_S

        if self.read_period_s is not None and not 0.0 <= self.read_period_s <= READ_TIMEOUT_S:
            # the product's limits: [imu] read_period_s never exceeds the source's read timeout
            raise ValueError(f"--read-period: {self.read_period_s} s; give 0 .. {READ_TIMEOUT_S:g} s")


def _entries(assets: Path, only: tuple[str, ...]) -> list[dict]:
    from edge_runtime.core.manifest import load_manifest, verify_all

    verify_all(assets)  # a tampered or missing model is bad input, reported before anything runs
    every = load_manifest(assets)["models"]
    entries = every
    if only:
        entries = [e for e in every if e["arch"] in only or e["name"] in only]
        if not entries:
            raise ValueError(f"--models {','.join(only)}: no manifest entry has that arch or name")
        # an architecture's step model (the ConvLSTM's) is what the box runs per decision: measured beside it
        named = {e["step_model"] for e in entries if "step_model" in e and e["arch"] in only}
        entries += [e for e in every if e["name"] in named and e not in entries]
    return entries


def _configs(entries: list[dict], opts: BenchOptions, assets: Path, with_torch: bool) -> list[InferenceConfig]:
    """ORT and OpenVINO for every entry; torch eager for the fp32 entries (torch has no int8 counterpart)."""
    per_round = -(-opts.n // opts.rounds)
    out = []
    for t in opts.threads:
        for e in entries:
            for rt in RUNTIMES:
                if rt == "torch-eager" and (not with_torch or e["precision"] != "fp32"):
                    continue
                if rt == "openvino" and not opts.use_openvino:
                    continue
                out.append(InferenceConfig(str(assets), e["name"], rt, t, per_round, opts.warmup, opts.seed))
    return out


def _inference(entries: list[dict], opts: BenchOptions, assets: Path, with_torch: bool,
               log: Callable[[str], None]) -> tuple[list[dict], list[dict]]:
    by_name = {e["name"]: e for e in entries}
    configs = _configs(entries, opts, assets, with_torch)
    pooled: dict[InferenceConfig, dict] = {}
    skipped: dict[InferenceConfig, str] = {}
    for r in range(opts.rounds):
        for i, c in enumerate(configs):
            if c in skipped:
                continue
            log(f"round {r + 1}/{opts.rounds} [{i + 1}/{len(configs)}] {c.entry} {c.runtime} {c.threads} thread(s)")
            try:
                res = run_child("inference", asdict(c))
            except ChildFailed as e:  # reported as a failed row; the exit status says so
                res = {"skipped": f"FAILED: {e}"}
            if "skipped" in res:
                skipped[c] = res["skipped"]
                continue
            acc = pooled.setdefault(c, {"times_ns": [], "peak_rss_mb": 0.0, "rss_idle_mb": float("inf")})
            acc["times_ns"] += res.pop("times_ns")
            acc["peak_rss_mb"] = max(acc["peak_rss_mb"], res.pop("peak_rss_mb"))
            acc["rss_idle_mb"] = min(acc["rss_idle_mb"], res.pop("rss_idle_mb"))
            res.pop("config")
            acc.update(res)
    rows = []
    for c, acc in pooled.items():
        e = by_name[c.entry]
        times = acc.pop("times_ns")
        rows.append({"model": e["arch"], "precision": e["precision"], "runtime": c.runtime, "threads": c.threads,
                     **summarize(times[: opts.n]), **acc, "name": e["name"],
                     "model_rss_mb": round(acc["peak_rss_mb"] - acc["rss_idle_mb"], 1)})
    notes = [{"model": by_name[c.entry]["arch"], "precision": by_name[c.entry]["precision"], "runtime": c.runtime,
              "threads": c.threads, "name": c.entry, "note": note} for c, note in skipped.items()]
    return rows, notes


def _loops(opts: BenchOptions, assets: Path, entries: list[dict], log: Callable[[str], None]) -> list[dict]:
    with tempfile.TemporaryDirectory(prefix="bench-loops-") as tmp:
        log(f"simulating a {opts.drive_minutes:g} min drive (seed {opts.seed}) ...")
        npy, start = prepare_drive(opts.drive_minutes, opts.seed, Path(tmp) / "drive.npy")
        log(f"wearable loop: {opts.realtime_s:g} s at 100 Hz in real time, then the drive sample by sample ...")
        cfg = WearableConfig(str(npy), start, opts.realtime_s, assets=str(assets), read_period_s=opts.read_period_s)
        try:
            loops = run_child("wearable", asdict(cfg))
        except ChildFailed as e:
            loops = [not_available("wearable_100hz", f"FAILED: {e}")]
        log(f"robot cycle: {opts.robot_s:g} s at 30 Hz in real time ...")
        loops += robot_rows(opts.robot_s, assets, entries, opts.seed, Path(tmp))
    return loops


def run_bench(opts: BenchOptions, log: Callable[[str], None] = lambda s: print(s, file=sys.stderr)) -> dict:
    """The whole report (see bench.report for its shape)."""
    from edge_runtime.core.manifest import ASSETS_DIR

    assets = Path(opts.assets) if opts.assets else ASSETS_DIR
    entries = _entries(assets, opts.models)
    torch = torch_version() if opts.use_torch else None
    machine = machine_info(with_torch=opts.use_torch)
    results, skipped = _inference(entries, opts, assets, torch is not None, log)
    order = {rt: i for i, rt in enumerate(RUNTIMES)}
    results.sort(key=lambda r: (r["model"], r["threads"], order[r["runtime"]], r["precision"]))
    loops = _loops(opts, assets, entries, log) if opts.loops else []
    method = {**{k: v for k, v in asdict(opts).items() if k != "command"}, "command": opts.command,
              "batch": 1, "process": "one child process per configuration and round (bench.worker)",
              "timer": "time.perf_counter_ns per call, gc paused", "assets": str(assets)}
    failures = sum(s.get("note", "").startswith("FAILED") for s in skipped + loops)
    return {"machine": machine, "method": method, "results": results, "skipped": skipped, "loops": loops,
            "profiles": profiles(results), "failures": failures}
