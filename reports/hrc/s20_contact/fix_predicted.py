"""Candidate: the escape turn is planned against everyone where he is now AND where his head's velocity takes
him SHIFTS_S ahead (his whole body moved with it, as the monitor's separation predicts), each a separate
'person' for plan_escape_turn (the turn is scored and its sweep bounded against every copy)."""
import os

import numpy as np

from edge_runtime.robot import hazard

SHIFTS_S = tuple(float(s) for s in os.environ.get("ESCAPE_SHIFTS", "0.5,1.0").split(","))
orig = hazard.HazardMonitor.escape_people


def escape_people(self, sweep_m):
    out = orig(self, sweep_m)
    if not out:
        return out
    extra = []
    for wid, seen in self._seen.items():
        est = self.estimates.get(wid)
        if est is None or abs(seen.t_s - self._last_pose_s) > 1e-9:
            continue
        v = np.array([est.velocity_mps[0], 0.0, est.velocity_mps[2]])
        if not np.isfinite(v).all() or float(v @ v) < 0.04:
            continue
        centres, radii = seen.spheres
        for s in SHIFTS_S:
            extra.append((centres + s * v, radii))
    return out + extra


def apply(EV, **_):
    hazard.HazardMonitor.escape_people = escape_people
