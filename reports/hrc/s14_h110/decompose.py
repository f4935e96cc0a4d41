"""Decompose worker 2's sphere clearance during the 5.84 s escape turn: actual arm vs (a) the arm turned by j0 ALONE
(the planner's model) through the same j0 angles, (b) the worker frozen at 5.84 s (his own reach excluded),
(c) the arm frozen at 5.80 s; and the frozen arm's minimum over the rest of the scenario."""
import json

import numpy as np

from firmware_sim.robot.sawyer import collision_spheres
from firmware_sim.scenarios import hrc
from firmware_sim.scenarios.hrc_world import scene_joints

d = json.load(open("base.json"))
sc = next(s for s in hrc.scenarios_for("hard:200", 15, 2.0) if s.name == "hard_110")
J = scene_joints(sc, 100)
steps = {s["t"]: s for s in d["steps"]}
q0 = np.array(steps[5.8]["q"])


def clear(body, q):
    c, r = collision_spheres(q)
    return float((np.linalg.norm(body[:, None] - c[None], axis=-1) - r[None]).min())


print(" t     actual  j0-only  worker@5.84  arm@5.80")
for t in sorted(steps):
    if not (5.84 <= t <= 6.6) or round(t * 100) % 4:
        continue
    k = int(round(t * 100))
    q = np.array(steps[t]["q"])
    qj0 = q0.copy()
    qj0[0] = q[0]
    print(f"{t:5.2f}  {clear(J[2, k], q):+.3f}  {clear(J[2, k], qj0):+.3f}   {clear(J[2, 584], q):+.3f}      "
          f"{clear(J[2, k], q0):+.3f}")
fro = [(clear(J[2, k], q0), k / 100) for k in range(584, J.shape[1]) if np.isfinite(J[2, k, 0, 0])]
print("arm frozen at 5.80 for the rest of the scenario: min", min(fro))
