"""Offline study of approach-velocity estimators on jtrace.py traces (shipped runs): per lifted frame, the shipped
coming clause (head tracker velocity) against the same clause with a candidate velocity (its approach, and the
separation predicted with it), and against the truth (true body, true head velocity over the same window).
Estimators (all over the head tracker's own window and resets, hazard.HeadTracker replayed):
  head   : the shipped head fit (check: equals the monitor's)
  med    : per-component median of the ground velocities of the least-squares fits of JOINTS (pelvis, hips,
           ankles, head, shoulders)
  medlcb : med's approach less K standard errors (median of the joints' fit standard errors of the approach)
  headlcb: the head's approach less K of its own fit standard error
  losS   : the head's approach less S times the share of it along the camera's line of sight (|u . los|): the
           lifted depth's velocity error (errdir.py) taken as S m/s, the bearing's as exact
usage: velstudy.py OUT.json ...   (prints per-trace counts; walk-by = nobody came within protective)"""
import json
import sys

import numpy as np
from candidates2 import _fit as fit

from edge_runtime.robot import hazard
from edge_runtime.robot.hazard import body_spheres, ground, separation_per_shift_m

JOINTS = (0, 1, 4, 3, 6, 10, 11, 14)
Z = hazard.ZoneParams()
TP = hazard.TrackerParams()
K = 2.0
LOS_S = (0.3, 0.5)


def clause(a, d):
    return a > Z.approach_speed_mps and d <= Z.body_retract_distance_m + a * Z.retract_lead_s


def sep(joints, v_g, caps):
    c, r = body_spheres(np.asarray(joints))
    v3 = np.array([v_g[0], 0.0, v_g[1]])
    return float(separation_per_shift_m(c, r, v3, (0.0, Z.predict_s), caps).min())


def study(path):
    X = json.load(open(path))
    F = X["frames"]
    trk, hist = {}, {}
    cam = next((ground(np.array(u["origin"])) for f in F for u in f["unlifted"].values() if "origin" in u), None)
    rows = []
    for f in F:
        caps = tuple(np.array(c) for c in f["caps"])
        eff_g = ground(np.array(f["eff"]))
        for w, p in f["lifted"].items():
            jts = np.array(p["joints"])
            tr = trk.setdefault(w, hazard.HeadTracker(TP, Z.predict_s))
            tr.update(f["t"], jts[10])
            h = hist.setdefault(w, [])
            h.append((f["t"], jts, np.array(p["true_joints"]) if "true_joints" in p else None))
            t0 = tr._t[0]
            h[:] = [x for x in h if x[0] >= t0 - 1e-9]
            pos_g = ground(np.array(p["pos"]))
            toward = eff_g - pos_g
            u = toward / max(np.linalg.norm(toward), 1e-9)
            v_head = ground(np.array(p["vel"]))
            r = {"t": f["t"], "w": w, "state": f["state"], "d": p["d"], "d_now": p["d_now"],
                 "a_head": float(v_head @ u), "ship": clause(float(v_head @ u), p["d"]), "reach": p["d"] <= Z.reach_retract_m}
            if len(h) >= TP.min_samples:
                ts = np.array([x[0] for x in h])
                xs = np.stack([ground(x[1][list(JOINTS)]) for x in h])  # (n, J, 2)
                v, se = fit(ts, xs)                                      # (J, 2)
                a_j = v @ u
                se_a = np.sqrt((se ** 2) @ (u ** 2))
                v_med = np.median(v, axis=0)
                sp = np.linalg.norm(v_med)
                if sp > TP.max_speed_mps:
                    v_med = v_med * TP.max_speed_mps / sp
                a_med = float(v_med @ u)
                d_med = sep(jts, v_med, caps)
                hi = list(JOINTS).index(10)
                r.update({"a_med": a_med, "d_med": d_med, "se_med": float(np.median(se_a)), "se_head": float(se_a[hi]),
                          "a_j": a_j.round(2).tolist()})
                r["med"] = clause(a_med, d_med)
                r["medlcb"] = clause(a_med - K * r["se_med"], d_med)
                r["headlcb"] = clause(r["a_head"] - K * r["se_head"], p["d"])
                if cam is not None:
                    los = (pos_g - cam) / max(np.linalg.norm(pos_g - cam), 1e-9)
                    for S in LOS_S:
                        r[f"los{S}"] = clause(r["a_head"] - S * abs(float(u @ los)), p["d"])
                if all(x[2] is not None for x in h):
                    txs = np.stack([ground(x[2][10]) for x in h])
                    tv, _ = fit(ts, txs)
                    tv = tv if np.linalg.norm(tv) <= 3 else tv * 3 / np.linalg.norm(tv)
                    tpos_g = ground(h[-1][2][10])
                    tu = (eff_g - tpos_g) / max(np.linalg.norm(eff_g - tpos_g), 1e-9)
                    r["a_true"] = float(tv @ tu)
                    r["d_true"] = sep(h[-1][2], tv, caps)
                    r["true"] = clause(r["a_true"], r["d_true"])
            else:
                r.update({"med": False, "medlcb": False, "headlcb": False})
            rows.append(r)
    return X, rows


if __name__ == "__main__":
    keys = ("ship", "med", "medlcb", "headlcb", "los0.3", "los0.5", "true")
    print("trace | walkby | halts | frames coming: " + " / ".join(keys) + " | true coming frames missed (reach clause false too): " + " / ".join(keys) + " | first coming t per person: " + " / ".join(keys))
    for path in sys.argv[1:]:
        X, rows = study(path)
        s = X["summary"]
        cnt = {k: sum(bool(r.get(k)) for r in rows) for k in keys}
        miss = {k: sum(bool(r.get("true")) and not r.get(k) and not r["reach"] for r in rows) for k in keys}
        first = {}
        for k in keys:
            for r in rows:
                if r.get(k):
                    first.setdefault(k, {}).setdefault(r["w"], r["t"])
        fs = " / ".join(str(first.get(k, {})) for k in keys)
        print(f"{path.split('/')[-1]} | {not s['came_within_protective']} | {s['halts']} {s['halt_reasons']} | "
              + " / ".join(str(cnt[k]) for k in keys) + " | " + " / ".join(str(miss[k]) for k in keys) + " | " + fs)
