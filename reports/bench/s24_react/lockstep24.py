"""Two trees' frames and ticks timed in lockstep (session 23's method, reports/bench/s23_perf/lockstep.py): the
bench's robot scenario slot by slot, one tree's frame (or tick), then the other's, the order swapped every slot,
both processes pinned to the same CPU, so whatever else the shared machine runs meets both alike; CPU by
``time.thread_time`` (frame24.py --mode lockstep). Per kind of frame (all, ordinary, and each command kind as
bench.robot_cycle names them) and for ticks: each side's p50, p99 and mean (ms) and the median and mean of the
per-slot ratios mine / base. Both runs' traces (every decision and CAN byte) must be the same.

    python reports/bench/s24_react/lockstep24.py BASE_TREE MINE_TREE --cpu 0 --seconds 60 --out lockstep.json
"""
from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "s23_perf"))
from lockstep import alternate  # noqa: E402 - session 23's: two lockstep processes, slot by slot

PY = "/work/main/.venv/bin/python"
KINDS = ("speed", "alarm", "stop", "retract", "escape", "resume", "move")


def start(tree: str, cpu: int, seconds: float, npz: str, out: str) -> subprocess.Popen:
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    return subprocess.Popen(["taskset", "-c", str(cpu), PY, str(HERE / "frame24.py"), "--mode", "lockstep",
                             "--seconds", str(seconds), "--npz", npz, "--out", out], cwd=tree, env=env, text=True,
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, bufsize=1)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("base")
    ap.add_argument("mine")
    ap.add_argument("--cpu", type=int, default=0)
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--npz", default="/tmp/react24/workers60.npz")
    ap.add_argument("--out", required=True)
    a = ap.parse_args()
    outs = {side: f"{a.out}.{side}.json" for side in ("base", "mine")}
    procs = {side: start(tree, a.cpu, a.seconds, a.npz, outs[side]) for side, tree in (("base", a.base),
                                                                                       ("mine", a.mine))}
    t0, load0 = time.strftime("%H:%M:%S", time.gmtime()), os.getloadavg()[0]
    slots = alternate(procs)  # (kind, base cpu, mine cpu)
    runs = {side: json.loads(Path(o).read_text()) for side, o in outs.items()}
    same = runs["base"]["trace"] == runs["mine"]["trace"]
    kinds = [f["kind"] for f in runs["base"]["frames"]]
    frames = [(b, m) for kind, b, m in slots if kind == "frame"]
    groups = {"all frames": frames, "no command": [fm for fm, k in zip(frames, kinds) if k is None],
              "commanding": [fm for fm, k in zip(frames, kinds) if k is not None],
              **{k: [fm for fm, kk in zip(frames, kinds) if kk == k] for k in KINDS},
              "ticks": [(b, m) for kind, b, m in slots if kind == "tick"]}
    lines = [f"{t0}-{time.strftime('%H:%M:%S', time.gmtime())} UTC, cpu {a.cpu}, load {load0:.2f}-"
             f"{os.getloadavg()[0]:.2f}, {len(slots)} slots; traces the same: {same}",
             f"{'ms':12s} {'n':>5s} {'base p50':>8s} {'mine p50':>8s} {'base p99':>8s} {'mine p99':>8s} "
             f"{'base mean':>9s} {'mine mean':>9s} {'ratio med':>9s} {'ratio mean':>10s}"]
    result = {}
    for name, pairs in groups.items():
        if not pairs:
            continue
        b, m = (np.array(x) * 1e3 for x in zip(*pairs))
        r = m / b
        row = {"n": len(b), "base_p50": np.median(b), "mine_p50": np.median(m), "base_p99": np.percentile(b, 99),
               "mine_p99": np.percentile(m, 99), "base_mean": b.mean(), "mine_mean": m.mean(),
               "ratio_median": np.median(r), "ratio_mean": r.mean()}
        result[name] = {k: float(v) for k, v in row.items()}
        lines.append(f"{name:12s} {len(b):5d} " + " ".join(f"{row[k]:8.3f}" for k in (
            "base_p50", "mine_p50", "base_p99", "mine_p99")) + f" {row['base_mean']:9.3f} {row['mine_mean']:9.3f} "
            f"{row['ratio_median']:9.3f} {row['ratio_mean']:10.3f}")
    print("\n".join(lines))
    Path(a.out).write_text(json.dumps({"summary": result, "text": lines, "traces_same": same,
                                       "argv": [a.base, a.mine, a.cpu, a.seconds]}, indent=1))


if __name__ == "__main__":
    main()
