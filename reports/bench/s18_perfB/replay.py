"""Replay capture.py's perception inputs through this tree: each stage timed alone (CPU, time.thread_time) and
its answers checked to the bit against the captured ones (the base tree's).

    cd TREE && OMP_NUM_THREADS=1 nice -n 10 env PYTHONPATH=. /work/main/.venv/bin/python \
        reports/bench/s18_perfB/replay.py /tmp/perfB/cap.pkl [--repeats 3]

Per frame, in the loop's order: PersonTracker.update -> PeopleLifter.push -> Calibration.to_robot (the latter
fed the captured joints, so each stage sees exactly its captured input). Prints per stage p50 / mean (us) and
whether every answer matched.
"""
from __future__ import annotations

import argparse
import copy
import pickle
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path.cwd()))

import bench.robot_cycle as rc  # noqa: E402
from edge_runtime.core.manifest import ASSETS_DIR  # noqa: E402
from edge_runtime.robot.keypoints import PersonTracker  # noqa: E402
from edge_runtime.robot.lifter import PeopleLifter, StreamingLifter  # noqa: E402


def same(a, b) -> bool:
    """Equal to the bit (NaN where NaN), arrays or plain values."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        return a.shape == b.shape and a.dtype == b.dtype and a.tobytes() == b.tobytes()
    return a == b or (a != a and b != b)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("capture")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args()
    cap = pickle.loads(Path(args.capture).read_bytes())
    setup = cap["setup"]
    box = rc._box()
    camera, fmt = rc.box_camera(box)
    params = replace(box.lifter, precision=setup["cfg"].lifter, threads=1)
    template = StreamingLifter.from_manifest(ASSETS_DIR, params, camera=camera, keypoint_format=fmt)
    times = {"tracker": [], "lifter": [], "calibration": []}
    bad = {k: 0 for k in times}
    for _ in range(args.repeats):
        tracker = PersonTracker(setup["people"], keypoint_format=fmt)
        lifter = PeopleLifter(template.sibling())
        cal = copy.deepcopy(setup["calibration"])
        cal._anchor = None
        frames = zip(cap["tracker"], cap["lifter"], cap["calibration"])
        for (t_s, people, ids), (lt_s, lin, lout), ((joints, observed, cids), cout) in frames:
            people = copy.deepcopy(people)
            c0 = time.thread_time()
            tracked = tracker.update(t_s, people)
            c1 = time.thread_time()
            poses = lifter.push(lt_s, tracked)
            c2 = time.thread_time()
            out = cal.to_robot(joints, observed, cids)
            c3 = time.thread_time()
            times["tracker"].append(c1 - c0)
            times["lifter"].append(c2 - c1)
            times["calibration"].append(c3 - c2)
            bad["tracker"] += [(p.id, p.source_id) for p in tracked] != ids
            bad["lifter"] += not (len(poses) == len(lout) and all(
                pid == qid and set(vars(p)) == set(q) and all(same(getattr(p, k), q[k]) for k in q if k != "infer_s")
                for (pid, p), (qid, q) in zip(poses, lout)))
            bad["calibration"] += not same(out, cout)
    for k, v in times.items():
        v = np.array(v) * 1e6
        print(f"{k:12s} p50 {np.percentile(v, 50):7.1f} us  mean {v.mean():7.1f} us  p99 {np.percentile(v, 99):7.1f} us"
              f"  answers {'all equal' if not bad[k] else f'{bad[k]} frames DIFFER'}")


if __name__ == "__main__":
    main()
