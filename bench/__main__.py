"""python -m bench [--threads N [N ...]] [--json OUT.json] [--n N] [--warmup W] [--assets DIR] [--no-torch]

Per-inference ConvLSTM latency at batch 1: torch eager, onnxruntime fp32 and
int8 (and the edge_runtime Engine around them), measured side by side in one
run. Prints a table; ``--json`` writes
``{"machine": {...}, "results": [{"model", "precision", "runtime", "threads",
"p50_us", "p99_us", "mean_us", "n", ...}], ...}``. See bench/latency.py for the method.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path


class _Parser(argparse.ArgumentParser):
    def error(self, message):
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        raise SystemExit(2)


def main(argv=None) -> int:
    p = _Parser(prog="python -m bench", description=__doc__.splitlines()[0])
    p.add_argument("--threads", type=int, nargs="+", default=[1], help="intra-op threads (one or more; default 1)")
    p.add_argument("--json", default=None, help="write the results here")
    p.add_argument("--n", type=int, default=5000, help="timed calls per runner (default 5000)")
    p.add_argument("--warmup", type=int, default=300, help="untimed calls per runner first (default 300)")
    p.add_argument("--rounds", type=int, default=10, help="interleaving rounds (default 10)")
    p.add_argument("--assets", default=None, help="assets directory with manifest.json (default: the shipped one)")
    p.add_argument("--no-torch", action="store_true", help="skip the torch eager rows")
    a = p.parse_args(argv)
    if any(t < 1 for t in a.threads):
        p.error(f"--threads: must be at least 1, got {a.threads}")
    if a.n < 1 or a.warmup < 0 or a.rounds < 1:
        p.error("--n and --rounds must be at least 1, --warmup at least 0")

    from bench.latency import format_table, run
    from edge_runtime.manifest import ModelIntegrityError

    try:
        report = run(a.threads, n=a.n, warmup=a.warmup, assets=a.assets, use_torch=not a.no_torch,
                     rounds=a.rounds, log=lambda s: print(s, file=sys.stderr))
    except (ModelIntegrityError, FileNotFoundError, ValueError) as e:
        print(f"error: {' '.join(str(e).split())}", file=sys.stderr)
        return 2
    print(format_table(report))
    if a.json:
        out = Path(a.json)
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(report, indent=2))
        print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
