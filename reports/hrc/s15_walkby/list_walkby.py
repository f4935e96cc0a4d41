"""Step 1: the walk-by halts (scenarios with came_within_protective false and halts > 0) in existing hrc outputs
(a full JSON's `details`, or a .jsonl of per-scenario summaries). usage: list_walkby.py SEED=FILE ..."""
import json
import sys

print("| seed | scenario | kind | workers (kind, top speed m/s, pause s) | true min sep m | halts | reasons | "
      "zone entries (t s, level, true dist m) |")
print("|---|---|---|---|---|---|---|---|")
for arg in sys.argv[1:]:
    seed, path = arg.split("=", 1)
    rows = [json.loads(x) for x in open(path)] if path.endswith(".jsonl") else json.load(open(path))["details"]
    n = h = 0
    wh = 0.0
    for s in rows:
        if s["came_within_protective"]:
            continue
        wh += s["worker_s"] / 3600
        if s["halts"] <= 0:
            continue
        n += 1
        h += s["halts"]
        ws = ", ".join(f"{w['kind']} {max(w['speeds_mps'])}" + (f" pause {w['pause'][1]:.1f}" if w["pause"] else "")
                       for w in s["worker_specs"])
        ze = "; ".join(f"{z['t_s']} {z['level']} {z['true_distance_m']}" for z in s["zone_entries"][:4])
        print(f"| {seed} | {s['name']} | {s['kind']} | {ws} | {s['min_separation_m']} | {s['halts']} | "
              f"{s['halt_reasons']} | {ze} |")
    print(f"| {seed} | **{n} scenarios** | | | | **{h}** | {h / wh:.1f} per walk-by worker-h ({wh:.4f} h) | |")
