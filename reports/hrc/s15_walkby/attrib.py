"""Attribute each halt in wtrace.py outputs: the clause that fired at the frame the state left NORMAL, and for a
lifted person's coming clause, counterfactuals from the truth at that frame: does the clause fire with the true
position and the rule's velocity (true separation now minus the rule's own prediction shrink, the rule's approach),
with the rule's position and the true velocity (the rule's separation now minus the true prediction shrink, the
true approach), with both true.  usage: attrib.py OUT.json ...  (prints a markdown table)"""
import json
import sys

from halts import held

R, LEAD, APP, REACH = 0.6, 0.9, 0.3, 0.85


def clause(d, a):
    return a > APP and d <= R + a * LEAD


print("| scenario | t s | state, reason | fired on | rule d / d_now / appr | true d / d_now / appr | "
      "true position + rule velocity | rule position + true velocity | both true | frames held | cause |")
print("|---|---|---|---|---|---|---|---|---|---|---|")
for path in sys.argv[1:]:
    X = json.load(open(path))
    F, s = X["frames"], X["summary"]
    prev = "NORMAL"
    for i, f in enumerate(F):
        if f["state"] != "NORMAL" and prev == "NORMAL" and f["t"] > 0:
            lifted = {w: p for w, p in f["people"].items() if p["coming"] or p["reach"]}
            if lifted:
                w, p = min(lifted.items(), key=lambda kv: kv[1]["d"])
                n = held(F, i, w)
                td, ta = p.get("true_d"), p.get("true_approach")
                tn = p.get("true_d_now")
                d_tv = tn - (p["d_now"] - p["d"])   # true position, the rule's velocity (its prediction shrink)
                d_rv = p["d_now"] - (tn - td)       # the rule's position, the true velocity
                cols = [clause(d_tv, p["approach"]) or d_tv <= REACH, clause(d_rv, ta) or d_rv <= REACH,
                        clause(td, ta) or td <= REACH]
                if cols[2]:
                    cause = "rule on the true motion"
                elif not cols[1] and cols[0]:
                    cause = "velocity (approach) error"
                elif not cols[0] and cols[1]:
                    cause = "lift/position error"
                else:
                    cause = "both (position and velocity error)"
                on = f"w{w} lifted, " + ("reach" if p["reach"] else "coming")
                print(f"| {s['name']} | {f['t']} | {f['state']} {f['reason']} | {on} | {p['d']} / {p['d_now']} / "
                      f"{p['approach']} | {td} / {p.get('true_d_now')} / {ta} | {cols[0]} | {cols[1]} | {cols[2]} | "
                      f"{n} | {cause} |")
            else:
                w = f["worker"]
                if f["unseen"] and str(f["worker"]) in f["bounded"] and f["dist"] is not None:
                    on = f"w{w} never lifted: ray bound {f['dist']} m"
                elif f["unseen"] and f["dist"] is not None:
                    on = f"w{w} unlifted now, lifted before: reachable-set bound {f['dist']} m"
                elif f["unlifted_stop"]:
                    on = f"w{f['unlifted_stop']} never lifted: ray bound {f['bounded']}"
                elif f["lost_stop"]:
                    on = f"w{f['lost_stop']} lost: reachable set"
                else:
                    on = f"unseen {list(f['unseen'])} (rays bound nothing)"
                print(f"| {s['name']} | {f['t']} | {f['state']} {(f['reason'] or '')[:40]} | {on} | | | | | | | |")
        prev = f["state"]
