"""Session 23: where a chosen operating point's false alerts come from (offline, fp32 probabilities of sweep.py).

    PYTHONPATH=. python reports/wearable/stream_s23/causes.py NAME SEED W HOP_MULT K THR OFF_S

A false alert here: an alert frame outside every distraction's [start - 2 s, end] (drive-eval's stream scoring
credits frames from 2 s before the start, reports/wearable/stream_s22). Cause: the Other motion whose span (+- 1 s)
holds the frame (its kind), else "return" within 5 s after a distraction's end, else "elsewhere".
"""
import collections
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "stream_s21"))
from policy import Policy, alerts  # noqa: E402
from sweep import DIR, load_streams, path  # noqa: E402

name, seed, w, hop, k, thr, off = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), int(sys.argv[4]), \
    int(sys.argv[5]), float(sys.argv[6]), float(sys.argv[7])
drives = load_streams(DIR / f"drives_seed{seed}")
z = np.load(path(name, seed, w))
pol = Policy(w, hop, "top", k, thr, off)
causes = collections.Counter()
for i, d in enumerate(drives):
    dis = [e for e in d["events"] if e["label"] != "Other"]
    oth = [e for e in d["events"] if e["label"] == "Other"]
    for a in alerts(z[f"t{i}"], z[f"p{i}"], pol):
        t = a["t_alert_s"]
        if any(e["start_s"] - 2.0 <= t <= e["end_s"] for e in dis):
            continue
        o = next((e for e in oth if e["start_s"] - 1.0 <= t <= e["end_s"] + 1.0), None)
        r = any(e["end_s"] < t <= e["end_s"] + 5.0 for e in dis)
        causes[o.get("kind", "Other") if o else ("return" if r else "elsewhere")] += 1
print(dict(causes.most_common()), sum(causes.values()))
