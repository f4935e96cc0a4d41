"""Aggregate incremental.py's JSONL (one scenario per line) the way `firmware_sim hrc` does (hrc.productivity)."""
import json
import sys

from firmware_sim.scenarios import hrc

for path in sys.argv[1:]:
    ds = list({d["name"]: d for d in map(json.loads, open(path))}.values())
    ran = [d for d in ds if "not_run" not in d]
    coll = [d for d in ds if d["collision"]]
    p = hrc.productivity(ran)
    print(f"{path}: scenarios {len(ds)} (not run {len(ds) - len(ran)}), collisions {len(coll)} "
          f"({sum(hrc.arm_was_moving(d) for d in coll)} arm moving): "
          + ", ".join(f"{d['name']} {d['min_separation_m']} m still {d.get('arm_still_at_contact_s')} s"
                      f" moved_in_contact {d.get('arm_moved_in_contact')}" for d in coll)
          + f"; min separation {min(d['min_separation_m'] for d in ran)} m; productive share "
          f"{p['productive_time_share']}; walk-by false stops / worker-h {p['false_stops_per_worker_hour']} "
          f"({p['walkby_stops']} in {p['walkby_worker_h']} h: {p['walkby_stops_by_reason']}); wall "
          f"{sum(d['wall_s'] for d in ds):.0f} s")
