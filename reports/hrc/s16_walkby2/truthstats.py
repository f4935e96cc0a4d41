"""The simulator's bodies in jtrace.py traces (every person with a truth, each frame): per joint, its height above
the floor (min / 1st pct / 99th pct / max) and its ground distance from the nearer ankle (max), the premises of
the ray bound's bands and body extent.  usage: truthstats.py OUT.json ..."""
import json
import sys

import numpy as np

from edge_runtime.core.skeleton import JOINTS, L_ANKLE, R_ANKLE

H, G = [], []
floor = None
for path in sys.argv[1:]:
    for f in json.load(open(path))["frames"]:
        for grp in ("lifted", "unlifted"):
            for p in f[grp].values():
                if "floor_y" in p:
                    floor = p["floor_y"]
                if "true_joints" in p:
                    tj = np.array(p["true_joints"])
                    H.append(tj[:, 1])
                    g = tj[:, [0, 2]]
                    G.append(np.minimum(np.linalg.norm(g - g[L_ANKLE], axis=1), np.linalg.norm(g - g[R_ANKLE], axis=1)))
H, G = np.array(H) - floor, np.array(G)
print(f"floor y {floor}, body-frames {len(H)}")
for j, n in enumerate(JOINTS):
    print(f"{n:15s} height min {H[:, j].min():.2f} p1 {np.percentile(H[:, j], 1):.2f} p99 {np.percentile(H[:, j], 99):.2f} "
          f"max {H[:, j].max():.2f} | ground from nearer ankle max {G[:, j].max():.2f} p99 {np.percentile(G[:, j], 99):.2f}")
