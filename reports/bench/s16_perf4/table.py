"""Tables of interleaved prof_cycle runs (reports/bench/s15_perf/prof_cycle.py): per-frame CPU mean / p50 / p99 by
kind of frame, and the mean CPU per stage. Usage: table.py DIR (holding ab_{base,after}_{1,2}.json)."""
import json
import sys
from pathlib import Path

import numpy as np

d = Path(sys.argv[1] if len(sys.argv) > 1 else ".")
runs = {f.stem[3:]: json.loads(f.read_text()) for f in sorted(d.glob("ab_*_*.json"))}
IDS = sorted({n.split("_")[1] for n in runs}, key=int)
KINDS = {"ordinary frames": lambda f, t: [x for x in f if not x["escape_planned"]],
         "escape-planning frames": lambda f, t: [x for x in f if x["escape_planned"]],
         "commanding frames": lambda f, t: [x for x in f if x.get("command")],
         "ticks planning escape": lambda f, t: [x for x in t if x["escape_planned"]],
         "all ticks": lambda f, t: t}


def sel(run, kind):
    return KINDS[kind](run["frames"], run["ticks"])


def cell(xs):
    c = np.array(xs) * 1e3
    return f"{c.mean():.2f} / {np.percentile(c, 50):.2f} / {np.percentile(c, 99):.2f}"


print(f"| kind | n | before: mean / p50 / p99 ms, runs {', '.join(IDS)} | after: the same |")
print("|---|---|---|---|")
for k in KINDS:
    cells = ["; ".join(cell([x["cpu"] for x in sel(runs[f"{side}_{i}"], k)]) for i in IDS) for side in ("base", "after")]
    print(f"| {k} | {len(sel(runs['base_1'], k))} | {cells[0]} | {cells[1]} |")
STAGES = ["tracker", "lifter", "calibration", "monitor", "separation", "people_log", "link_poll", "act", "backfires",
          "escape", "escape_people", "plan_escape_turn", "link_send"]
RUNS = [f"{side}_{i}" for side in ("base", "after") for i in IDS]
for k in ("ordinary frames", "escape-planning frames", "ticks planning escape"):
    means = {(st, n): np.mean([x.get(st, 0.0) for x in sel(runs[n], k)]) * 1e3 for st in STAGES for n in RUNS}
    print(f"\n{k}: mean CPU per stage (ms), runs {' / '.join(IDS)}")
    print("| stage | before | after |\n|---|---|---|")
    shown = [st for st in STAGES if max(means[st, n] for n in RUNS) > 0.005]
    for st in shown:
        b, a = (" / ".join(f"{means[st, f'{side}_{i}']:.3f}" for i in IDS) for side in ("base", "after"))
        print(f"| {st} | {b} | {a} |")
digests = {n: (r["digest"], r["payload_digest"]) for n, r in runs.items()}
print("\ndigests:", "all identical" if len(set(digests.values())) == 1 else digests, next(iter(digests.values())))
