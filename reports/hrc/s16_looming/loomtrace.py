"""s16_walkby2/jtrace.py's trace plus, per lifted person and frame, his keypoints' viewing rays in
the robot frame (unit directions from the camera centre; NaN where the keypoint is not seen, as the lifter's
min_score): the product computes rays only for people it cannot lift, so hrc_world._feed is wrapped to make
them for everyone (observe-only: the loop still gets only the unlifted ones).  Written as "rays" next to the
lifted joints, and "cam" (the camera centre) per frame.
usage: loomtrace.py SEED NAME OUT.json     (development seeds only)"""
import json
import runpy
import sys
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
WALKBY2 = HERE.parent / "s16_walkby2"
sys.path.insert(0, str(WALKBY2))
sys.path.insert(0, str(HERE.parent / "s15_walkby"))
import tracebase  # noqa: E402

from edge_runtime.robot import hazard  # noqa: E402
from edge_runtime.robot.rays import lifter_rays  # noqa: E402
from firmware_sim.scenarios import hrc_world  # noqa: E402

current = {}
per_frame = []
orig_feed = hrc_world._feed


def feed(loop, outs, percepts, k):
    # every worker's rays through the lifter's camera, into the robot frame by the loop's own calibration
    rays = {w: lifter_rays(p.lifter, p.keypoints[k]) for w, p in enumerate(percepts)
            if isinstance(p, hrc_world.LifterPerception)}
    current.clear()
    current.update(loop._robot_rays(rays))
    return orig_feed(loop, outs, percepts, k)


orig_observe = hazard.HazardMonitor.observe


def observe(self, *a, **kw):
    dec = orig_observe(self, *a, **kw)
    if self.zones.separation != "head":     # jtrace.py records a frame exactly then
        per_frame.append({int(w): (np.round(r.origin_m, 3).tolist(), np.round(r.directions, 5).tolist())
                          for w, r in current.items()})
    return dec


orig_run = tracebase.run


def run(su, extra, frames):
    orig_run(su, extra, frames)
    with open(su.args.out) as f:
        X = json.load(f)
    assert len(X["frames"]) == len(per_frame)
    for fr, rr in zip(X["frames"], per_frame):
        for w, p in fr["lifted"].items():
            if int(w) in rr:
                fr["cam"], p["rays"] = rr[int(w)]
    with open(su.args.out, "w") as f:
        json.dump(X, f, default=float)


hrc_world._feed = feed
hazard.HazardMonitor.observe = observe
tracebase.run = run
runpy.run_path(str(WALKBY2 / "jtrace.py"), run_name="__main__")
