"""Before/after CPU per frame and per tick: prof_frame.py --mode plain run in two trees, in pairs, the order
alternating (the first of a pair ran measurably faster on this shared machine in session 18), the same simulated
scenario in each. Every run must print the same decision and payload digests.

    python reports/bench/s23_perf/ab.py BASE_TREE MINE_TREE --pairs 4 --seconds 60 --out ab.json

Prints per run and the medians over the runs of each tree: frames' CPU mean, p50, p99; commanding frames' mean
and p99; ticks' mean and p99 (ms, time.thread_time).
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
PY = "/work/main/.venv/bin/python"


def run(tree: str, seconds: float, npz: str, out: Path) -> dict:
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    subprocess.run([PY, str(HERE / "prof_frame.py"), "--mode", "plain", "--seconds", str(seconds), "--npz", npz,
                    "--out", str(out)], cwd=tree, env=env, check=True, stdout=subprocess.DEVNULL)
    d = json.loads(out.read_text())
    cpu = np.array([f["cpu"] for f in d["frames"]]) * 1e3
    cmd = np.array([f["cpu"] for f in d["frames"] if f.get("command")]) * 1e3
    tick = np.array([t["cpu"] for t in d["ticks"]]) * 1e3
    return {"tree": tree, "digest": d["digest"], "payload_digest": d["payload_digest"],
            "frame_mean": cpu.mean(), "frame_p50": np.percentile(cpu, 50), "frame_p99": np.percentile(cpu, 99),
            "cmd_mean": cmd.mean(), "cmd_p99": np.percentile(cmd, 99), "tick_mean": tick.mean(),
            "tick_p99": np.percentile(tick, 99), "utc": time.strftime("%H:%M:%S", time.gmtime()),
            "load": os.getloadavg()[0]}


def _pairs(runs: list[dict]):
    """(base run, mine run) of each pair."""
    for k in sorted({r["pair"] for r in runs}):
        side = {r["side"]: r for r in runs if r["pair"] == k}
        yield side["base"], side["mine"]


FIELDS = ("frame_mean", "frame_p50", "frame_p99", "cmd_mean", "cmd_p99", "tick_mean", "tick_p99")


def two_trees(**extra) -> argparse.Namespace:
    """The command line of a comparison of two trees (BASE MINE --seconds --npz --out), ``extra`` options too
    (name -> (type, default))."""
    ap = argparse.ArgumentParser()
    for name in ("base", "mine"):
        ap.add_argument(name)
    for name, (kind, default) in {**extra, "seconds": (float, 60.0), "npz": (str, "/tmp/perf23/workers60.npz")}.items():
        ap.add_argument(f"--{name}", type=kind, default=default)
    ap.add_argument("--out", required=True)
    return ap.parse_args()


def main() -> None:
    a = two_trees(pairs=(int, 3))
    runs = []
    tmp = Path("/tmp/perf23/ab_run.json")
    for k in range(a.pairs):
        order = (("base", a.base), ("mine", a.mine)) if k % 2 == 0 else (("mine", a.mine), ("base", a.base))
        for name, tree in order:
            r = {"side": name, "pair": k, **run(tree, a.seconds, a.npz, tmp)}
            runs.append(r)
            print(f"{r['utc']} pair {k} {name:4s} load {r['load']:.2f} " + " ".join(f"{f} {r[f]:.3f}" for f in FIELDS),
                  flush=True)
    digests = {(r["digest"], r["payload_digest"]) for r in runs}
    summary = {side: {f: statistics.median(r[f] for r in runs if r["side"] == side) for f in FIELDS}
               for side in ("base", "mine")}
    print(f"digests the same in every run: {len(digests) == 1} ({sorted(digests)[0][0][:16]}...)")
    print(f"{'median over runs, ms':22s} " + " ".join(f"{f:>10s}" for f in FIELDS))
    for side in ("base", "mine"):
        print(f"{side:22s} " + " ".join(f"{summary[side][f]:10.3f}" for f in FIELDS))
    print(f"{'mine / base':22s} " + " ".join(f"{summary['mine'][f] / summary['base'][f]:10.3f}" for f in FIELDS))
    paired = {f: statistics.median(m[f] / b[f] for b, m in _pairs(runs)) for f in FIELDS}
    print(f"{'paired ratio, median':22s} " + " ".join(f"{paired[f]:10.3f}" for f in FIELDS))
    summary["paired_ratio_median"] = paired
    Path(a.out).write_text(json.dumps({"runs": runs, "median": summary, "same_digests": len(digests) == 1,
                                       "argv": sys.argv[1:]}, indent=1))


if __name__ == "__main__":
    main()
