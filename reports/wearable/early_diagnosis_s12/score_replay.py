"""Score one CLI replay: onset -> trigger -> first alert frame per distraction (the drive's truth.json and the
runtime's --alerts JSONL). Usage: python score_replay.py DIR (DIR/truth.json, DIR/alerts.jsonl)."""
import json
import sys
from collections import Counter

import numpy as np

d = sys.argv[1]
truth = [e for e in json.load(open(f"{d}/truth.json"))["events"] if e["label"] != "Other"]
dec = [json.loads(line) for line in open(f"{d}/alerts.jsonl")]
alerts = sorted((x for x in dec if x["alerted"] and x["status"] in ("preliminary", "alert", "confirmed", "revised")),
                key=lambda x: x["t_alert_s"])
rows = []
for e in truth:
    own = [x for x in alerts if e["start_s"] - 1.0 <= x["t_trigger_s"] <= e["end_s"]]
    trig = sorted({x["t_trigger_s"] for x in dec if e["start_s"] - 1.0 <= x["t_trigger_s"] <= e["end_s"]})
    if own:
        f = own[0]
        rows.append((e["label"], f["t_trigger_s"] - e["start_s"], f["t_alert_s"] - f["t_trigger_s"], f["t_alert_s"] - e["start_s"],
                     f["steps"], f["label"] == e["label"]))
    else:
        rows.append((e["label"], trig[0] - e["start_s"] if trig else None, None, None, None, None))
a = [r for r in rows if r[3] is not None]
q = lambda v, p: float(np.percentile(v, p))  # noqa: E731
print(f"{len(truth)} distractions, {len(a)} alerted, class right {np.mean([r[5] for r in a]):.3f}")
for name, k in (("onset->trigger (alerting capture)", 1), ("trigger->first alert", 2), ("onset->first alert", 3)):
    v = [r[k] for r in a]
    print(f"{name}: median {q(v, 50):.2f} s, p95 {q(v, 95):.2f} s")
print("first alert at S:", sorted(Counter(r[4] for r in a).items()))
