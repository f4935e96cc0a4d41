"""Physically impossible motion in the lifted heads (jtrace.py traces): per lifted person and pair of consecutive pose
frames (<= 0.1 s apart), ground steps faster than 3 m/s and tracker-velocity changes above 10 m/s^2; overall and
within the 0.5 s before each frame where the shipped coming clause fires and the true one does not (velstudy.py).
usage: jumps.py OUT.json ..."""
import sys

import numpy as np
from velstudy import study

from edge_runtime.robot.hazard import ground

for path in sys.argv[1:]:
    import json
    X = json.load(open(path))
    _, rows = study(path)
    false_t = {(r["w"], r["t"]) for r in rows if r["ship"] and not r.get("true", True)}
    prev = {}
    n = fast = acc = 0
    bad_t = []
    for f in X["frames"]:
        for w, p in f["lifted"].items():
            h, v = ground(np.array(p["joints"][10])), ground(np.array(p["vel"]))
            if w in prev and 0 < f["t"] - prev[w][0] <= 0.1:
                dt = f["t"] - prev[w][0]
                n += 1
                s = np.linalg.norm(h - prev[w][1]) / dt
                a = np.linalg.norm(v - prev[w][2]) / dt
                fast += s > 3.0
                acc += a > 10.0
                if s > 3.0 or a > 10.0:
                    bad_t.append((w, f["t"]))
            prev[w] = (f["t"], h, v)
    near = sum(any(bw == w and 0 <= t - bt <= 0.5 for bw, bt in bad_t) for w, t in false_t)
    print(f"{path.split('/')[-1]}: steps {n}, > 3 m/s {fast}, velocity change > 10 m/s^2 {acc}; "
          f"false coming frames {len(false_t)}, with such a step in the 0.5 s before {near}")
