"""The link's stages in interleaved prof_cycle runs (reports/bench/s15_perf/prof_cycle.py): mean CPU of link_poll,
act and link_send per kind of frame and tick, and the whole frame's. Usage: table.py DIR (ab_{base,after}_N.json)."""
import json
import sys
from pathlib import Path

import numpy as np

d = Path(sys.argv[1] if len(sys.argv) > 1 else ".")
runs = {f.stem[3:]: json.loads(f.read_text()) for f in sorted(d.glob("ab_*_*.json"))}
ids = sorted({n.split("_")[1] for n in runs}, key=int)
kinds = {"commanding frames": lambda r: [x for x in r["frames"] if x.get("command")],
         "ordinary frames": lambda r: [x for x in r["frames"] if not x["escape_planned"]],
         "escape-planning frames": lambda r: [x for x in r["frames"] if x["escape_planned"]],
         "ticks that send a command": lambda r: [x for x in r["ticks"] if x.get("link_send", 0) > 0],
         "all ticks": lambda r: r["ticks"]}
stages = ("link_poll", "act", "link_send", "cpu")
print("Mean CPU (ms) per frame or tick; runs " + " / ".join(ids) + "; `cpu` is the whole frame's.\n")
print("| kind | n | stage | before | after |\n|---|---|---|---|---|")
for kind, pick in kinds.items():
    for st in stages:
        cells = [" / ".join(f"{np.mean([x.get(st, 0.0) for x in pick(runs[f'{side}_{i}'])]) * 1e3:.3f}" for i in ids)
                 for side in ("base", "after")]
        print(f"| {kind} | {len(pick(runs['base_1']))} | {st} | {cells[0]} | {cells[1]} |")
digests = {n: (r["digest"], r["payload_digest"]) for n, r in runs.items()}
print("\ndigests:", "all identical" if len(set(digests.values())) == 1 else digests, next(iter(digests.values())))
