"""Worker 2's sphere clearance (the judge's measure) against the arm as it moved and against the arm frozen at 5.80 s,
and the arm's joint change since 5.80 s, 5.6-7.0 s."""
import json

import numpy as np

from firmware_sim.robot.sawyer import _spheres_by_segment, collision_spheres
from firmware_sim.scenarios import hrc
from firmware_sim.scenarios.hrc_world import scene_joints

d = json.load(open("base.json"))
sc = next(s for s in hrc.scenarios_for("hard:200", 15, 2.0) if s.name == "hard_110")
J = scene_joints(sc, 100)
steps = {s["t"]: s for s in d["steps"]}
q0 = np.array(steps[5.8]["q"])
cf, rf = collision_spheres(q0)
N = ['pelvis', 'rhip', 'rknee', 'rank', 'lhip', 'lknee', 'lank', 'spine', 'thorax', 'neck', 'head', 'lsho', 'lelb',
     'lwri', 'rsho', 'relb', 'rwri']
for t in sorted(steps):
    if not (5.6 <= t <= 7.0) or round(t * 100) % 5:
        continue
    k = int(round(t * 100))
    q = np.array(steps[t]["q"])
    c, r, seg = _spheres_by_segment(q)
    da = np.linalg.norm(J[2, k][:, None] - c[None], axis=-1) - r[None]
    df = np.linalg.norm(J[2, k][:, None] - cf[None], axis=-1) - rf[None]
    ja, sa = np.unravel_index(da.argmin(), da.shape)
    jf, _ = np.unravel_index(df.argmin(), df.shape)
    print(f"{t:5.2f} actual {da.min():+.3f} ({N[ja]}-seg{seg[sa]})  frozen {df.min():+.3f} ({N[jf]})  "
          f"dq since 5.80 (deg) {np.round(np.degrees(q - q0), 1).tolist()}")
