"""Add hrc runs of the validated configuration (same safety hash) to validated.json's later_runs.
usage: later.py WHEN JSON..."""
import json
import sys
from pathlib import Path

path = Path("reports/hrc/validated.json")
rec = json.loads(path.read_text())
when, files = sys.argv[1], sys.argv[2:]
later = rec.setdefault("later_runs", {"runs": [], "what": ""})
for f in files:
    d = json.loads(Path(f).read_text())
    assert d["safety_sha256"] == rec["safety_sha256"], f
    later["runs"].append({"arm_moved_in_contact": d["arm_moved_in_contact"], "collided": d["collided"],
                          "collisions": d["collisions"], "json": f, "link": d["link"],
                          "min_separation_m": d["min_separation_m"], "not_run": d["not_run"],
                          "scenario": d["scenario"], "seed": d["seed"], "when": when})
path.write_text(json.dumps(rec, indent=1, sort_keys=True) + "\n")
print(len(later["runs"]), "later runs")
