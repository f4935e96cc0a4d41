"""How long the ray bound's region is (ground distance from the camera, m) in the frames where it is low (<= reach_retract_m)
while the truth is far (> 1.3 m), against where the person truly is; and the camera's height.  usage: raywidth.py OUT.json ..."""
import json
import sys

import numpy as np
from raycand import explained

from edge_runtime.robot import hazard

why = explained()
Z = hazard.ZoneParams()
W, A, CH, TG = [], [], [], []
for path in sys.argv[1:]:
    for f in json.load(open(path))["frames"]:
        caps = tuple(np.array(c) for c in f["caps"])
        for u in f["unlifted"].values():
            if "dirs" not in u or "true_d_now" not in u or u["bound"] is None or not (u["bound"] <= 0.85 and u["true_d_now"] > 1.3):
                continue
            o = np.array(u["origin"])
            out = why(hazard.PersonRays(o, np.array(u["dirs"], float), u["floor_y"]), caps, Z)
            L = out[2]
            W.append(L["far"] - L["near"])
            feet = [r for r in L["regions"] if set(r[2]) & {3, 6}]
            A.append(feet[0][1] - feet[0][0] - 2 * (feet[0][3] + hazard.RAY_KEYPOINT_ERROR_M) if feet else np.nan)
            CH.append(o[1] - u["floor_y"])
            TG.append(np.hypot(*(np.array(u["true_joints"])[[3, 6]][:, [0, 2]] - o[[0, 2]]).T).mean())
W, A, CH, TG = map(np.array, (W, A, CH, TG))
print(f"low frames {len(W)}: region length median {np.median(W):.2f} m (p10 {np.percentile(W, 10):.2f}, p90 {np.percentile(W, 90):.2f}); "
      f"the feet's own ray range (before extent and e) median {np.nanmedian(A):.2f} m, without a foot anchor {np.isnan(A).sum()}; "
      f"camera height {np.median(CH):.2f} m (min {CH.min():.2f}, max {CH.max():.2f}); true feet from the camera median {np.median(TG):.2f} m")
