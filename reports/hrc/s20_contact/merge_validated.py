"""Merge the per-run validation records (/work/notes/val20/v_*.json, one hrc --validated run each) into
reports/hrc/validated.json of the worktree given, keeping the record before under `superseded`.
usage: merge_validated.py WORKTREE WHAT"""
import glob
import json
import sys
from pathlib import Path

tree, what = Path(sys.argv[1]), sys.argv[2]
recs = [json.loads(Path(f).read_text()) for f in sorted(glob.glob("/work/notes/val20/v_*.json"))]
hashes = {r["safety_sha256"] for r in recs}
assert len(hashes) == 1, hashes
new = {"safety_sha256": recs[0]["safety_sha256"], "safety_config": recs[0]["safety_config"], "runs": {}}
for r in recs:
    assert r["safety_config"] == new["safety_config"]
    new["runs"].update(r["runs"])
new["must_hold_met"] = all(r["collisions"] == 0 for r in new["runs"].values())
new["what"] = what
path = tree / "reports/hrc/validated.json"
old = json.loads(path.read_text())
assert old["safety_sha256"] != new["safety_sha256"]
new["superseded"] = {k: old[k] for k in ("safety_sha256", "what", "runs", "later_runs") if k in old}
new["superseded"]["earlier"] = old.get("superseded")
path.write_text(json.dumps(new, indent=1, sort_keys=True) + "\n")
print(len(new["runs"]), "runs; must_hold_met", new["must_hold_met"], new["safety_sha256"][:8])
