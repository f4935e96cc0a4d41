"""Session 13: the whole-body ray bound against the truth through calibrations the runtime fitted.

For head-error development seeds 1-3 (10 placements each: a camera 3-8 m away and 1-3 m high, a worker's
labelled marker walk at a real detector's noise, lifted by the shipped int8 lifter, fitted by
``from_recording``), 40 bodies each near the arm (pelvis 0.6-4 m from the effector, every keypoint up to
RAY_KEYPOINT_ERROR_M off its joint, 0-3 joints hidden) are seen through the TRUE camera and bounded
through the FITTED one, as the runtime does. Prints how many bounds lie above the true separation.

    PYTHONPATH=.:tests python reports/robot/ray_bound_s13.py rigid|pnp
"""
import sys

import numpy as np
from support.robot import EFF
from tests.robot.test_hazard import FLOOR_Y, body_near_arm, separation_of

from edge_runtime.core.manifest import ASSETS_DIR
from edge_runtime.robot import calibration as C
from edge_runtime.robot.hazard import PersonRays, ZoneParams, effector_capsule, ray_separation_m
from edge_runtime.robot.lifter import LifterParams, StreamingLifter
from firmware_sim.scenarios import head_error as he

method = sys.argv[1]
lifter = StreamingLifter.from_manifest(ASSETS_DIR, LifterParams(precision="int8"))
cals = []
for seed in (1, 2, 3):
    for s in np.random.default_rng(seed).integers(0, 2**31, 10):
        lifter.restart()
        rng = np.random.default_rng(int(s))
        camera = he.random_placement(rng)
        walk, labels = he.calibration_motion(he._body(rng), rng)
        joints = he.lift(lifter, he.detect(camera, walk.joints_m, rng, he.NOISES["real"]), 0.0, warm=False)
        try:
            cal = C.from_recording(walk.t_s, joints, C.CalibrationParams(method=method), marker=labels)
        except C.CalibrationError:
            continue
        cals.append((cal, camera.R, camera.position_m))
zones, caps = ZoneParams(), effector_capsule(EFF)
rng = np.random.default_rng(7)
over, none = [], 0
for cal, R, c_true in cals:
    for _ in range(40):
        body, keypoints = body_near_arm(rng)
        seen_cam = (keypoints - c_true) @ R.T
        if (seen_cam[:, 2] < 0.3).any():
            continue
        d = seen_cam @ cal.A.T
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        d[rng.choice(17, size=int(rng.integers(0, 4)), replace=False)] = np.nan
        b = ray_separation_m(PersonRays(cal.b.copy(), d, FLOOR_Y), caps, zones)
        if b is None:
            none += 1
        else:
            over.append(b[0] - separation_of(body))
over = np.array(over)
print(f"{method}: {len(cals)} calibrations, {len(over)} bounds (None {none}); above the truth {(over > 0).sum()}, "
      f"by > 0.1 m {(over > 0.1).sum()}, by > 0.5 m {(over > 0.5).sum()}; worst {over.max():+.2f} m; "
      f"median slack {-np.median(over):.2f} m")
