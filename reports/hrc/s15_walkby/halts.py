"""Summarise the halts in a wtrace.py output: per episode (state leaves NORMAL), the frame where it began, the
reason, and per person what the rule used vs the truth; how many frames the triggering clause held.
usage: halts.py OUT.json [...]"""
import json
import sys


def held(frames, i, w):
    """How many consecutive frames from frames[i] person w's coming or reach clause held (his lifted frames)."""
    n = 0
    for g in frames[i:]:
        q = g["people"].get(w)
        if q is None or not (q["coming"] or q["reach"]):
            break
        n += 1
    return n


def main(paths):
    for path in paths:
        X = json.load(open(path))
        F = X["frames"]
        s = X["summary"]
        print(f"## {s['name']} fix={X['fix'] or 'shipped'} halts={s['halts']} {s['halt_reasons']} "
              f"minsep={s['min_separation_m']} cwp={s['came_within_protective']} share={s['productive_time_share']}")
        prev = "NORMAL"
        for i, f in enumerate(F):
            if f["state"] != "NORMAL" and prev == "NORMAL":
                # clause duration: consecutive frames around i with the same reason's clause true
                print(f"  t={f['t']} -> {f['state']} reason={f['reason']} worker={f['worker']} dist={f['dist']} "
                      f"unseen={f['unseen']} unlifted_stop={f['unlifted_stop']} lost_stop={f['lost_stop']} "
                      f"bounded={f['bounded']}")
                for w, p in f["people"].items():
                    n = held(F, i, w)
                    print(f"    w{w}: rule d={p['d']} d_now={p['d_now']} speed={p['speed']} appr={p['approach']} "
                          f"lim={p['lim']} coming={p['coming']} reach={p['reach']} (held {n} fr) | true "
                          f"d={p.get('true_d')} d_now={p.get('true_d_now')} speed={p.get('true_speed')} "
                          f"appr={p.get('true_approach')} | head {p['head']} vs {p.get('true_head')}")
                # frames before: the 3 preceding for the trigger person
                for g in F[max(0, i - 3):i]:
                    print("     pre", g["t"], {w: (p["d"], p["approach"], p.get("true_d"), p.get("true_approach"))
                                               for w, p in g["people"].items()}, g["unseen"], g["bounded"])
            prev = f["state"]


if __name__ == "__main__":
    main(sys.argv[1:])
