"""Looming (issue 13): a line-of-sight depth rate from the person's IMAGE SCALE and its rate of change, against
the lifted head's, on loomtrace.py traces (every lifted person's keypoint rays recorded).
Scale measures (angles between the rays of two image points, in rad; angle ~ real length / range R), each only
from the keypoints seen in that frame (a NaN ray is unseen):
  torso : shoulder-mid (11, 14) to hip-mid (1, 4)      leg   : hip-mid to ankle-mid (3, 6)
  height: head (10) to ankle-mid                       med   : per frame window, the median of the log-scale slopes
          of the seen segments thighs, shins, hips width, shoulders width, pelvis-thorax, both upper arms
Per frame and measure: slope of log(scale) by least squares over the head tracker's own window (hazard.HeadTracker
replayed, as velstudy.py), at least TP.min_samples seen frames; R the range camera -> pelvis (lifted, or true for
comparison), g its ground distance; ground line-of-sight rate v_los = dR/dt * R / g = -slope * R^2 / g.
Truth: the true head's least-squares ground velocity over the same frames, along the line of sight (camera -> lifted
head, ground plane, as errdir.py).  The looming velocity: line-of-sight part from looming, across part from the
lifted head's tracker velocity; the coming clause (velstudy.clause / velstudy.sep) evaluated with it.
LOOM_WINDOW_S=1.5 (diagnostic): every fit over the last 1.5 s instead of the tracker's window.
usage: loom.py OUT.json ...   (prints the tables; --rows FILE.json also dumps the per-frame rows)"""
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "s16_walkby2"))
from velstudy import TP, Z, clause, sep
from velstudy import fit as lsq

from edge_runtime.robot import hazard
from edge_runtime.robot.hazard import ground

SEGS = ((1, 2), (2, 3), (4, 5), (5, 6), (1, 4), (11, 14), (0, 8), (11, 12), (14, 15))
MEASURES = ("torso", "leg", "height", "med")
WINDOW_S = float(os.environ.get("LOOM_WINDOW_S", "0"))


def unit(v):
    n = np.linalg.norm(v)
    return v / n if n > 1e-12 else v * np.nan


def mid(R, idx):
    return unit(np.mean(R[list(idx)], axis=0))


def ang(a, b):
    return float(np.arccos(np.clip(a @ b, -1.0, 1.0)))


def scales(R):
    """log angular sizes of one frame's (17, 3) unit rays: dict name -> log(rad) (NaN where a joint is unseen)."""
    hip, sh, ank = mid(R, (1, 4)), mid(R, (11, 14)), mid(R, (3, 6))
    out = {"torso": ang(sh, hip), "leg": ang(hip, ank), "height": ang(R[10], ank)}
    for i, j in SEGS:
        out[f"s{i}_{j}"] = ang(R[i], R[j])
    return {k: (np.log(v) if np.isfinite(v) and v > 1e-6 else np.nan) for k, v in out.items()}


def slope(ts, ys):
    ok = np.isfinite(ys)
    if ok.sum() < TP.min_samples:
        return np.nan
    t, y = ts[ok], ys[ok]
    return float(np.polyfit(t - t.mean(), y, 1)[0]) if np.ptp(t) > 0 else np.nan


def study(path):
    X = json.load(open(path))
    s = X["summary"]
    walkby = not s["came_within_protective"]
    trk, hist, rows = {}, {}, []
    stand = {}
    for f in X["frames"]:
        for w, p in f["lifted"].items():
            if "true_joints" in p:
                stand[w] = max(stand.get(w, 0.0), p["true_joints"][10][1])
    prev_state = "NORMAL"
    for f in X["frames"]:
        halt_first = prev_state == "NORMAL" and f["state"] not in ("NORMAL", "FAULT") and f["coming_any"]
        prev_state = f["state"]
        if "cam" not in f:
            continue
        cam3 = np.array(f["cam"])
        cam = ground(cam3)
        eff_g = ground(np.array(f["eff"]))
        caps = tuple(np.array(c) for c in f["caps"])
        for w, p in f["lifted"].items():
            jts = np.array(p["joints"])
            tr = trk.setdefault(w, hazard.HeadTracker(TP, Z.predict_s))
            tr.update(f["t"], jts[10])
            R = np.array(p["rays"], float) if "rays" in p else np.full((17, 3), np.nan)
            tj = np.array(p["true_joints"]) if "true_joints" in p else None
            h = hist.setdefault(w, [])
            # the same measures from noise-free rays to the true joints (seen where the observed keypoint is):
            # separates the method's own error (posture, foreshortening) from keypoint noise
            Rc = np.array([unit(j - cam3) for j in tj]) if tj is not None else R * np.nan
            Rc[~np.isfinite(R[:, 0])] = np.nan
            h.append((f["t"], scales(R), tj, scales(Rc)))
            # LOOM_WINDOW_S (diagnostic only): a longer window than the tracker's, the truth over the same one
            h[:] = [x for x in h if x[0] >= (f["t"] - WINDOW_S if WINDOW_S else tr._t[0]) - 1e-9]
            if tj is None or len(h) < TP.min_samples or any(x[2] is None for x in h):
                continue
            ts = np.array([x[0] for x in h])
            sl = {m: slope(ts, np.array([x[1][m] for x in h])) for m in ("torso", "leg", "height")}
            seg = [slope(ts, np.array([x[1][f"s{i}_{j}"] for x in h])) for i, j in SEGS]
            seg = [v for v in seg if np.isfinite(v)]
            sl["med"] = float(np.median(seg)) if len(seg) >= 3 else np.nan
            slc = {m: slope(ts, np.array([x[3][m] for x in h])) for m in ("torso", "leg", "height")}
            pos_g = ground(np.array(p["pos"]))
            los = unit(pos_g - cam)
            perp = np.array([-los[1], los[0]])
            tv, _ = lsq(ts, np.stack([ground(x[2][10]) for x in h]))
            v_head = ground(np.array(p["vel"]))
            u = unit(eff_g - pos_g)
            tpos_g = ground(tj[10])
            tu = unit(eff_g - tpos_g)
            tvc = tv if np.linalg.norm(tv) <= 3 else tv * 3 / np.linalg.norm(tv)
            a_true = float(tvc @ tu)
            d_true = sep(tj, tvc, caps)
            r = {"path": path.split("/")[-1], "walkby": walkby, "t": f["t"], "w": w, "halt_first": halt_first and f["worker"] == int(w),
                 "los_true": float(tv @ los), "los_head": float(v_head @ los), "dist": float(np.linalg.norm(tpos_g - cam)),
                 "ship": clause(float(v_head @ u), p["d"]), "true": clause(a_true, d_true), "reach": p["d"] <= Z.reach_retract_m,
                 "a_true": a_true, "a_head": float(v_head @ u),
                 "seen": int(np.isfinite(R[:, 0]).sum()),
                 "bend": tj[10][1] < stand[w] - 0.25,
                 "reach_pose": max(np.linalg.norm(ground(tj[13]) - ground(tj[0])), np.linalg.norm(ground(tj[16]) - ground(tj[0]))) > 0.45}
            # turning: the true shoulder line's yaw rate over the window
            yaw = np.unwrap([np.arctan2(*(ground(x[2][11]) - ground(x[2][14]))[::-1]) for x in h])
            r["turn"] = abs(np.polyfit(ts - ts.mean(), yaw, 1)[0]) > 1.5
            for zname, pel in (("lift", jts[0]), ("truez", tj[0])):
                Rng = float(np.linalg.norm(pel - cam3))
                g = max(float(np.linalg.norm(ground(pel) - cam)), 0.3)
                for m in MEASURES:
                    r[f"los_{m}_{zname}"] = -sl[m] * Rng * Rng / g
            for m in ("torso", "leg", "height"):
                r[f"los_{m}_clean"] = -slc[m] * Rng * Rng / g      # true range (the last zname), clean rays
            for m in MEASURES:
                vl = r[f"los_{m}_lift"]
                if not np.isfinite(vl):
                    r[f"c_{m}"] = None
                    continue
                v = vl * los + float(v_head @ perp) * perp
                sp = np.linalg.norm(v)
                v = v if sp <= TP.max_speed_mps else v * TP.max_speed_mps / sp
                r[f"c_{m}"] = clause(float(v @ u), sep(jts, v, caps))
            rows.append(r)
    return X, rows


def stats(e):
    e = np.asarray([x for x in e if np.isfinite(x)])
    if not len(e):
        return "-"
    return f"{np.sqrt((e ** 2).mean()):.2f} / {np.percentile(abs(e), 95):.2f} (n {len(e)})"


if __name__ == "__main__":
    args = [a for a in sys.argv[1:] if not a.startswith("--")]
    dump = sys.argv[sys.argv.index("--rows") + 1] if "--rows" in sys.argv else None
    args = [a for a in args if a != dump]
    rows = []
    for path in args:
        rows += study(path)[1]
    if dump:
        json.dump(rows, open(dump, "w"), default=float)
    cols = (["los_head"] + [f"los_{m}_{z}" for m in MEASURES for z in ("lift", "truez")]
            + [f"los_{m}_clean" for m in ("torso", "leg", "height")])
    splits = {
        "all": lambda r: True, "walk-by traces": lambda r: r["walkby"], "approach traces": lambda r: not r["walkby"],
        "dist < 3 m": lambda r: r["dist"] < 3, "dist 3-5 m": lambda r: 3 <= r["dist"] < 5, "dist >= 5 m": lambda r: r["dist"] >= 5,
        "bending (head >0.25 m below standing)": lambda r: r["bend"], "turning (>1.5 rad/s)": lambda r: r["turn"],
        "reaching (wrist >0.45 m from pelvis)": lambda r: r["reach_pose"], "all 17 keypoints seen": lambda r: r["seen"] == 17,
        "<= 14 keypoints seen": lambda r: r["seen"] <= 14,
        "shipped coming, true not": lambda r: r["ship"] and not r["true"],
    }
    print("## line-of-sight ground rate error (estimate - true), m/s: RMS / p95 |err| (n frames with the estimate)\n")
    print("| frames | " + " | ".join(cols) + " |")
    print("|---" * (len(cols) + 1) + "|")
    for name, fn in splits.items():
        sel = [r for r in rows if fn(r)]
        print(f"| {name} (n {len(sel)}) | " + " | ".join(stats([r[c] - r["los_true"] for r in sel]) for c in cols) + " |")
    print("\n## coming clause per trace: frames coming (ship / true / looming measures), walk-by halts' first frames "
          "(does each fire there), first coming time per person\n")
    keys = ["ship", "true"] + [f"c_{m}" for m in MEASURES]
    print("| trace | walk-by | frames coming " + "/".join(keys) + " | true coming missed (reach false) " + "/".join(keys[2:])
          + " | halt-first frames: fires " + "/".join(keys) + " | first coming t per person " + " / ".join(keys) + " |")
    print("|---" * 6 + "|")
    tot = {}
    for path in args:
        pr = [r for r in rows if r["path"] == path.split("/")[-1]]
        cnt = [sum(bool(r.get(k)) for r in pr) for k in keys]
        miss = [sum(bool(r["true"]) and not r.get(k) and not r["reach"] for r in pr) for k in keys[2:]]
        hf = [r for r in pr if r["halt_first"]]
        hfc = [sum(bool(r.get(k)) for r in hf) for k in keys]
        first = {k: {} for k in keys}
        for r in pr:
            for k in keys:
                if r.get(k):
                    first[k].setdefault(r["w"], r["t"])
        wb = pr[0]["walkby"] if pr else None
        for k, v in zip(("cnt", "miss", "hf", "nhf"), (cnt, miss, hfc, [len(hf)])):
            tot.setdefault((wb, k), np.zeros(len(v), int))
            tot[(wb, k)] += np.array(v)
        print(f"| {path.split('/')[-1]} | {wb} | {cnt} | {miss} | {len(hf)}: {hfc} | " + " / ".join(str(first[k]) for k in keys) + " |")
    for (wb, k), v in sorted(tot.items(), key=str):
        print(f"total walkby={wb} {k}: {v.tolist()}")
