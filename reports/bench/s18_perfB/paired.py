"""Paired per-frame CPU of the perception stages, a base tree against this one, in ONE process: both trees'
modules are imported side by side and every captured frame goes through the base stage and this tree's stage
back to back (order alternating), so the machine's load, which drifts between runs of a shared box, weighs on
both alike. Reports each stage's median per-frame time in both trees and the median of the per-frame
differences, and checks every answer of this tree against the base's.

    cd TREE && OMP_NUM_THREADS=1 nice -n 10 /work/main/.venv/bin/python reports/bench/s18_perfB/paired.py \
        /tmp/perfB/cap.pkl --base /work/wt/base18 [--repeats 3]
"""
from __future__ import annotations

import argparse
import importlib
import pickle
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np


def load_tree(root: str) -> dict:
    """The perception modules of the tree at ``root`` (its own module objects, apart from any other tree's)."""
    for name in [m for m in sys.modules if m == "edge_runtime" or m.startswith("edge_runtime.") or m == "bench"
                 or m.startswith("bench.")]:
        del sys.modules[name]
    sys.path.insert(0, root)
    try:
        mods = {name: importlib.import_module(name) for name in (
            "edge_runtime.robot.keypoints", "edge_runtime.robot.lifter", "edge_runtime.robot.calibration",
            "edge_runtime.core.manifest", "bench.robot_cycle")}
    finally:
        sys.path.remove(root)
    return mods


def build(mods: dict, cap: dict):
    kp, lm, rc = mods["edge_runtime.robot.keypoints"], mods["edge_runtime.robot.lifter"], mods["bench.robot_cycle"]
    box = rc._box()
    camera, fmt = rc.box_camera(box)
    params = replace(box.lifter, precision=cap["setup"]["cfg"].lifter, threads=1)
    template = lm.StreamingLifter.from_manifest(mods["edge_runtime.core.manifest"].ASSETS_DIR, params,
                                                camera=camera, keypoint_format=fmt)
    calibration = rc._known_calibration(box.calibration)
    return kp.PersonTracker(box.people, keypoint_format=fmt), lm.PeopleLifter(template), calibration, kp.Person


def same(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return a.shape == b.shape and a.tobytes() == b.tobytes()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("capture")
    ap.add_argument("--base", required=True)
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    cap = pickle.loads(Path(args.capture).read_bytes())
    trees = {"base": load_tree(args.base), "this": load_tree(str(Path.cwd()))}
    stages = ("tracker", "lifter", "calibration")
    times = {t: {s: [] for s in stages} for t in trees}
    differ = 0
    for rep in range(args.repeats):
        made = {t: build(m, cap) for t, m in trees.items()}
        frames = zip(cap["tracker"], cap["lifter"], cap["calibration"])
        for k, ((t_s, people, _), (lt_s, _, _), ((joints, observed, ids), _)) in enumerate(frames):
            got = {}
            for t in (("base", "this") if (k + rep) % 2 else ("this", "base")):
                tracker, lifter, calibration, person = made[t]
                mine = [person(np.array(p.keypoints, copy=True), p.id) for p in people]
                c0 = time.thread_time()
                tracked = tracker.update(t_s, mine)
                c1 = time.thread_time()
                poses = lifter.push(lt_s, tracked)
                c2 = time.thread_time()
                out = calibration.to_robot(joints, observed, ids)
                c3 = time.thread_time()
                for s, dt in zip(stages, (c1 - c0, c2 - c1, c3 - c2)):
                    times[t][s].append(dt)
                got[t] = ([(p.id, p.source_id) for p in tracked],
                          [(pid, p.valid, p.joints_cam_m.tobytes(), p.observed.tobytes()) for pid, p in poses],
                          out.tobytes())
            differ += got["base"] != got["this"]
    print(f"{len(times['base']['tracker'])} frames each; answers {'all equal' if not differ else f'{differ} DIFFER'}")
    print(f"{'stage':12s} {'base p50 us':>11s} {'this p50 us':>11s} {'base mean':>9s} {'this mean':>9s} "
          f"{'median diff us':>14s}")
    for s in stages:
        b, n = np.array(times["base"][s]) * 1e6, np.array(times["this"][s]) * 1e6
        print(f"{s:12s} {np.median(b):11.1f} {np.median(n):11.1f} {b.mean():9.1f} {n.mean():9.1f} "
              f"{np.median(n - b):14.1f}")
    b = sum(np.array(times["base"][s]) for s in stages) * 1e6
    n = sum(np.array(times["this"][s]) for s in stages) * 1e6
    print(f"{'all three':12s} {np.median(b):11.1f} {np.median(n):11.1f} {b.mean():9.1f} {n.mean():9.1f} "
          f"{np.median(n - b):14.1f}")


if __name__ == "__main__":
    main()
