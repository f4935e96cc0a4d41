"""Clearance of every worker against the arm FROZEN at its posture of time T (s) for the rest of the
scenario, from the traced run's true joints (the same scene_joints as run_scenario), against the traced arm."""
import json
import sys

import numpy as np

from firmware_sim.robot.sawyer import _spheres_by_segment, collision_spheres
from firmware_sim.scenarios import hrc
from firmware_sim.scenarios.hrc_world import scene_joints

trace, T = sys.argv[1], float(sys.argv[2])
d = json.load(open(trace))
sc = next(s for s in hrc.scenarios_for("hard:200", 15, 2.0) if s.name == "hard_110")
J = scene_joints(sc, 100)
steps = {s["t"]: s for s in d["steps"]}
q_frozen = np.array(steps[T]["q"])
c0, r0 = collision_spheres(q_frozen)
seg = _spheres_by_segment(q_frozen)
print("segments of spheres:", [int(x) for x in seg[2]] if len(seg) > 2 else seg)
N = ['pelvis', 'rhip', 'rknee', 'rank', 'lhip', 'lknee', 'lank', 'spine', 'thorax', 'neck', 'head', 'lsho', 'lelb',
     'lwri', 'rsho', 'relb', 'rwri']
best_f, best_a = (9, None), (9, None)
for t in sorted(steps):
    if t < T - 1e-9 or t > 8.0:
        continue
    k = int(round(t * 100))
    q = np.array(steps[t]["q"])
    for w in range(J.shape[0]):
        if not np.isfinite(J[w, k, 0, 0]):
            continue
        for name, (c, r) in (("frozen", (c0, r0)), ("actual", collision_spheres(q))):
            dj = np.linalg.norm(J[w, k][:, None] - c[None], axis=-1) - r[None]
            m = float(dj.min())
            if name == "frozen" and m < best_f[0]:
                best_f = (m, t, w, N[np.unravel_index(dj.argmin(), dj.shape)[0]])
            if name == "actual" and m < best_a[0]:
                best_a = (m, t, w, N[np.unravel_index(dj.argmin(), dj.shape)[0]],
                          int(np.unravel_index(dj.argmin(), dj.shape)[1]))
print("arm frozen at", T, "-> min sphere clearance", best_f)
print("arm as it moved   -> min sphere clearance", best_a)
