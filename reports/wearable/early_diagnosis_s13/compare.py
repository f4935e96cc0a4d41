"""Stage 1's go / no-go table from ``peeks.py``'s JSON outputs: per drive seed and (model, family), the fastest
policy whose first-alert class accuracy and false alerts per hour are no worse than the reference's (the shipped
model on today's grid at the shipped policy: threshold 0.9 from S = 2).

    python reports/wearable/early_diagnosis_s13/compare.py NAME=PEEKS_JSON [NAME=PEEKS_JSON ...]
"""
import json
import sys


def main(args):
    runs = {a.split("=", 1)[0]: json.load(open(a.split("=", 1)[1])) for a in args}
    first = next(iter(runs.values()))
    L = ["| seed | model | family | constraint | earliest | thr | recall | class | median | p95 | false/h | repeat |",
         "|---:|---|---|---|---|---:|---:|---:|---:|---:|---:|---:|"]
    for seed in first["seeds"]:
        ref = next(r for r in first["policies"] if r["seed"] == seed and r["family"] == "grid"
                   and r["early_from"] == "2:33" and r["threshold"] == 0.9)
        cons = {"class >= 0.90, false/h <= ref": lambda r: r["first_alert_class_accuracy"] >= 0.90
                and r["false_alerts_per_hour"] <= ref["false_alerts_per_hour"] + 1e-9,
                "class >= ref, false/h <= ref": lambda r: r["first_alert_class_accuracy"] >= ref["first_alert_class_accuracy"] - 1e-9
                and r["false_alerts_per_hour"] <= ref["false_alerts_per_hour"] + 1e-9}
        rows = [("reference (shipped: grid, 0.9 from 2:33)", "grid", "-", ref)]
        for name, run in runs.items():
            for fam in ("grid", "peek"):
                for cname, ok in cons.items():
                    cand = [r for r in run["policies"] if r["seed"] == seed and r["family"] == fam and ok(r)
                            and r["event_recall"] >= ref["event_recall"] - 0.005]
                    if cand:
                        best = min(cand, key=lambda r: (r["onset_to_first_alert_s"]["median"], r["false_alerts_per_hour"]))
                        rows.append((name, fam, cname, best))
        for name, fam, cname, r in rows:
            o = r["onset_to_first_alert_s"]
            L.append(f"| {seed} | {name} | {fam} | {cname} | {r['early_from']} | {r['threshold']} | {r['event_recall']:.3f} | "
                     f"{r['first_alert_class_accuracy']:.3f} | {o['median']:.2f} | {o['p95']:.2f} | "
                     f"{r['false_alerts_per_hour']:.2f} | {r['repeat_alerts']} |")
    print("\n".join(L))


if __name__ == "__main__":
    main(sys.argv[1:])
