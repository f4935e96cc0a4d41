"""The stance candidate's lag for a person who stops working and walks toward the arm at 2 m/s (s17 headtail).

    PYTHONPATH=. python reports/robot/s17_headtail/lag.py --placements 20 --seed 4

Per placement (the head-error tool's camera placements and real-detector noise, the true calibration): a
worker works 3 s at a random point 3-8 m from the camera, then walks at 2 m/s (accelerating at 4 m/s^2)
toward a point 0.5 m from the arm's base axis. Scored over the first 1.5 s of the walk: how much farther from
the arm (head, on the ground) each anchoring places him than the shipped one does (m), and that as time at
2 m/s. A lag of the hazard monitor's input is a distance it places a person nearer the arm too late.
"""
from __future__ import annotations

import argparse
import math

import numpy as np
from candidates import stance_anchor, still_detected

from edge_runtime.core.manifest import ASSETS_DIR
from edge_runtime.core.skeleton import HEAD
from edge_runtime.robot.lifter import LifterParams, StreamingLifter
from firmware_sim.devices.camera import REAL_DETECTOR, detect, random_placement
from firmware_sim.people import motions
from firmware_sim.scenarios.head_error import RATE_HZ, WORK_S, _body, lift, stop_points, true_calibration

SPEED_MPS = 2.0
SCORED_S = 1.5


def _arm_distance_m(robot: np.ndarray, frames: np.ndarray) -> np.ndarray:
    """The head's ground distance from the arm's base axis (the robot frame's y axis) in ``frames``."""
    return np.hypot(robot[frames, HEAD, 0], robot[frames, HEAD, 2])


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--placements", type=int, default=20)
    ap.add_argument("--seed", type=int, default=4)
    ap.add_argument("--radius-m", type=float, default=0.25)
    a = ap.parse_args()
    lifter = StreamingLifter.from_manifest(ASSETS_DIR, LifterParams(precision="int8"))
    extra: dict[str, list] = {}
    for s in np.random.default_rng(a.seed).integers(0, 2**31, a.placements):
        rng = np.random.default_rng(int(s))
        lifter.restart()
        camera = random_placement(rng)
        body = _body(rng)
        start = stop_points(camera, rng, 1)[0]
        goal = 0.5 * start / np.linalg.norm(start)
        work = motions.work_at(body, start, math.atan2(-start[0], -start[1]), WORK_S, rate_hz=RATE_HZ, rng=rng)
        go = motions.walk(body, [start, goal], SPEED_MPS, RATE_HZ, accel_mps2=4.0, rng=rng)
        mot = motions.concat([work, go], blend_s=0.3)
        J, obs, warm = lift(lifter, detect(camera, mot.joints_m, rng, REAL_DETECTOR), 0.0, warm=True)
        valid = np.isfinite(J).all(axis=(1, 2))
        onset = int(np.flatnonzero(np.asarray(mot.labels) != "work")[0])
        scored = np.zeros(len(J), bool)
        scored[onset: onset + int(SCORED_S * RATE_HZ)] = True
        scored &= valid & ~warm
        if not scored.any():
            continue
        anchored = {}
        for name, frames in (("shipped", 0), ("stance (Calibration.anchor_stance_frames 90)", 90)):
            cal = true_calibration(camera)
            cal.anchor_stance_frames = frames
            out = np.full_like(J, np.nan)
            for t in np.flatnonzero(valid):
                out[t] = cal.to_robot(J[t][None], obs[t][None])[0]
            anchored[name] = out
        # the same estimate without the nearer-to-the-arm choice (offline only): what that choice buys
        anchored["stance without the nearer choice"] = stance_anchor(still_detected(a.radius_m), 90, False)(
            true_calibration(camera), J, obs, valid)
        base = _arm_distance_m(anchored.pop("shipped"), scored)
        for v, out in anchored.items():
            extra.setdefault(v, []).append(_arm_distance_m(out, scored) - base)
    for v, e in extra.items():
        e = np.concatenate(e)
        print(f"{v}: placed farther from the arm than the shipped anchoring, first {SCORED_S:g} s of a {SPEED_MPS:g} m/s "
              f"walk toward it ({len(e)} frames): mean {e.mean():+.3f} m ({e.mean() / SPEED_MPS * 1000:+.0f} ms), "
              f"p95 {np.percentile(e, 95):+.3f} m ({np.percentile(e, 95) / SPEED_MPS * 1000:+.0f} ms), "
              f"max {e.max():+.3f} m; share > 0.1 m {np.mean(e > 0.1):.3f}")


if __name__ == "__main__":
    main()
