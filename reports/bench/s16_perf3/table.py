"""Tables of the interleaved before/after runs: ``table.py DIR`` reads DIR/ab_{base,after}_{1,2}.json
(reports/bench/s15_perf/prof_cycle.py) and DIR/replay_{base,after}_{1,2}.json (replay.py here) and prints
markdown: per-frame CPU, per-stage mean and p99 of ordinary frames, the stages alone, and the digests."""
import json
import sys
from pathlib import Path

import numpy as np

d = Path(sys.argv[1] if len(sys.argv) > 1 else ".")
RUNS = [(side, i) for i in (1, 2) for side in ("base", "after")]
prof = {r: json.loads((d / f"ab_{r[0]}_{r[1]}.json").read_text()) for r in RUNS}
replay = {r: json.loads((d / f"replay_{r[0]}_{r[1]}.json").read_text()) for r in RUNS
          if (d / f"replay_{r[0]}_{r[1]}.json").exists()}


def ms(v, q):
    return float(np.percentile(np.asarray(v) * 1e3, q)) if len(v) else float("nan")


def cell(side, f):
    return "; ".join(f(prof[(side, i)]) for i in (1, 2))


kinds = {"ordinary frames": lambda o: [x for x in o["frames"] if not x["escape_planned"]],
         "commanding frames": lambda o: [x for x in o["frames"] if x.get("command")],
         "all frames": lambda o: o["frames"]}
print("Per-frame CPU, ms, p50 / p99 (run 1; run 2)\n")
print("| kind | n | before | after |\n|---|---|---|---|")
for k, sel in kinds.items():
    def f(o, sel=sel):
        c = [x["cpu"] for x in sel(o)]
        return f"{ms(c, 50):.2f} / {ms(c, 99):.2f}"
    print(f"| {k} | {len(sel(prof[('base', 1)]))} | {cell('base', f)} | {cell('after', f)} |")

print("\nOrdinary frames, CPU per stage, ms, mean / p99 (run 1; run 2)\n")
print("| stage | before | after |\n|---|---|---|")
for st in ("tracker", "lifter", "calibration", "monitor", "people_log", "link_poll", "act"):
    def f(o, st=st):
        v = [x.get(st, 0.0) for x in kinds["ordinary frames"](o)]
        return f"{np.mean(v) * 1e3:.3f} / {ms(v, 99):.3f}"
    print(f"| {st} | {cell('base', f)} | {cell('after', f)} |")

if replay:
    print("\nThe stages alone (replay.py: tracker untimed, no monitor or link), ms, mean / p50 / p99 (run 1; run 2)\n")
    print("| stage | before | after |\n|---|---|---|")
    for st in ("lifter", "calibration", "rays"):
        cells = ["; ".join(f"{replay[(s, i)][st]['mean']:.3f} / {replay[(s, i)][st]['p50']:.3f} / "
                           f"{replay[(s, i)][st]['p99']:.3f}" for i in (1, 2) if (s, i) in replay)
                 for s in ("base", "after")]
        print(f"| {st} | {cells[0]} | {cells[1]} |")

print("\nDigests")
for r in RUNS:
    o = prof[r]
    rd = replay.get(r, {}).get("digest", "-")
    print(f"- {r[0]} {r[1]}: decisions {o['digest']}, CAN payloads {o['payload_digest']}, replay outputs {rd}")
