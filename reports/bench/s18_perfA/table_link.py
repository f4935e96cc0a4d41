"""Per-stage p50/mean (ms) of the link stages over frames and ticks, median over runs:
    python table_link.py A1.json A2.json ... -- B1.json B2.json ..."""
from __future__ import annotations

import json
import sys

import numpy as np

STAGES = ["cpu", "tracker", "lifter", "calibration", "monitor", "separation", "people_log", "act", "backfires",
          "link_poll", "receive", "recv", "decode", "feed", "check_state", "link_send", "check_target",
          "enc_target", "enc_mode", "enc_speed", "enc_alarm", "enc_heartbeat", "bus_send"]


def stats(path):
    out = json.load(open(path))
    res = {"digest": out["digest"][:8] + ".." + out["digest"][-4:],
           "payload": out["payload_digest"][:8] + ".." + out["payload_digest"][-4:]}
    for kind, items in (("frames", out["frames"]), ("ticks", out["ticks"])):
        for s in STAGES:
            v = np.array([f.get(s, 0.0) for f in items]) * 1e3
            res[(kind, s)] = (float(np.percentile(v, 50)), float(np.percentile(v, 99)), float(v.mean()))
    # the commanding frames' send (what a move / retraction costs on the link)
    v = np.array([f.get("link_send", 0.0) for f in out["frames"] if f.get("link_send")]) * 1e3
    res[("sending frames", "link_send")] = (float(np.percentile(v, 50)), float(np.percentile(v, 99)), float(v.mean()))
    return res


def main(argv):
    groups, cur = [], []
    for a in argv:
        if a == "--":
            groups.append(cur)
            cur = []
        else:
            cur.append(a)
    groups.append(cur)
    runs = [[stats(p) for p in g] for g in groups if g]
    for g, rs in zip(groups, runs):
        print("group:", " ".join(g), "| digests", {r["digest"] for r in rs}, {r["payload"] for r in rs})
    keys = [k for k in runs[0][0] if isinstance(k, tuple)]
    print(f"{'kind':15s} {'stage':14s}" + "".join(f" | g{i} p50 / p99 / mean" for i in range(len(runs))))
    for k in keys:
        cols = []
        for rs in runs:
            m = np.median([r[k] for r in rs], axis=0)
            cols.append(f" | {m[0]:6.3f} {m[1]:6.3f} {m[2]:6.3f}")
        print(f"{k[0]:15s} {k[1]:14s}" + "".join(cols))


if __name__ == "__main__":
    main(sys.argv[1:])
