"""Side-by-side table of runs_*.txt lines (batch.sh output): seed, scenario, per candidate: collision / min sep /
halts (reasons) / came_within_protective / productive share.  usage: compare.py runs_A.txt runs_B.txt ..."""
import json
import sys

runs = {}
tags = []
for path in sys.argv[1:]:
    for line in open(path):
        tag, seed, rest = line.split(" ", 2)
        s = json.loads(rest[:rest.rindex("}") + 1])
        runs.setdefault((int(seed.split("=")[1]), s["name"]), {})[tag] = s
        if tag not in tags:
            tags.append(tag)
print("| seed scenario | " + " | ".join(tags) + " |")
print("|---|" + "---|" * len(tags))
for (seed, name), by in runs.items():
    cells = []
    for t in tags:
        s = by.get(t)
        if s is None:
            cells.append("-")
            continue
        c = "**COLLISION** " + ("arm moving " if s["arm_moved_in_contact"] else "arm still ") if s["collision"] else ""
        cells.append(f"{c}{s['min_separation_m']} m, halts {s['halts']} {s['halt_reasons'] or ''}, "
                     f"{'cwp' if s['came_within_protective'] else 'walk-by'}, share {s['productive_time_share']}")
    print(f"| {seed} {name} | " + " | ".join(cells) + " |")
