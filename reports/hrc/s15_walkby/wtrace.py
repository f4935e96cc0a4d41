"""Walk-by halt tracer (issue 13, false stops): one hard:200 scenario through hrc's own per-scenario path
(hrc._run_one, CAN, lifter, 30 Hz, labelled calibration, max 2.0 m/s, shipped box), with an observe-only
wrapper on HazardMonitor.observe that records, per pose frame and per person, what the whole-body rule used
(lifted separation d = min(now, predict_s ahead), the lifted separation now, head ground speed, approach
component, the coming / reach clauses) against the truth (scene_joints at the frame's time: separation of the
true body from the same arm capsules, the true head ground velocity and approach), plus the monitor's state,
reason and the unlifted / lost / ray-bound lists.
--fix NAME replaces the coming clause with a candidate (see CANDIDATES); default: the shipped rule, unchanged.
usage: wtrace.py SEED NAME OUT.json [--fix NAME]    (development seeds only)"""
import math

import numpy as np
from tracebase import run, setup

from edge_runtime.core.skeleton import HEAD
from edge_runtime.robot import hazard
from edge_runtime.robot.hazard import arm_capsules, body_spheres, ground, separation_per_shift_m

su = setup("--fix", "a candidates.py name")
a, dt, n_pre, J = su.args, su.dt, su.n_pre, su.truth
FR = []
HM = hazard.HazardMonitor


def truth(w, t):
    k = int(round(t / dt))
    if not (0 <= k < J.shape[1]) or not np.isfinite(J[w, k, 0, 0]):
        return None
    k0, k1 = max(k - 5, 0), min(k + 5, J.shape[1] - 1)
    if not (np.isfinite(J[w, k0, 0, 0]) and np.isfinite(J[w, k1, 0, 0])):
        k0 = k1 = k
    v = (J[w, k1, HEAD] - J[w, k0, HEAD]) / max((k1 - k0) * dt, 1e-9)
    return J[w, k], v


def per_person(self, t_s, people, ests, effector_m, arm_q_rad):
    z = self.zones
    caps = arm_capsules(arm_q_rad) if arm_q_rad is not None else hazard.effector_capsule(effector_m)
    eff_g = ground(effector_m)
    t = round(t_s - n_pre * dt, 3)
    out = {}
    for wid, est in ests.items():
        centres, radii = body_spheres(people[wid])
        v_g = ground(est.velocity_mps)
        toward = eff_g - ground(est.position_m)
        approach = float(v_g @ toward) / max(float(np.linalg.norm(toward)), 1e-9)
        v3 = np.array([est.velocity_mps[0], 0.0, est.velocity_mps[2]])
        per = separation_per_shift_m(centres, radii, v3, (0.0, z.predict_s), caps)
        d, d_now = float(per.min()), float(per[0])
        rec = {"d": round(d, 3), "d_now": round(d_now, 3), "speed": round(float(np.linalg.norm(v_g)), 2),
               "approach": round(approach, 2), "lim": round(z.body_retract_distance_m + approach * z.retract_lead_s, 3),
               "coming": bool(approach > z.approach_speed_mps and d <= z.body_retract_distance_m
                              + approach * z.retract_lead_s), "reach": bool(d <= z.reach_retract_m),
               "head": np.round(est.position_m, 2).tolist()}
        tr = truth(wid, t) if isinstance(wid, (int, np.integer)) and wid < J.shape[0] else None
        if tr is not None:
            body, v = tr
            tg = eff_g - ground(body[HEAD])
            vg = ground(v)
            c2, r2 = body_spheres(body)
            pt = separation_per_shift_m(c2, r2, np.array([v[0], 0.0, v[2]]), (0.0, z.predict_s), caps)
            rec.update({"true_d_now": round(float(pt[0]), 3), "true_d": round(float(pt.min()), 3),
                        "true_speed": round(float(np.linalg.norm(vg)), 2),
                        "true_approach": round(float(vg @ tg) / max(float(np.linalg.norm(tg)), 1e-9), 2),
                        "true_head": np.round(body[HEAD], 2).tolist()})
        out[int(wid)] = rec
    return t, out


orig_observe = HM.observe


def observe(self, t_s, people, effector_m, arm_q_rad=None, unseen=None, rays=None):
    dec = orig_observe(self, t_s, people, effector_m, arm_q_rad, unseen, rays)
    if self.zones.separation == "head":
        return dec
    t, per = per_person(self, t_s, {w: np.asarray(p, float) for w, p in people.items()}, self.estimates,
                        effector_m, arm_q_rad)
    FR.append({"t": t, "state": self.state.name, "reason": self.reason, "coming_any": self._coming,
               "unseen": {int(k): str(v) for k, v in (unseen or {}).items()},
               "lost_stop": [int(x) for x in self._lost_stop], "unlifted_stop": [int(x) for x in self._unlifted_stop],
               "bounded": {int(k): round(float(v[1]), 3) for k, v in self._bounded.items()},
               "dist": None if not math.isfinite(dec.distance_m) else round(dec.distance_m, 3),
               "worker": None if dec.worker is None else int(dec.worker), "people": per})
    return dec


HM.observe = observe

if a.fix:
    import candidates
    candidates.apply(a.fix)

run(su, {"fix": a.fix}, FR)
