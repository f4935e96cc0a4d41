"""python -m bench [--threads N ...] [--cpus 0,1] [--busy-cpus 1] [--quick] [--robot-seconds S] [--json OUT.json] [--markdown OUT.md] [--compare OLD.json]

What the box will do, per shipped model and per loop:

* every entry of the assets' manifest.json (ConvLSTM, lifter, baselines) x runtime
  (onnxruntime; torch eager for fp32 when torch is installed and can rebuild the
  model) x threads: a warm-up, then at least 1,000 timed single inferences
  (batch 1): p50, p99, mean (us), model file size, peak resident memory (each
  configuration in a child process of its own);
* loop costs: the wearable loop at 100 Hz in real time (CPU share of one core,
  deadline misses, peak memory), the detector per sample, the alert latency
  (last sample of a capture -> alert frame on the CAN bus), the robot cycle at 30 Hz and its
  reaction (keypoints in -> command frame on the CAN bus, per kind of command; two simulated
  workers, 300 s by default so that at least 300 frames cause a command);
* a per-model profile: int8 against fp32 (file size, memory, latency, ratios).

Prints a table; ``--json`` writes {"machine", "method", "results", "skipped",
"loops", "profiles"}; ``--markdown`` the README tables; ``--compare OLD.json``
prints new/old ratios per row and exits 1 if a figure regressed by more than
``--tolerance`` (or a configuration failed). The machine is shared and noisy: compare runs of one machine only.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

from edge_runtime.cli import CliError, OneLineParser, positive_float, positive_int, run

QUICK = {"n": 100, "warmup": 5, "rounds": 1, "drive_minutes": 2.0, "realtime_s": 1.0, "robot_s": 1.0}
"""--quick: enough to exercise every path (tests), not to measure."""


def _name_list(s: str) -> tuple[str, ...]:
    return tuple(p.strip() for p in s.split(",") if p.strip())


def build_parser() -> OneLineParser:
    p = OneLineParser(prog="python -m bench", description="Per-inference latency and memory of every shipped "
                      "model, and the loops' costs, on this machine.")
    p.add_argument("--threads", type=positive_int, nargs="+", default=[1, 2], help="intra-op threads (default 1 2)")
    p.add_argument("--cpus", default=None, help="pin to these CPUs, e.g. 0,1 or 0-1 (os.sched_setaffinity)")
    p.add_argument("--busy-cpus", default=None, metavar="CPUS",
                   help="run a busy-loop process on each of these CPUs while measuring (a load generator: "
                        "the other core busy); pin the bench elsewhere with --cpus")
    p.add_argument("--n", type=positive_int, default=2000, help="timed calls per configuration (default 2000)")
    p.add_argument("--warmup", type=positive_int, default=200, help="untimed calls per configuration and round")
    p.add_argument("--rounds", type=positive_int, default=2, help="sweeps over all configurations (default 2)")
    p.add_argument("--quick", action="store_true", help="few iterations and a short drive: for tests, not figures")
    p.add_argument("--assets", default=None, help="assets directory with manifest.json (default: the shipped one)")
    p.add_argument("--models", type=_name_list, default=(), help="only these archs or entry names, comma-separated")
    p.add_argument("--no-torch", action="store_true", help="skip the torch eager rows")
    p.add_argument("--no-openvino", action="store_true", help="skip the OpenVINO rows")
    p.add_argument("--no-loops", action="store_true", help="skip the loop costs")
    p.add_argument("--realtime", type=positive_float, default=None, metavar="S",
                   help="seconds of the real-time wearable and robot loops (default 15 and 300)")
    p.add_argument("--robot-seconds", type=positive_float, default=None, metavar="S",
                   help="seconds of the real-time robot loop alone (default 300, enough for 300 frames that cause "
                        "a command; overrides --realtime for the robot)")
    p.add_argument("--read-period", type=float, default=None, metavar="S",
                   help="feed the real-time wearable loop in the blocks a live IMU source read every S seconds "
                        "hands over (default: the box's [imu] read_period_s; 0: one sample at a time)")
    p.add_argument("--seed", type=int, default=1, help="seed of the simulated drive and the inputs (default 1)")
    p.add_argument("--json", default=None, metavar="OUT.json", help="write the report here")
    p.add_argument("--markdown", default=None, metavar="OUT.md", help="write the README tables here")
    p.add_argument("--compare", default=None, metavar="OLD.json", help="print new/old ratios against this report")
    p.add_argument("--tolerance", type=positive_float, default=0.10,
                   help="--compare: a ratio above 1 + this is a regression (default 0.10)")
    return p


def _load_report(path: str) -> dict:
    try:
        data = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise CliError(f"--compare {path}: not a readable JSON report ({type(e).__name__})") from None
    if not isinstance(data, dict) or not isinstance(data.get("results"), list):
        raise CliError(f"--compare {path}: field 'results': missing; not a python -m bench report")
    return data


def _write(path: str, text: str) -> None:
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text)
    print(f"wrote {out}")


def cmd(a) -> int:
    from contextlib import nullcontext

    from bench.machine import LoadGenerator, parse_cpus, pin_cpus
    from bench.report import compare, format_markdown, format_table
    from bench.sweep import BenchOptions, run_bench

    old = _load_report(a.compare) if a.compare else None  # bad input before minutes of measuring
    busy = LoadGenerator(parse_cpus(a.busy_cpus)) if a.busy_cpus else nullcontext()  # checked before pinning
    if a.cpus:
        pin_cpus(parse_cpus(a.cpus))
    sizes = {"n": a.n, "warmup": a.warmup, "rounds": a.rounds, **(QUICK if a.quick else {})}
    if a.realtime:
        sizes.update(realtime_s=a.realtime, robot_s=a.realtime)
    if a.robot_seconds:
        sizes.update(robot_s=a.robot_seconds)
    opts = BenchOptions(assets=a.assets or "", threads=tuple(a.threads), use_torch=not a.no_torch,
                        use_openvino=not a.no_openvino, models=a.models, loops=not a.no_loops, seed=a.seed,
                        read_period_s=a.read_period,
                        command="python -m bench " + " ".join(sys.argv[1:]), **sizes)
    with busy:
        report = run_bench(opts)
    report["load_generator_cpus"] = busy.cpus if a.busy_cpus else []
    print(format_table(report))
    if a.json:
        _write(a.json, json.dumps(report, indent=2))
    if a.markdown:
        _write(a.markdown, format_markdown(report))
    status = 0
    if report["failures"]:
        print(f"{report['failures']} configuration(s) FAILED (see 'skipped')", file=sys.stderr)
        status = 1
    if old is not None:
        lines, regressions = compare(report, old, a.tolerance)
        print("\n".join(lines))
        status = status or (1 if regressions else 0)
    return status


def main(argv=None) -> int:
    from edge_runtime.core.manifest import ModelIntegrityError

    args = build_parser().parse_args(argv)
    return run(lambda: cmd(args), bad_input=(ModelIntegrityError, ValueError), what="bench", extra="bench")


if __name__ == "__main__":
    sys.exit(main())
