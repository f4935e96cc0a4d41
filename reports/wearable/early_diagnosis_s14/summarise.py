"""Tables and the go / no-go of ``hybrid.py``'s JSON (figures read from it, none typed in).

    python reports/wearable/early_diagnosis_s14/summarise.py OUT.json [CHECK_SEED] > OUT/summary.md

GO if on CHECK_SEED (default 5) the policy chosen on the other seed gives a median onset -> first alert <= 2.5 s
with a first-alert class accuracy >= the shipped policy's and false alerts / h <= the shipped + 0.3 (attribution
"frame", drive-eval's headline); otherwise NO-GO.
"""
import json
import sys

GO_MEDIAN_S, GO_FALSE_EXTRA_PER_H = 2.5, 0.3


def cells(s: dict) -> str:
    o = s["onset_to_first_alert_s"]
    return (f"{s['event_recall']:.3f} | {s['first_alert_class_accuracy']:.3f} | {o['median']:.2f} | {o['p95']:.2f} | "
            f"{s['false_alerts_per_hour']:.2f} ({s['false_alerts']}) | {s['repeat_alerts']}")


HEAD = ("| recall | first-alert class | median (s) | p95 (s) | false / h (n) | repeat |",
        "|---:|---:|---:|---:|---:|---:|")


def policy(r: dict) -> str:
    gate = r.get("max_mean_other", 1.0)
    return (f"t {r['threshold']}, agree {r['agree']}, {r['first_s']:.2f}-{r['last_s']:.2f} s"
            + (f", mean P(Other) <= {gate}" if gate < 1.0 else ""))


def main(path: str, check: int = 5) -> None:
    rep = json.load(open(path))
    seeds = [str(s) for s in rep["seeds"]]
    choose = str(rep["choose_on"])
    best = rep["chosen_index"]
    L = [f"Prefix model {rep['prefix_model']}; {rep['hours']:g} h of drive-eval drives per seed; policy chosen on "
         f"seed {choose}; wall {rep['wall_s']} s.", ""]
    L += ["## Shipped policy: the runtime against the re-implementation (attribution frame / trigger)", "",
          "| seed | captures | decisions runtime / re-impl. / identical | who | attribution " + HEAD[0],
          "|---:|---:|---|---|---" + HEAD[1]]
    for s in seeds:
        p = rep["per_seed"][s]
        c = p["reimplementation_check"]
        for who in ("runtime_shipped", "reimplemented_shipped"):
            for att in ("frame", "trigger"):
                L.append(f"| {s} | {p['captures']} | {c['runtime_decisions']} / {c['reimplemented_decisions']} / "
                         f"{c['identical']} | {who} | {att} | {cells(p[who][att])} |")
    L += ["", "## The hybrid chosen on seed " + choose + " (rule: class >= shipped, false / h <= shipped + 0.3 there; "
          "lowest median)", ""]
    if best is None:
        L.append("No policy of the grid met the rule on the choosing seed.")
    else:
        L += ["| seed | policy | attribution | prefix alerts " + HEAD[0], "|---:|---|---|---:" + HEAD[1]]
        for s in seeds:
            r = rep["per_seed"][s]["hybrid"][best]
            for att in ("frame", "trigger"):
                L.append(f"| {s} | {policy(r)} | {att} | {r['prefix_alerts']} | {cells(r['scores'][att])} |")
    # the trade-off: every threshold / agreement, the fastest (first, last) window that meets the rule on the
    # choosing seed, and the same policy on the others
    L += ["", f"## The trade-off (frame): per threshold and agreement, the fastest window eligible on seed {choose} "
          "(else the fastest), and the same policy on the other seeds", "",
          "| policy | eligible on " + choose + " | " + " | ".join(f"seed {s}: recall / class / median / p95 / false/h"
                                                                  for s in seeds) + " |",
          "|---|---|" + "---|" * len(seeds)]
    rows = rep["per_seed"][choose]["hybrid"]
    ship = rep["per_seed"][choose]["runtime_shipped"]["frame"]

    def eligible(r):
        f = r["scores"]["frame"]
        return (f["first_alert_class_accuracy"] >= ship["first_alert_class_accuracy"]
                and f["false_alerts_per_hour"] <= ship["false_alerts_per_hour"] + GO_FALSE_EXTRA_PER_H)

    groups = {}
    for i, r in enumerate(rows):
        groups.setdefault((r["threshold"], r["agree"], r.get("max_mean_other", 1.0)), []).append(i)
    for _, idx in sorted(groups.items()):
        el = [i for i in idx if eligible(rows[i])]
        i = min(el or idx, key=lambda i: rows[i]["scores"]["frame"]["onset_to_first_alert_s"]["median"])
        out = []
        for s in seeds:
            f = rep["per_seed"][s]["hybrid"][i]["scores"]["frame"]
            o = f["onset_to_first_alert_s"]
            out.append(f"{f['event_recall']:.3f} / {f['first_alert_class_accuracy']:.3f} / {o['median']:.2f} / "
                       f"{o['p95']:.2f} / {f['false_alerts_per_hour']:.2f}")
        L.append(f"| {policy(rows[i])} | {'yes' if el else 'no'} | " + " | ".join(out) + " |")
    if check in rep["seeds"] and best is not None:
        sh = rep["per_seed"][str(check)]["runtime_shipped"]["frame"]
        hy = rep["per_seed"][str(check)]["hybrid"][best]["scores"]["frame"]
        med = hy["onset_to_first_alert_s"]["median"]
        tests = {f"median {med:.2f} s <= {GO_MEDIAN_S}": med <= GO_MEDIAN_S,
                 f"first-alert class {hy['first_alert_class_accuracy']:.3f} >= shipped "
                 f"{sh['first_alert_class_accuracy']:.3f}": hy["first_alert_class_accuracy"] >= sh["first_alert_class_accuracy"],
                 f"false alerts {hy['false_alerts_per_hour']:.2f} / h <= shipped {sh['false_alerts_per_hour']:.2f} + "
                 f"{GO_FALSE_EXTRA_PER_H}": hy["false_alerts_per_hour"] <= sh["false_alerts_per_hour"] + GO_FALSE_EXTRA_PER_H}
        L += ["", f"## Verdict on seed {check}: {'GO' if all(tests.values()) else 'NO-GO'}", ""]
        L += [f"* {k}: {'yes' if v else 'NO'}" for k, v in tests.items()]
    print("\n".join(L))


if __name__ == "__main__":
    main(sys.argv[1], int(sys.argv[2]) if len(sys.argv) > 2 else 5)
