"""The lifter's, the calibration's and the rays' per-frame CPU on the bench's robot scenario, alone.

Run from a tree (its code is imported):  cd TREE && OMP_NUM_THREADS=1 nice -n 10 \
    /work/main/.venv/bin/python reports/bench/s16_perf3/replay.py [--seconds 60] [--precision int8] [--out OUT.json]

The frames of bench/robot_cycle.py (its workers' COCO keypoints, ``/work/notes/perf/workers.npz`` as
reports/bench/s15_perf/prof_cycle.py makes it) go through the box's PersonTracker (untimed, as in the robot
command, so the H36M conversion memo is as warm as there), then, timed with time.thread_time each:
``PeopleLifter.push`` ("lifter"), ``lifter_rays`` of the people lifted invalidly ("rays"), and
``Calibration.to_robot`` of the valid ones as RobotLoop.feed_poses hands them over ("calibration"). The
hazard monitor and the link are not run, so two trees can be compared stage by stage at a lower noise
than the whole cycle's. Prints per-stage mean / p50 / p99 (ms) and a sha256 of every output to the bit
(every LiftedPose field, every robot-frame skeleton, every ray), which two trees must share.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path.cwd()))

import bench.robot_cycle as rc  # noqa: E402
from edge_runtime.robot.keypoints import Person, PersonTracker  # noqa: E402
from edge_runtime.robot.lifter import PeopleLifter, StreamingLifter  # noqa: E402
from edge_runtime.robot.loop import _measured  # noqa: E402
from edge_runtime.robot.rays import lifter_rays  # noqa: E402


def _pose_bytes(pid, p) -> bytes:
    parts = [repr((pid, p.t_s, p.valid, p.reason, p.warming_up)).encode()]
    for a in (p.joints_cam_m, p.root_cam_m, p.observed, p.held, p.joints_model_cam_m, p.missing):
        parts.append(b"-" if a is None else np.ascontiguousarray(a).tobytes())
    return b"|".join(parts)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--precision", default="int8")
    ap.add_argument("--npz", default="/work/notes/perf/workers.npz")
    ap.add_argument("--out", default=None)
    ap.add_argument("--one-call-each", action="store_true",
                    help="one onnxruntime call per person (as a model of fixed batch size gets), not one per frame")
    args = ap.parse_args()

    box = rc._box()
    camera, fmt = rc.box_camera(box)
    frames = np.load(args.npz)["keypoints_px"]
    params = replace(box.lifter, precision=args.precision, threads=1)
    lifter = PeopleLifter(StreamingLifter.from_manifest(params=params, camera=camera, keypoint_format=fmt))
    if args.one_call_each:
        lifter.template._batches = False
    tracker = PersonTracker(box.people, keypoint_format=fmt)
    cal = rc._known_calibration(box.calibration)
    digest = hashlib.sha256()
    times = {"lifter": [], "rays": [], "calibration": []}
    for k in range(int(round(args.seconds * rc.FRAME_RATE_HZ))):
        t_s = k / rc.FRAME_RATE_HZ
        people = tracker.update(t_s, [Person(keypoints=kp) for kp in frames[k % len(frames)]])
        c0 = time.thread_time()
        poses = lifter.push(t_s, people)
        c1 = time.thread_time()
        rays = {pid: lifter_rays(lifter.template, person.keypoints)
                for (pid, pose), person in zip(poses, people) if not pose.valid}
        c2 = time.thread_time()
        valid = [(pid, p) for pid, p in poses if p.valid]
        robot = None
        if valid:
            persons = np.stack([_measured(p) for _, p in valid])
            observed = np.stack([p.observed for _, p in valid])
            c3 = time.thread_time()
            robot = cal.to_robot(persons, observed, [pid for pid, _ in valid])
            c4 = time.thread_time()
            times["calibration"].append(c4 - c3)
        times["lifter"].append(c1 - c0)
        times["rays"].append(c2 - c1)
        for pid, p in poses:
            digest.update(_pose_bytes(pid, p))
        for pid, r in rays.items():
            digest.update(repr(pid).encode() + r.tobytes())
        digest.update(b"R" + (b"-" if robot is None else robot.tobytes()))
    st = lifter.stats.to_json()
    summary = {"tree": str(Path.cwd()), "precision": args.precision, "one_call_each": args.one_call_each,
               "digest": digest.hexdigest(),
               "stats": {k: v for k, v in st.items() if k not in ("infer_s", "mean_infer_ms")}}
    for name, v in times.items():
        v = np.asarray(v) * 1e3
        summary[name] = {"n": len(v), "mean": float(v.mean()), "p50": float(np.percentile(v, 50)),
                         "p99": float(np.percentile(v, 99))}
    print(json.dumps(summary))
    if args.out:
        Path(args.out).write_text(json.dumps({**summary, "times_s": times}))


if __name__ == "__main__":
    main()
