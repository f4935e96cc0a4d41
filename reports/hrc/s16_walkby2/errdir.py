"""Where the lifted head velocity's error points: along the camera's line of sight (depth, from the floor
anchoring) or across it (bearing, from the keypoints). Per trace: RMS of the (tracker - true) ground velocity
error along / across the camera->head ground direction over all lifted frames with a full true window, and the
same at the frames where the shipped coming clause fires and the true one does not.  Camera centre: the rays'
origin of any unlifted person in the trace (fixed camera).  usage: errdir.py OUT.json ..."""
import sys

import numpy as np
from velstudy import TP, fit, study

from edge_runtime.robot.hazard import ground

for path in sys.argv[1:]:
    X, rows = study(path)
    cam = next((ground(np.array(u["origin"])) for f in X["frames"] for u in f["unlifted"].values() if "origin" in u), None)
    if cam is None:
        print(path.split("/")[-1], "no camera origin")
        continue
    F = {f["t"]: f for f in X["frames"]}
    allv, fire = [], []
    for r in rows:
        if "a_true" not in r:
            continue
        f = F[r["t"]]
        p = f["lifted"][r["w"]]
        pos = ground(np.array(p["pos"]))
        los = (pos - cam) / np.linalg.norm(pos - cam)
        perp = np.array([-los[1], los[0]])
        # the true velocity: LS over the same frames' true heads (velstudy's a_true is its projection only)
        ts, xs = [], []
        for f2 in X["frames"]:
            if r["t"] - TP.window_s - 1e-9 <= f2["t"] <= r["t"] and r["w"] in f2["lifted"] and "true_joints" in f2["lifted"][r["w"]]:
                ts.append(f2["t"])
                xs.append(ground(np.array(f2["lifted"][r["w"]]["true_joints"][10])))
        if len(ts) < 3:
            continue
        tv, _ = fit(np.array(ts), np.array(xs))
        e = ground(np.array(p["vel"])) - tv
        allv.append((e @ los, e @ perp))
        if r["ship"] and not r.get("true"):
            fire.append((e @ los, e @ perp))
    a, b = np.array(allv), np.array(fire) if fire else np.zeros((0, 2))
    rms = lambda m: np.sqrt((m ** 2).mean(axis=0)).round(2).tolist() if len(m) else None  # noqa: E731
    print(f"{path.split('/')[-1]}: all lifted frames n {len(a)} RMS err along / across line of sight {rms(a)}; "
          f"shipped-only coming frames n {len(b)} {rms(b)}")
