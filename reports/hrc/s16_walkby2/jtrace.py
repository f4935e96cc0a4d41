"""Joint-level trace of one hard:200 scenario (issue 13, walk-by halts), for offline study of velocity estimators
and ray bounds: s15_walkby/wtrace.py's path (hrc._run_one, CAN, lifter, 30 Hz, labelled calibration, 2.0 m/s,
shipped box) with an observe-only wrapper on HazardMonitor.observe recording per pose frame: state and reason;
per lifted person his 17 lifted joints, the head tracker's estimate and the shipped clauses' inputs; per person in
view but not lifted his keypoints' rays and the shipped ray bound; and for both the truth (scene_joints at the
frame's time: the true body; its separation from the same arm capsules).  Runtime id == worker index is assumed
(as wtrace.py).  --cand NAME applies a candidates2.py monkeypatch first (default: shipped, unchanged).
usage: jtrace.py SEED NAME OUT.json [--cand NAME]    (development seeds only)"""
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "s15_walkby"))
from tracebase import run, setup  # noqa: E402

from edge_runtime.robot import hazard  # noqa: E402
from edge_runtime.robot.hazard import arm_capsules, body_spheres, separation_m, separation_per_shift_m  # noqa: E402

su = setup("--cand", "a candidates2.py name, or ray:VARIANT (raycand.py); several joined by ','")
frames = []


def r3(x):
    return np.round(np.asarray(x, float), 3).tolist()


orig_observe = hazard.HazardMonitor.observe


def observe(self, t_s, people, effector_m, arm_q_rad=None, unseen=None, rays=None):
    dec = orig_observe(self, t_s, people, effector_m, arm_q_rad, unseen, rays)
    if self.zones.separation == "head":
        return dec
    z = self.zones
    caps = arm_capsules(arm_q_rad) if arm_q_rad is not None else hazard.effector_capsule(effector_m)
    t = round(t_s - su.n_pre * su.dt, 4)
    lifted, unl = {}, {}
    for wid, person in people.items():
        person = np.asarray(person, float)
        est = self.estimates[wid]
        c, r = body_spheres(person)
        v3 = np.array([est.velocity_mps[0], 0.0, est.velocity_mps[2]])
        per = separation_per_shift_m(c, r, v3, (0.0, z.predict_s), caps)
        rec = {"joints": r3(person), "pos": r3(est.position_m), "vel": r3(est.velocity_mps),
               "d": round(float(per.min()), 4), "d_now": round(float(per[0]), 4)}
        tb = su.body(wid, t)
        if tb is not None:
            rec["true_joints"] = r3(tb)
            rec["true_d_now"] = round(float(separation_m(*body_spheres(tb), caps)), 4)
        lifted[int(wid)] = rec
    for wid in (unseen or {}):
        ray = (rays or {}).get(wid)
        rec = {"why": str(unseen[wid])}
        if ray is not None:
            b = hazard.ray_separation_m(ray, caps, z) if z.ray_bound else None
            rec.update({"origin": r3(ray.origin_m), "dirs": np.round(ray.directions, 5).tolist(),
                        "floor_y": float(ray.floor_y_m), "bound": None if b is None else round(float(b[0]), 4)})
        tb = su.body(wid, t)
        if tb is not None:
            rec["true_joints"] = r3(tb)
            rec["true_d_now"] = round(float(separation_m(*body_spheres(tb), caps)), 4)
        unl[int(wid)] = rec
    frames.append({"t": t, "state": self.state.name, "reason": self.reason, "coming_any": bool(self._coming),
               "eff": r3(effector_m), "caps": [r3(x) for x in caps],
               "lost_stop": [int(x) for x in self._lost_stop], "unlifted_stop": [int(x) for x in self._unlifted_stop],
               "bounded": {int(k): round(float(v[1]), 4) for k, v in self._bounded.items()},
               "dist": None if not math.isfinite(dec.distance_m) else round(dec.distance_m, 4),
               "worker": None if dec.worker is None else int(dec.worker), "lifted": lifted, "unlifted": unl})
    return dec


hazard.HazardMonitor.observe = observe

if su.args.cand:
    import candidates2
    candidates2.apply_all(su.args.cand)

run(su, {"seed": su.args.seed, "cand": su.args.cand}, frames)
