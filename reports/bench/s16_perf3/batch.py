"""The shipped lifters batched, on this CPU: (1) every realistic window of the bench scenario through one call of
N windows against N calls of one, to the bit; (2) the CPU of one call on N windows against N calls of one.

Run from a tree (its code is imported):  cd TREE && OMP_NUM_THREADS=1 nice -n 10 \
    /work/main/.venv/bin/python reports/bench/s16_perf3/batch.py [--npz /work/notes/perf/workers.npz]

(1) Windows: the bench's two workers (bench/robot_cycle.py, the npz reports/bench/s15_perf/prof_cycle.py makes)
through the box's PersonTracker and a PeopleLifter, every third frame's windows, 1,200 per precision; batches
of 2, 3, 4 and 7 against batch 1: prints the largest difference (0: the same bits). (2) thread time of a call,
the median of 300 calls, in 6 interleaved rounds of batch sizes 1, 2 and 3.
"""
from __future__ import annotations

import argparse
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path.cwd()))

import bench.robot_cycle as rc  # noqa: E402
from edge_runtime.robot.keypoints import Person, PersonTracker  # noqa: E402
from edge_runtime.robot.lifter import INPUT_NAME, PeopleLifter, StreamingLifter  # noqa: E402


def windows(precision: str, frames: np.ndarray) -> tuple[StreamingLifter, np.ndarray]:
    box = rc._box()
    camera, fmt = rc.box_camera(box)
    params = replace(box.lifter, precision=precision, threads=1)
    people = PeopleLifter(StreamingLifter.from_manifest(params=params, camera=camera, keypoint_format=fmt))
    tracker = PersonTracker(box.people, keypoint_format=fmt)
    out = []
    for k in range(1800):
        people.push(k / 30, tracker.update(k / 30, [Person(keypoints=kp) for kp in frames[k % len(frames)]]))
        if k % 3 == 0:
            out += [lf.window().copy() for lf in people.lifters.values() if lf._buffered_t is not None]
    return people.template, np.stack(out)


def largest_difference(lifter: StreamingLifter, w: np.ndarray) -> float:
    run = lifter.session.run
    ref = [run(lifter._outputs, {INPUT_NAME: w[i:i + 1]}) for i in range(len(w))]
    worst = 0.0
    for n in (2, 3, 4, 7):
        for s in range(0, len(w) - n, n):
            pose, root = run(lifter._outputs, {INPUT_NAME: np.ascontiguousarray(w[s:s + n])})
            for i in range(n):
                worst = max(worst, float(np.abs(pose[i] - ref[s + i][0][0]).max()),
                            float(np.abs(root[i] - ref[s + i][1][0]).max()))
    return worst


def call_cpu_us(lifter: StreamingLifter, w: np.ndarray) -> dict[int, list[float]]:
    rounds: dict[int, list[float]] = {}
    for _ in range(6):
        for n in (1, 2, 3):
            x = {INPUT_NAME: np.ascontiguousarray(w[:n])}
            for _ in range(20):
                lifter.session.run(lifter._outputs, x)
            cpu = []
            for _ in range(300):
                c0 = time.thread_time()
                lifter.session.run(lifter._outputs, x)
                cpu.append(time.thread_time() - c0)
            rounds.setdefault(n, []).append(float(np.median(cpu)) * 1e6)
    return rounds


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--npz", default="/work/notes/perf/workers.npz")
    args = ap.parse_args()
    frames = np.load(args.npz)["keypoints_px"]
    for precision in ("int8", "fp32"):
        lifter, w = windows(precision, frames)
        print(f"{precision}: {len(w)} windows, largest difference batch N vs 1: {largest_difference(lifter, w)}")
        for n, v in call_cpu_us(lifter, w).items():
            print(f"  batch {n}: median {np.median(v):.0f} us of CPU a call (rounds {', '.join(f'{x:.0f}' for x in v)})")


if __name__ == "__main__":
    main()
