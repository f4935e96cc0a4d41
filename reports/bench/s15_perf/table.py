import json

import numpy as np

runs = {n: json.load(open(f"ab_{n}.json")) for n in ("base_1", "after_1", "base_2", "after_2")}
def sel(out, kind):
    f, t = out["frames"], out["ticks"]
    return {"ordinary frames": [x for x in f if not x["escape_planned"]],
            "escape-planning frames": [x for x in f if x["escape_planned"]],
            "commanding frames": [x for x in f if x.get("command")],
            "ticks planning escape": [x for x in t if x["escape_planned"]],
            "all ticks": t}[kind]
kinds = ["ordinary frames", "escape-planning frames", "commanding frames", "ticks planning escape", "all ticks"]
print("| kind | n | before p50 / p99 (ms), run 1; run 2 | after p50 / p99 (ms), run 1; run 2 |")
print("|---|---|---|---|")
for k in kinds:
    cells = []
    for side in ("base", "after"):
        s = []
        for i in (1, 2):
            c = np.array([x["cpu"] for x in sel(runs[f"{side}_{i}"], k)]) * 1e3
            s.append(f"{np.percentile(c, 50):.2f} / {np.percentile(c, 99):.2f}")
        cells.append("; ".join(s))
    print(f"| {k} | {len(sel(runs['base_1'], k))} | {cells[0]} | {cells[1]} |")
stages = ["tracker", "lifter", "calibration", "monitor", "separation", "people_log", "link_poll", "act", "backfires",
          "escape", "escape_people", "plan_escape_turn", "link_send"]
print()
for k in ("ordinary frames", "escape-planning frames", "ticks planning escape"):
    print(f"\n{k}: mean CPU per stage (ms), before run1/run2 -> after run1/run2")
    print("| stage | before | after |\n|---|---|---|")
    for st in stages:
        b = [np.mean([x.get(st, 0.0) for x in sel(runs[f"base_{i}"], k)]) * 1e3 for i in (1, 2)]
        a = [np.mean([x.get(st, 0.0) for x in sel(runs[f"after_{i}"], k)]) * 1e3 for i in (1, 2)]
        if max(b + a) > 0.005:
            print(f"| {st} | {b[0]:.3f} / {b[1]:.3f} | {a[0]:.3f} / {a[1]:.3f} |")
