"""Does a camera frame wait for a control tick in the product's live driver? (session 19, task "tick")

Drives edge_runtime/robot/command.py's own ``_live_frames`` (its camera reader thread, its queue and its
``q.get(timeout=TICK_S)``) in real time with a stand-in loop whose ``tick()`` and frames spend fixed CPU
(pure-Python spinning, so they hold the GIL as the loop's Python code does), and a camera that queues a frame
every 1/30 s (optionally with Gaussian jitter on each frame's time). Per frame: when the camera had it (its due time: the
reader thread may then wait for the GIL, held by a tick in Python, before it can queue it),
when the driver handed it over (the generator's yield returned in the main thread), and whether a tick was
running when it was ready. Prints per configuration: frames, how many were queued during a tick, and the
hand-over delay p50/p99/max (us), split by whether a tick was running.

    cd TREE && OMP_NUM_THREADS=1 nice -n 10 env PYTHONPATH=. /work/main/.venv/bin/python \
        reports/bench/s19_tick/live_interleave.py --seconds 20 [--out OUT.json]
"""
from __future__ import annotations

import argparse
import json
import random
import time
from pathlib import Path

import numpy as np

from edge_runtime.robot import command


def _spin(s: float) -> None:
    end = time.perf_counter() + s
    while time.perf_counter() < end:
        pass


class _Loop:
    def __init__(self, tick_s: float):
        self.tick_s = tick_s
        self.ticks: list[tuple[float, float]] = []

    def tick(self) -> None:
        t0 = time.perf_counter()
        _spin(self.tick_s)
        self.ticks.append((t0, time.perf_counter()))


def run(seconds: float, tick_s: float, frame_s: float, jitter_s: float, seed: int = 1) -> dict:
    rng = random.Random(seed)
    loop = _Loop(tick_s)
    queued: list[float] = []
    start = time.perf_counter()

    def camera():
        for k in range(int(seconds * 30)):
            due = start + k / 30 + (rng.gauss(0.0, jitter_s) if jitter_s else 0.0)
            delay = due - time.perf_counter()
            if delay > 0:
                time.sleep(delay)
            queued.append(due)  # when the frame is ready: the thread may wait for the GIL to queue it
            yield k, (lambda lp: _spin(frame_s))

    handed, frame_ends = [], []
    for _, feed in command._live_frames(loop, camera(), time.monotonic(), None):
        handed.append(time.perf_counter())
        feed(loop)
        frame_ends.append(time.perf_counter())
    n = min(len(queued), len(handed))
    q, h = np.array(queued[:n]), np.array(handed[:n])
    starts = np.array([a for a, _ in loop.ticks])
    ends = np.array([b for _, b in loop.ticks])
    idx = np.searchsorted(starts, q) - 1  # the last tick that started before the frame was queued
    in_tick = (idx >= 0) & (ends[np.maximum(idx, 0)] > q)
    # a frame queued while the previous frame still ran (the frame itself is behind, not a tick)
    fe = np.array(frame_ends[:n])
    behind = np.r_[False, fe[:-1] > q[1:]]
    wait_us = (h - q) * 1e6
    gaps = np.diff(starts) * 1e3

    def stats(sel):
        w = wait_us[sel]
        return {"n": int(sel.sum()), **({"p50_us": round(float(np.percentile(w, 50)), 1),
                                         "p99_us": round(float(np.percentile(w, 99)), 1),
                                         "max_us": round(float(w.max()), 1)} if sel.any() else {})}

    return {"tick_ms": tick_s * 1e3, "frame_ms": frame_s * 1e3, "jitter_ms": jitter_s * 1e3, "frames": n,
            "queued_during_tick": int(in_tick.sum()), "queued_during_previous_frame": int(behind.sum()),
            "all": stats(np.ones(n, bool)), "during_tick": stats(in_tick), "clear": stats(~in_tick & ~behind),
            "ticks": len(starts), "tick_gap_ms_p50_max": [round(float(np.percentile(gaps, 50)), 2),
                                                         round(float(gaps.max()), 2)]}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=20.0)
    ap.add_argument("--out", default=None)
    args = ap.parse_args()
    rows = []
    for tick_ms, frame_ms in ((0.45, 4.2), (1.2, 4.2)):
        for jitter_ms in (0.0, 1.0, 3.0):
            r = run(args.seconds, tick_ms / 1e3, frame_ms / 1e3, jitter_ms / 1e3)
            rows.append(r)
            print(json.dumps(r), flush=True)
    if args.out:
        Path(args.out).write_text(json.dumps(rows, indent=1))


if __name__ == "__main__":
    main()
