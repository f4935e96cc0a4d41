"""Per-stage p50 / mean (ms) of prof_cycle JSON files, base vs this branch, median over rounds; with each
stage's share of an untouched reference (monitor + people_log + act: other helpers' stages, unchanged here),
which corrects for the machine's load drifting between runs.

    python reports/bench/s18_perfB/table.py '/tmp/perfB/t2-base18-*.json' '/tmp/perfB/t2-perfB-*.json'
"""
import glob
import json
import sys

import numpy as np

STAGES = ["tracker", "lifter", "calibration", "monitor", "people_log", "act"]
REF = ["monitor", "people_log", "act"]


def stats(path):
    d = json.load(open(path))
    fr = [f for f in d["frames"] if not f["escape_planned"]]
    out = {"digest": d["digest"][:8] + ".." + d["digest"][-4:], "payload": d["payload_digest"][:8]}
    cpu = [f["cpu"] for f in d["frames"]]
    out["frame"] = (np.percentile(cpu, 50) * 1e3, np.mean(cpu) * 1e3, np.percentile(cpu, 99) * 1e3)
    for s in STAGES:
        v = [f.get(s, 0.0) for f in fr]
        out[s] = (np.percentile(v, 50) * 1e3, np.mean(v) * 1e3)
    ref = sum(out[s][1] for s in REF)
    out["rel"] = {s: out[s][1] / ref for s in STAGES[:3]}
    return out


def main():
    rows = {}
    for label, pattern in zip(("base", "perfB"), sys.argv[1:3]):
        runs = [stats(p) for p in sorted(glob.glob(pattern))]
        rows[label] = runs
        print(f"{label}: {len(runs)} runs, digests {sorted({r['digest'] for r in runs})}, "
              f"payload {sorted({r['payload'] for r in runs})}")
    print(f"{'stage':12s} {'base p50':>9s} {'perfB p50':>9s} {'base mean':>9s} {'perfB mean':>10s} "
          f"{'base/ref':>8s} {'perfB/ref':>9s}")
    for s in STAGES:
        b = rows["base"]
        n = rows["perfB"]
        def med(runs, k, s=s):
            return float(np.median([r[s][k] for r in runs]))

        line = f"{s:12s} {med(b, 0):9.3f} {med(n, 0):9.3f} {med(b, 1):9.3f} {med(n, 1):10.3f}"
        if s in STAGES[:3]:
            line += (f" {np.median([r['rel'][s] for r in b]):8.3f} {np.median([r['rel'][s] for r in n]):9.3f}")
        print(line)
    for k, name in enumerate(("p50", "mean", "p99")):
        print(f"frame {name:5s} {np.median([r['frame'][k] for r in rows['base']]):9.3f} "
              f"{np.median([r['frame'][k] for r in rows['perfB']]):9.3f}")


if __name__ == "__main__":
    main()
