"""The bench's robot cycle in real time with one schedule of frames and ticks (session 19, task "tick").

Runs ``bench.robot_cycle.measure_robot`` in this process (not ``python -m bench``) on CPU 0 with the other core
busy (``bench.machine.LoadGenerator`` on CPU 1), with ``RobotConfig.schedule`` "grid" (the bench's fixed grids,
a tick before a frame due at the same instant) or "live" (the robot command's camera driver's order), and
prints the reaction (keypoints due -> command on the link) and the cycle. Run A and B alternately, one process
each:

    cd TREE && for s in grid live grid live; do OMP_NUM_THREADS=1 nice -n 10 env PYTHONPATH=. \
        /work/main/.venv/bin/python reports/bench/s19_tick/schedule_ab.py --schedule $s --seconds 60 \
        --out /tmp/tick/ab_$s_$(date +%H%M%S).json; done

``--cpu-clock``: the run on a clock that advances with this thread's CPU time (time.thread_time) and jumps over
the idle time to the next due slot, instead of the wall clock: an unloaded core's timeline (no preemption by
other processes, no sleep overshoot), so that two schedules compare on a shared, loaded machine. Every
latency then is CPU time spent on this thread from the due time (ticks, arm slots and the frame itself).
"""
from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np

import bench.robot_cycle as rc
from bench.machine import LoadGenerator


class _CpuClock:
    """``bench.robot_cycle._SimClock``'s interface on the thread's CPU time (see the module docstring)."""

    def __init__(self):
        self.base_s, self.cpu0_s = 0.0, time.thread_time()

    def __call__(self) -> float:
        return self.base_s + time.thread_time() - self.cpu0_s

    def wait_until(self, due_s: float) -> None:
        if due_s > self():
            self.base_s, self.cpu0_s = due_s, time.thread_time()


def _waits(run) -> dict:
    """How long frames waited from their due time to their start (ms): every frame, the frames due at a tick's
    instant on the grid (every third), and the commanding frames (their from_due less their from pick-up)."""
    late = np.asarray(run.late_s) * 1e3
    cmd = (np.asarray(run.due_reaction_s) - np.asarray(run.reaction_s)) * 1e3

    def pct(v):
        return {"n": int(v.size), "p50": round(float(np.percentile(v, 50)), 3), "p99": round(float(np.percentile(v, 99)), 3),
                "max": round(float(v.max()), 3), "mean": round(float(v.mean()), 3)} if v.size else {"n": 0}

    # frame 0 left out: it is late by the start-up (the arm's first state, cold caches) on either schedule
    return {"all_frames": pct(late[1:]), "at_tick_instants": pct(late[3::3]), "commanding_frames": pct(cmd)}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--schedule", choices=rc.SCHEDULES, required=True)
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--npz", default="/work/notes/perf/workers.npz")
    ap.add_argument("--out", required=True)
    ap.add_argument("--cpu-clock", action="store_true")
    args = ap.parse_args()
    from edge_runtime.core.manifest import ASSETS_DIR, load_manifest

    lifter = rc.lifter_entry(load_manifest(ASSETS_DIR)["models"])
    cfg = rc.RobotConfig(args.npz, args.seconds, "", lifter["precision"], rc._arm_posture(), schedule=args.schedule,
                         simulated=args.cpu_clock)
    if args.cpu_clock:
        rc._SimClock = _CpuClock  # run_cycle's simulated clock, on CPU time
    runs = []
    run_cycle = rc.run_cycle
    rc.run_cycle = lambda c: runs.append(run_cycle(c)) or runs[-1]  # measure_robot's run, kept for its waits
    with LoadGenerator([1]):  # started before this process is pinned: it checks the CPU is ours
        os.sched_setaffinity(0, {0})
        t0 = time.strftime("%H:%M:%S", time.gmtime())
        rows = rc.measure_robot(cfg)
    t1 = time.strftime("%H:%M:%S", time.gmtime())
    out = {"schedule": args.schedule, "cpu_clock": args.cpu_clock, "utc": [t0, t1], "load_avg": os.getloadavg(),
           "rows": rows, "waits": _waits(runs[0])}
    Path(args.out).write_text(json.dumps(out, indent=1))
    by = {r["name"]: r for r in rows}
    cyc, rea, tick = by["robot_30hz"], by["robot_reaction"], by["robot_tick_command"]

    def ms(d, k):
        return d[k] / 1e3 if d.get(k) is not None else float("nan")

    fd, cpu = rea["from_due"], rea["frame_cpu"]
    print(f"{args.schedule:5s}{' cpu-clock' if args.cpu_clock else ''} {t0}-{t1} load {out['load_avg'][0]:.2f}: from_due n {fd['n']} p50 {ms(fd, 'p50_us'):.2f} "
          f"p99 {ms(fd, 'p99_us'):.2f} max {ms(fd, 'max_us'):.2f} ms | from pick-up p50 {ms(rea, 'p50_us'):.2f} p99 "
          f"{ms(rea, 'p99_us'):.2f} | frame_cpu p50 {ms(cpu, 'p50_us'):.2f} p99 {ms(cpu, 'p99_us'):.2f} | cycle p50 "
          f"{ms(cyc, 'p50_us'):.2f} p99 {ms(cyc, 'p99_us'):.2f} | start_late p99 {cyc['start_late_p99_us'] / 1e3:.2f} "
          f"| misses {cyc['deadline_misses']} unacked {cyc['unacked']} | tick cmds n {tick['n']} | cpu "
          f"{cyc['cpu_share_pct']:.1f} %", flush=True)
    w = out["waits"]
    print("      waits due -> start ms: " + "; ".join(f"{k} p50 {v['p50']:.3f} p99 {v['p99']:.3f} max {v['max']:.3f} "
                                                      f"mean {v['mean']:.3f}" for k, v in w.items() if v["n"]),
          flush=True)


if __name__ == "__main__":
    main()
