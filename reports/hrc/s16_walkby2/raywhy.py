"""Which term of hazard.ray_separation_m binds (one trace, frames with a low bound and a far truth): per frame the
anchor regions (ground distance from the camera: near..far, members, extent), the person's true ground distance
from the camera (his nearer ankle), and per joint the bound's term (its ray span's clearance, the bone-chain term,
the column term) with the joint that sets d.  usage: raywhy.py OUT.json [MAXFRAMES]"""
import json
import sys

import numpy as np
from raycand import explained

from edge_runtime.core.skeleton import JOINTS
from edge_runtime.robot import hazard

why = explained()
Z = hazard.ZoneParams()
X = json.load(open(sys.argv[1]))
left = int(sys.argv[2]) if len(sys.argv) > 2 else 5
for f in X["frames"]:
    caps = tuple(np.array(c) for c in f["caps"])
    for w, u in f["unlifted"].items():
        if "dirs" not in u or "true_d_now" not in u or u["bound"] is None or not (u["bound"] <= 0.85 and u["true_d_now"] > 1.3):
            continue
        if left <= 0:
            sys.exit()
        left -= 1
        o = np.array(u["origin"])
        rays = hazard.PersonRays(o, np.array(u["dirs"], float), u["floor_y"])
        d, stands, L = why(rays, caps, Z)
        tj = np.array(u["true_joints"])
        gd = np.hypot(*(tj[:, [0, 2]] - o[[0, 2]]).T)
        print(f"t {f['t']} w{w} bound {d:.3f} true {u['true_d_now']:.3f}; camera h {o[1] - u['floor_y']:.2f} m, "
              f"true ground dist from camera: ankles {gd[3]:.2f}/{gd[6]:.2f} head {gd[10]:.2f}")
        print("   regions:", [(round(a, 2), round(b, 2), [JOINTS[j] for j in m], e) for a, b, m, e in L["regions"]],
              "near/far", round(L["near"], 2), round(L["far"], 2), "column", round(L["column"], 3))
        joint, clear = L["joint"], L["clear"]
        per_joint = joint - hazard.BODY_RADII_M
        per_limb = L["limb"] - 0.5 * (hazard.BODY_RADII_M[L["a_"]] + hazard.BODY_RADII_M[L["b_"]])
        k = int(np.argmin(per_joint))
        li = int(np.argmin(per_limb))
        chain = (clear[None, :] - hazard.JOINT_REACH_M).max(axis=1)
        setter = (f"joint {JOINTS[k]} {per_joint[k]:.3f}" if per_joint[k] <= per_limb[li] else
                  f"limb {JOINTS[L['a_'][li]]}-{JOINTS[L['b_'][li]]} {per_limb[li]:.3f}")
        print(f"   sets d: {setter}; {JOINTS[k]}: chain {chain[k]:.3f} from "
              f"{JOINTS[int(np.argmax(clear - hazard.JOINT_REACH_M[k]))]}, column {L['column']:.3f}; "
              "seen joints' ray clearance:", {JOINTS[j]: round(float(clear[j]), 2) for j in L["joints"]})
