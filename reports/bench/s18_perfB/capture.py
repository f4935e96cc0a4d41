"""Capture the perception stages' inputs in the bench scenario (simulated clock, prof_cycle's frames) -> pickle.

Records every PersonTracker.update (t_s, people), PeopleLifter.push (t_s, people), lifter_rays keypoints and
Calibration.to_robot (joints, observed, ids) call, with the answers: the inputs paired.py times each stage on
(a base tree's and this one's, side by side).

    cd TREE && OMP_NUM_THREADS=1 nice -n 10 env PYTHONPATH=. /work/main/.venv/bin/python \
        reports/bench/s18_perfB/capture.py --seconds 60 --out /tmp/perfB/cap.pkl
"""
from __future__ import annotations

import argparse
import copy
import pickle
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path.cwd()))

import bench.robot_cycle as rc  # noqa: E402
import edge_runtime.robot.calibration as calmod  # noqa: E402
import edge_runtime.robot.keypoints as kpmod  # noqa: E402
import edge_runtime.robot.lifter as liftmod  # noqa: E402
import edge_runtime.robot.loop as loopmod  # noqa: E402

CAP: dict = {"tracker": [], "lifter": [], "rays": [], "calibration": []}


def _pose(p):
    return {k: (None if v is None else np.array(v, copy=True) if isinstance(v, np.ndarray) else v)
            for k, v in vars(p).items()}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--npz", default="/work/notes/perf/workers.npz")
    ap.add_argument("--out", required=True)
    args = ap.parse_args()

    upd = kpmod.PersonTracker.update

    def update(self, t_s, people):
        inp = copy.deepcopy(list(people))
        out = upd(self, t_s, people)
        CAP["tracker"].append((t_s, inp, [(p.id, p.source_id) for p in out]))
        return out

    push = liftmod.PeopleLifter.push

    def lpush(self, t_s, people):
        inp = [(p.id, np.array(p.keypoints, copy=True)) for p in people]
        out = push(self, t_s, people)
        CAP["lifter"].append((t_s, inp, [(pid, _pose(p)) for pid, p in out]))
        return out

    rays = loopmod.lifter_rays

    def lrays(lifter, keypoints):
        out = rays(lifter, keypoints)
        CAP["rays"].append((np.array(keypoints, copy=True), out.copy()))
        return out

    to_robot = calmod.Calibration.to_robot

    def cal(self, joints, observed=None, ids=None):
        inp = (np.array(joints, copy=True), None if observed is None else np.array(observed, copy=True),
               None if ids is None else list(ids))
        out = to_robot(self, joints, observed, ids)
        CAP["calibration"].append((inp, out.copy()))
        return out

    kpmod.PersonTracker.update = update
    liftmod.PeopleLifter.push = lpush
    loopmod.lifter_rays = lrays
    calmod.Calibration.to_robot = cal

    from edge_runtime.core.manifest import ASSETS_DIR, load_manifest

    lifter = rc.lifter_entry(load_manifest(ASSETS_DIR)["models"])
    cfg = rc.RobotConfig(args.npz, args.seconds, "", lifter["precision"], rc._arm_posture(), simulated=True)
    rc.run_cycle(cfg)
    box = rc._box()
    CAP["setup"] = {"people": box.people, "calibration": rc._known_calibration(box.calibration), "cfg": cfg}
    Path(args.out).write_bytes(pickle.dumps(CAP))
    print({k: len(v) for k, v in CAP.items() if isinstance(v, list)})


if __name__ == "__main__":
    main()
