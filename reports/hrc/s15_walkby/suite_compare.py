"""Compare a candidate's per-scenario JSONL (incr_cand.py) with a full shipped `hrc --json` output, on the
scenarios both ran: collisions (arm moving), min separation, walk-by halts per walk-by worker-hour (hrc's
definition: halts in scenarios nobody came within the protective distance / their worker-hours), productive
share (hrc's: sum productive_s / sum scenario_s), and the scenarios whose outcome differs.
usage: suite_compare.py SHIPPED.json CAND.jsonl"""
import json
import sys

ship = {d["name"]: d for d in json.load(open(sys.argv[1]))["details"]}
cand = {d["name"]: d for d in (json.loads(x) for x in open(sys.argv[2]))}
names = [n for n in cand if n in ship]


def figures(rows):
    wb = [d for d in rows if not d["came_within_protective"]]
    wh = sum(d["worker_s"] for d in wb) / 3600
    halts = sum(d["halts"] for d in wb)
    reasons = {}
    for d in wb:
        for k, v in d.get("halt_reasons", {}).items():
            reasons[k] = reasons.get(k, 0) + v
    return {"scenarios": len(rows), "collisions": sum(d["collision"] for d in rows),
            "arm_moving": sum(bool(d["collision"] and d["arm_moved_in_contact"]) for d in rows),
            "min_sep_m": min(d["min_separation_m"] for d in rows),
            "walkby_scenarios": len(wb), "walkby_h": round(wh, 4), "walkby_halts": halts,
            "walkby_per_h": round(halts / wh, 1) if wh else None, "walkby_reasons": reasons,
            "productive_share": round(sum(d["productive_s"] for d in rows) / sum(d["scenario_s"] for d in rows), 4)}


print("shipped  ", json.dumps(figures([ship[n] for n in names])))
print("candidate", json.dumps(figures([cand[n] for n in names])))
same = 0
for n in names:
    a, b = ship[n], cand[n]
    ka = (a["collision"], a["min_separation_m"], a["halts"], a["came_within_protective"])
    kb = (b["collision"], b["min_separation_m"], b["halts"], b["came_within_protective"])
    if ka == kb:
        same += 1
    else:
        print(f"  {n}: shipped coll={a['collision']} sep={a['min_separation_m']} halts={a['halts']} "
              f"{a['halt_reasons']} cwp={a['came_within_protective']} | cand coll={b['collision']} "
              f"sep={b['min_separation_m']} halts={b['halts']} {b['halt_reasons']} cwp={b['came_within_protective']}")
print(f"{same} of {len(names)} scenarios identical in (collision, min sep, halts, came_within_protective)")
