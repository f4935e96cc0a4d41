"""Totals of record_states.py's per-scenario files: productive time and the non-NORMAL time by
bucket and by the monitor's reason, side by side for several runs, and the scenarios where the first
two runs differ most.

    python reports/hrc/s17_prodshare/summarize.py A.json.gz B.json.gz [...] [--top N]
"""
from __future__ import annotations

import gzip
import json
import sys
from collections import defaultdict
from pathlib import Path


def load(path: str) -> list[dict]:
    with gzip.open(path, "rt") as f:
        return json.load(f)


def totals(rows: list[dict]) -> dict:
    out: dict = defaultdict(float)
    for r in rows:
        out["scenario_s"] += r["scenario_s"]
        out["productive_s"] += r["productive_s"]
        # the commanded speed cap while NORMAL, time-weighted: work the metric's "productive" time can do
        out["speed_weighted_s"] += r["productive_s"] * (r["mean_speed_scale_normal"] or 0.0)
        out["collisions"] += bool(r["collision"])
        for k, v in r["buckets_s"].items():
            out["bucket " + k] += v
        for k, v in r["reasons_s"].items():
            out["reason " + k] += v
    out["min_separation_m"] = min(r["min_separation_m"] for r in rows)
    out["share"] = out["productive_s"] / out["scenario_s"]
    out["speed_weighted_share"] = out["speed_weighted_s"] / out["scenario_s"]
    return out


def main(argv: list[str]) -> int:
    top = 12
    if "--top" in argv:
        i = argv.index("--top")
        top = int(argv[i + 1])
        argv = argv[:i] + argv[i + 2:]
    runs = [(Path(p).name.removesuffix(".json.gz").removeprefix("seg_"), load(p)) for p in argv]
    tots = [totals(rows) for _, rows in runs]
    # the hrc command's own figures, from its --json beside each record (hard60_<tag>.json)
    for (name, _), path, t in zip(runs, argv, tots):
        hrc_json = Path(path).with_name("hard60_" + name + ".json")
        if hrc_json.exists():
            h = json.loads(hrc_json.read_text())
            for k in ("collisions_arm_moving", "retracts", "halts", "false_stops_per_worker_hour"):
                t["hrc " + k] = h[k]
            t["hrc productive_time_share"] = h["productive_time_share"]
    keys = ["scenario_s", "productive_s", "share", "speed_weighted_share", "collisions", "min_separation_m"]
    keys += sorted({k for t in tots for k in t if k.startswith(("hrc", "bucket", "reason"))})
    print("| | " + " | ".join(name for name, _ in runs) + " |")
    print("|---|" + "---:|" * len(runs))
    for k in keys:
        print(f"| {k} | " + " | ".join(f"{t.get(k, 0.0):.4g}" for t in tots) + " |")
    if len(runs) >= 2:
        a, b = ({r["name"]: r for r in rows} for _, rows in runs[:2])
        diffs = sorted(((a[n]["productive_s"] - b[n]["productive_s"], n) for n in a if n in b), reverse=True)
        print(f"\nproductive s, {runs[0][0]} - {runs[1][0]}: largest and smallest {top}")
        for d, n in diffs[:top] + [(None, "...")] + diffs[-top:]:
            if d is None:
                print("...")
                continue
            print(f"{n} {d:+.2f} s ({a[n]['productive_s']:.2f} / {b[n]['productive_s']:.2f} of {a[n]['scenario_s']:.1f})")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
