"""Per-frame noise of each scale measure: log(observed angular size) - log(the same from noise-free rays to the true
joints), over every lifted frame of the traces; and the measure's size (rad).  With the least-squares slope over
n frames spanning T s its noise is about sd * sqrt(12 / n) / T per second, times the range R for the depth rate.
usage: noise.py OUT.json ..."""
import json
import sys

import numpy as np
from loom import scales, unit

acc = {}
for path in sys.argv[1:]:
    for f in json.load(open(path))["frames"]:
        if "cam" not in f:
            continue
        cam3 = np.array(f["cam"])
        for p in f["lifted"].values():
            if "rays" not in p or "true_joints" not in p:
                continue
            R = np.array(p["rays"], float)
            Rc = np.array([unit(np.array(j) - cam3) for j in p["true_joints"]])
            so, sc = scales(R), scales(Rc)
            for k in so:
                if np.isfinite(so[k]) and np.isfinite(sc[k]):
                    acc.setdefault(k, []).append((so[k] - sc[k], np.exp(sc[k])))
print("| measure | frames | sd of log error | median abs log error | median size (rad) |")
print("|---|---:|---:|---:|---:|")
for k, v in acc.items():
    e, a = np.array(v).T
    print(f"| {k} | {len(e)} | {e.std():.3f} | {np.median(abs(e - np.median(e))):.3f} | {np.median(a):.3f} |")
