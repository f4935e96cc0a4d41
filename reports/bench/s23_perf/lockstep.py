"""Two trees' frames and ticks timed in lockstep: the same scenario slot by slot, one tree's frame (or tick), then
the other's, the order swapped every slot, both processes pinned to the same CPU. Whatever else the shared machine
runs meets both alike within microseconds, so the per-slot ratio of their CPU times (time.thread_time) measures
the code, not the moment (the paired whole-run A/B of ab.py still moved by +-15 % at load 3).

    python reports/bench/s23_perf/lockstep.py BASE_TREE MINE_TREE --cpu 0 --seconds 60 --out lockstep.json

Prints, for frames, commanding frames and ticks: the means and p50/p99 of each side, and the median and mean of
the per-slot ratios mine / base; both runs' decision digests must agree (prof_frame.py writes them).
"""
from __future__ import annotations

import json
import os
import subprocess
import time
from pathlib import Path

import numpy as np
from ab import two_trees

HERE = Path(__file__).resolve().parent
PY = "/work/main/.venv/bin/python"


def start(tree: str, cpu: int, seconds: float, npz: str, out: str) -> subprocess.Popen:
    env = {**os.environ, "OMP_NUM_THREADS": "1"}
    return subprocess.Popen(["taskset", "-c", str(cpu), PY, str(HERE / "prof_frame.py"), "--mode", "lockstep",
                             "--seconds", str(seconds), "--npz", npz, "--out", out], cwd=tree, env=env, text=True,
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, bufsize=1)


def step(proc: subprocess.Popen) -> tuple[str, float] | None:
    """Its next slot's (kind, CPU s), or None once its run is over."""
    try:
        proc.stdin.write("\n")
        proc.stdin.flush()
    except BrokenPipeError:  # the run is over and the process gone
        return None
    line = proc.stdout.readline()
    if not line:
        return None
    kind, cpu = line.split()
    return kind, float(cpu)


def alternate(procs: dict) -> list[tuple[str, float, float]]:
    """Run the two lockstep processes (``procs``: "base" and "mine") slot by slot, the order swapped every slot, until
    either ends: (kind, base CPU s, mine CPU s) of each slot; both closed and waited for after."""
    slots, i = [], 0
    while True:
        order = ("base", "mine") if i % 2 == 0 else ("mine", "base")
        got = {}
        for side in order:
            got[side] = step(procs[side])
            if got[side] is None:
                break
        if len(got) < 2 or got[order[1]] is None:
            break
        assert got["base"][0] == got["mine"][0], (i, got)
        slots.append((got["base"][0], got["base"][1], got["mine"][1]))
        i += 1
    for p in procs.values():
        try:
            p.stdin.close()
        except BrokenPipeError:
            pass
        p.wait()
    return slots


def main() -> None:
    a = two_trees(cpu=(int, 0))
    outs = {"base": "/tmp/perf23/lockstep_base.json", "mine": "/tmp/perf23/lockstep_mine.json"}
    procs = {side: start(tree, a.cpu, a.seconds, a.npz, outs[side]) for side, tree in (("base", a.base),
                                                                                       ("mine", a.mine))}
    t0 = time.strftime("%H:%M:%S", time.gmtime())
    slots = alternate(procs)
    runs = {side: json.loads(Path(o).read_text()) for side, o in outs.items()}
    commanding = [f.get("command") is not None for f in runs["base"]["frames"]]
    lines = [f"{t0}-{time.strftime('%H:%M:%S', time.gmtime())} UTC, cpu {a.cpu}, load {os.getloadavg()[0]:.2f}, "
             f"{len(slots)} slots; digests the same: "
             f"{all(runs['base'][k] == runs['mine'][k] for k in ('digest', 'payload_digest'))}",
             f"{'ms':18s} {'base mean':>9s} {'mine mean':>9s} {'base p50':>9s} {'mine p50':>9s} {'base p99':>9s} "
             f"{'mine p99':>9s} {'ratio med':>9s} {'ratio mean':>10s}"]
    frames = [(b, m) for kind, b, m in slots if kind == "frame"]
    table = {"frames": frames, "commanding frames": [fm for fm, c in zip(frames, commanding) if c],
             "ticks": [(b, m) for kind, b, m in slots if kind == "tick"]}
    result = {}
    for name, pairs in table.items():
        b, m = (np.array(x) * 1e3 for x in zip(*pairs))
        r = m / b
        row = {"base_mean": b.mean(), "mine_mean": m.mean(), "base_p50": np.median(b), "mine_p50": np.median(m),
               "base_p99": np.percentile(b, 99), "mine_p99": np.percentile(m, 99), "ratio_median": np.median(r),
               "ratio_mean": r.mean(), "n": len(b)}
        result[name] = {k: float(v) for k, v in row.items()}
        lines.append(f"{name:18s} " + " ".join(f"{row[k]:9.3f}" for k in ("base_mean", "mine_mean", "base_p50",
                                                                          "mine_p50", "base_p99", "mine_p99",
                                                                          "ratio_median")) + f" {row['ratio_mean']:10.3f}")
    print("\n".join(lines))
    Path(a.out).write_text(json.dumps({"summary": result, "text": lines, "argv": [a.base, a.mine, a.cpu, a.seconds]},
                                      indent=1))


if __name__ == "__main__":
    main()
