"""Median over the interleaved runs of ab.sh (/tmp/perfC/ab_TAG_{base,mine}_N.json) of each stage's p50 and mean (ms), base
against this tree, per kind of frame. Usage: python ab_table.py TAG [TAG ...]"""
import glob
import json
import sys

import numpy as np

tags = sys.argv[1:]  # several: their runs pooled (ab.sh rounds with ORDER both ways cancel the order bias)
STAGES = ["tracker", "lifter", "calibration", "monitor", "separation", "people_log", "link_poll", "act", "escape",
          "plan_escape_turn", "backfires", "link_send"]
def load(side):
    return [json.load(open(f)) for tag in tags for f in sorted(glob.glob(f"/tmp/perfC/ab_{tag}_{side}_*.json"))]
runs = {s: load(s) for s in ("base", "mine")}
print({s: len(v) for s, v in runs.items()}, "digests same:",
      len({(r["digest"], r["payload_digest"]) for v in runs.values() for r in v}) == 1)
def pct(x, q): return float(np.percentile(x, q)) * 1e3 if len(x) else float("nan")
def sel(r, kind):
    fs = r["frames"]
    return {"all": fs, "ordinary": [f for f in fs if not f["escape_planned"]], "escape": [f for f in fs if f["escape_planned"]],
            "commanding": [f for f in fs if f.get("command")], "ticks": r["ticks"]}[kind]
print(f"{'kind / stage':28s} {'base p50':>9s} {'mine p50':>9s} {'d p50':>7s} | {'base mean':>9s} {'mine mean':>9s} {'d mean':>7s}")
for kind in ("all", "ordinary", "commanding", "escape", "ticks"):
    for q in (50, 99):
        b = np.median([pct([f["cpu"] for f in sel(r, kind)], q) for r in runs["base"]])
        m = np.median([pct([f["cpu"] for f in sel(r, kind)], q) for r in runs["mine"]])
        print(f"{kind + ' frame p' + str(q):28s} {b:9.3f} {m:9.3f} {m - b:+7.3f}")
    for s in STAGES:
        vb = [[f.get(s, 0.0) for f in sel(r, kind)] for r in runs["base"]]
        vm = [[f.get(s, 0.0) for f in sel(r, kind)] for r in runs["mine"]]
        if not any(any(x) for x in vb + vm):
            continue
        b50, m50 = np.median([pct(v, 50) for v in vb]), np.median([pct(v, 50) for v in vm])
        bm, mm = np.median([np.mean(v) * 1e3 for v in vb]), np.median([np.mean(v) * 1e3 for v in vm])
        print(f"   {s:25s} {b50:9.3f} {m50:9.3f} {m50 - b50:+7.3f} | {bm:9.3f} {mm:9.3f} {mm - bm:+7.3f}")
