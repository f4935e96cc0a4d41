"""Tables of tail.py's output (issue 12, session 15).

    python reports/wearable/tail_s15/summarise.py S1.json S5.json [--csv-dir DIR]
    python reports/wearable/tail_s15/summarise.py --levers LEVERS.json ... --oracle ORACLE.json ...

Prints Markdown: the first alert by sub-window count, the causes of the slowest 10 % and of the misses, what the
classifier said at each step for the first alerts made only at S = 6, the trigger's timing, and examples. With
``--csv-dir``: one CSV per seed, a row per distraction.
"""
from __future__ import annotations

import argparse
import csv
import json
from collections import Counter
from pathlib import Path

import numpy as np

CLASSES = ["Phone", "Texting", "Drink", "Marker", "TouchScreen"]


def q(v, qs=(50, 90)) -> str:
    v = np.asarray([x for x in v if x is not None], float)
    return "–" if not v.size else " / ".join(f"{np.percentile(v, x):.2f}" for x in qs)


def overview(runs) -> list[str]:
    out = ["| seed | distractions | alerted | median / p95 (s) | slowest 10 % from (s) | first alert at S: count (median latency s, median trigger delay s) |",
           "|---:|---:|---:|---|---:|---|"]
    for d in runs:
        ev = d["events"]
        al = [r for r in ev if r["alerted"]]
        by_s = "; ".join(
            f"S{s}: {len(rs)} ({np.median([r['latency_s'] for r in rs]):.2f}, {np.median([r['trigger_delay_s'] for r in rs]):.2f})"
            for s in range(2, 7) for rs in [[r for r in al if r["S"] == s]] if rs)
        f = d["figures"]
        out.append(f"| {d['seed']} | {len(ev)} | {len(al)} | {f['median_s']:.2f} / {f['p95_s']:.2f} | {d['p90_s']:.2f} | {by_s} |")
    return out


def causes(runs) -> list[str]:
    keys = Counter()
    for d in runs:
        for r in d["events"]:
            if r["tail"]:
                keys[("slow" if r["alerted"] else "missed", r["cause"])] += 1
    rows = sorted(keys, key=lambda k: (k[0] != "slow", -sum(
        1 for d in runs for r in d["events"] if r["tail"] and r["cause"] == k[1] and (r["alerted"] == (k[0] == "slow")))))
    out = ["| group | cause | " + " | ".join(f"seed {d['seed']}: n (share)" for d in runs) + " |",
           "|---|---|" + "---:|" * len(runs)]
    for grp, c in rows:
        cells = []
        for d in runs:
            g = [r for r in d["events"] if r["tail"] and r["alerted"] == (grp == "slow")]
            n = sum(r["cause"] == c for r in g)
            cells.append(f"{n} ({n / len(g):.0%})")
        out.append(f"| {grp} | {c} | " + " | ".join(cells) + " |")
    for grp in ("slow", "missed"):
        out.append(f"| {grp} | **all** | " + " | ".join(
            str(sum(1 for r in d["events"] if r["tail"] and r["alerted"] == (grp == "slow"))) for d in runs) + " |")
    return out


def steps_of_s6(runs) -> list[str]:
    out = ["| seed | group | n | S | top = true class | top = another distraction | top = Other | confidence of top, median (p90) |",
           "|---:|---|---:|---:|---:|---:|---:|---|"]
    for d in runs:
        al = [r for r in d["events"] if r["alerted"] and r["S"] == 6 and r["steps"]]
        for name, sel in (("all first alerts at S = 6", al), ("of them in the slowest 10 %", [r for r in al if r["tail"]])):
            for s in (2, 3, 4, 5):
                st = [(r, r["steps"][s - 1]) for r in sel]
                true = sum(x["label"] == r["label"] for r, x in st)
                oth = sum(x["label"] == "Other" for r, x in st)
                conf = [x["conf"] for r, x in st]
                out.append(f"| {d['seed']} | {name} | {len(sel)} | {s} | {true} | {len(sel) - true - oth} | {oth} | "
                           f"{np.median(conf):.2f} ({np.percentile(conf, 90):.2f}) |")
    return out


def confusion_s3(runs) -> list[str]:
    out = ["| seed | truth | first alerts at S >= 4 | S = 3's top class: the truth / " + " / ".join(
        c for c in CLASSES) + " / Other |", "|---:|---|---:|---|"]
    for d in runs:
        al = [r for r in d["events"] if r["alerted"] and r["S"] >= 4 and r["steps"]]
        for c in CLASSES:
            rs = [r for r in al if r["label"] == c]
            cnt = Counter(r["steps"][2]["label"] for r in rs)
            out.append(f"| {d['seed']} | {c} | {len(rs)} | {cnt.get(c, 0)} / " + " / ".join(
                ("–" if k == c else str(cnt.get(k, 0))) for k in CLASSES) + f" / {cnt.get('Other', 0)} |")
    return out


def by_class(runs) -> list[str]:
    out = ["| seed | class | distractions | first alert at S = 6 | in the slowest 10 % | missed | trigger delay median / p90 (s) |",
           "|---:|---|---:|---:|---:|---:|---|"]
    for d in runs:
        for c in CLASSES:
            rs = [r for r in d["events"] if r["label"] == c]
            al = [r for r in rs if r["alerted"]]
            out.append(f"| {d['seed']} | {c} | {len(rs)} | {sum(r['S'] == 6 for r in al)} | "
                       f"{sum(r['tail'] and r['alerted'] for r in rs)} | {sum(not r['alerted'] for r in rs)} | "
                       f"{q(r['trigger_delay_s'] for r in al)} |")
    return out


def trigger_timing(runs) -> list[str]:
    out = ["| seed | group | n | trigger delay median / p90 (s) | trigger - first P3 crossing, median / p90 (s) | P3 max in the first 1 s after onset, median / p10 (m/s²) | Other motion ended ≤ 3 s before onset |",
           "|---:|---|---:|---|---|---|---:|"]
    for d in runs:
        al = [r for r in d["events"] if r["alerted"]]
        groups = [("all alerted", al),
                  ("slowest 10 %, first own capture alerted", [r for r in al if r["tail"] and r["alerting_capture_index"] == 0
                                                              and r["first_overlap_owner"] == "this"])]
        for name, sel in groups:
            gap = [r["trigger_delay_s"] - r["p3_cross_after_onset_s"] for r in sel if r["p3_cross_after_onset_s"] is not None]
            prev = sum(1 for r in sel if r["prev_other"] and r["prev_other"]["end_before_onset_s"] <= 3)
            out.append(f"| {d['seed']} | {name} | {len(sel)} | {q(r['trigger_delay_s'] for r in sel)} | {q(gap)} | "
                       f"{q((r['p3_max_first_s'] for r in sel), (50, 10))} | {prev} |")
    return out


def tail_groups(runs, prefix: str):
    """(seed's run, "slow" or "missed", its events in the slowest 10 % or missed whose cause starts with ``prefix``)."""
    for d in runs:
        for grp in ("slow", "missed"):
            sel = [r for r in d["events"] if r["tail"] and r["alerted"] == (grp == "slow") and r["cause"].startswith(prefix)]
            if sel:
                yield d, grp, sel


def busy(runs) -> list[str]:
    out = ["| seed | group | n | what set off the capture covering the onset | its trigger before onset, median (s) | its full window (S = 6) top class |",
           "|---:|---|---:|---|---|---|"]
    for d, grp, sel in tail_groups(runs, "(e)"):
        kinds = Counter(r.get("first_overlap_other_kind") or "no Other motion" for r in sel).most_common(4)
        s6 = Counter(r["first_overlap_steps"][5]["label"] for r in sel if r.get("first_overlap_steps")).most_common(3)
        out.append(f"| {d['seed']} | {grp} | {len(sel)} | {', '.join(f'{k} {n}' for k, n in kinds)} | "
                   f"{q((-r['first_overlap_trigger_rel_s'] for r in sel), (50,))} | {', '.join(f'{k} {n}' for k, n in s6)} |")
    return out


def later_capture(runs) -> list[str]:
    out = ["| seed | group | n | first own capture's full window: Other / a distraction below its threshold / a distraction over it, held by max_mean_other | its trigger after onset, median (s) | the alerting capture's trigger after onset, median (s) |",
           "|---:|---|---:|---|---|---|"]
    for d, grp, sel in tail_groups(runs, "(c)"):
        s6 = [r["first_own_steps"][5] for r in sel if r.get("first_own_steps")]
        oth = sum(x["label"] == "Other" for x in s6)
        below = sum(x["label"] != "Other" and not x["over"] for x in s6)
        over = sum(x["over"] for x in s6)
        out.append(f"| {d['seed']} | {grp} | {len(sel)} | {oth} / {below} / {over} | "
                   f"{q((r['own_triggers_rel_s'][0] for r in sel), (50,))} | "
                   f"{q((r['trigger_delay_s'] for r in sel if r['alerted']), (50,))} |")
    return out


def fmt_steps(steps) -> str:
    return ", ".join(f"S{x['S']} {x['label']} {x['conf']:.2f}" for x in steps[1:]) if steps else "–"


def examples(d, n_per=2) -> list[str]:
    out = ["| seed | drive | class | onset (s) | lasts (s) | cause | trigger after onset (s) | S | latency (s) | class and confidence at S = 2..6 (thresholds 0.9 ×4, 0.39) |",
           "|---:|---|---|---:|---:|---|---|---:|---:|---|"]
    seen = Counter()
    for r in sorted((r for r in d["events"] if r["tail"]), key=lambda r: (r["drive"], r["onset_s"])):
        key = r["cause"][:3]
        if seen[key] >= n_per:
            continue
        seen[key] += 1
        trig = ", ".join(f"{t:+.2f}" for t in r["own_triggers_rel_s"]) or "none"
        t0 = r["first_overlap_trigger_rel_s"]
        if r["first_overlap_owner"] not in ("this", None):
            trig = (f"busy: capture from {t0:+.2f}; own {trig}" if t0 < -1.0
                    else f"first capture {t0:+.2f}, after the end; own {trig}")
        steps = r.get("steps") or r.get("first_own_steps") or r.get("first_overlap_steps")
        out.append(f"| {d['seed']} | {r['drive'].replace('drive seed ', '')} | {r['label']} | {r['onset_s']:.1f} | {r['duration_s']:.1f} | "
                   f"{r['cause']} | {trig} | {r.get('S', '–')} | {r.get('latency_s', 'missed')} | {fmt_steps(steps)} |")
    return out


def write_csv(d, path: Path) -> None:
    cols = ["drive", "label", "onset_s", "duration_s", "alerted", "latency_s", "S", "first_label", "first_conf",
            "trigger_delay_s", "alerting_capture_index", "own_triggers_rel_s", "first_overlap_trigger_rel_s",
            "first_overlap_owner", "p3_cross_after_onset_s", "p3_max_first_s", "tail", "cause", "miss_reason"]
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(cols + [f"S{s}" for s in range(2, 7)])
        for r in d["events"]:
            st = r.get("steps") or r.get("first_own_steps") or []
            w.writerow([json.dumps(r.get(c)) if isinstance(r.get(c), list) else r.get(c, "") for c in cols]
                       + [f"{x['label']} {x['conf']:.3f}" for x in st[1:]])


LEVER_HEAD = ("| lever | median / p95 (s) | p90 (s) | first alerts ≤ 3.5 s (of all distractions) | event recall | "
              "first-alert class (Phone = Texting) | false alerts (/h) | repeat |", "|---|---|---:|---:|---:|---|---|---:|")
ORACLE_HEAD = ("| detector | triggers / h | no own trigger | busy at onset | trigger delay p50 / p90 / p95 (s) | "
               "oracle at S = 2: median / p95 (s), ≤ 3.5 s of all | oracle at S = 3: median / p95 (s), ≤ 3.5 s of all |",
               "|---|---:|---:|---:|---|---|---|")


def lever_row(r: dict) -> str:
    return (f"| {r['lever']} | {r['median_s']:.2f} / {r['p95_s']:.2f} | {r['p90_s']:.2f} | {r['within_3_5_s_of_all']:.3f} | "
            f"{r['event_recall']:.4f} | {r['class_accuracy']:.4f} ({r['class_accuracy_phone_eq_texting']:.4f}) | "
            f"{r['false_alerts']} ({r['false_alerts_per_hour']:.2f}) | {r['repeat_alerts']} |")


def oracle_row(r: dict) -> str:
    t, o2, o3 = r["trigger_delay_s"], r["oracle_S2"], r["oracle_S3"]
    return (f"| {r['setting']} | {r['triggers_per_hour']} | {r['no_own_trigger']} | {r['detector_busy_at_onset']} | "
            f"{t['50']} / {t['90']} / {t['95']} | {o2['median_s']} / {o2['p95_s']}, {o2['within_3_5_s_of_all']:.3f} | "
            f"{o3['median_s']} / {o3['p95_s']}, {o3['within_3_5_s_of_all']:.3f} |")


def run_table(path: Path, key: str, head: tuple[str, str], row) -> list[str]:
    """levers.py's (key "levers") or oracle.py's (key "settings") output as a Markdown table."""
    d = json.loads(path.read_text())
    return [f"seed {d['seed']}, {d['hours']:g} h", "", *head, *(row(r) for r in d[key])]


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("runs", nargs="*")
    p.add_argument("--csv-dir")
    p.add_argument("--levers", nargs="*", default=[], help="levers.py outputs: their tables only")
    p.add_argument("--oracle", nargs="*", default=[], help="oracle.py outputs: their tables only")
    a = p.parse_args(argv)
    for x in a.levers:
        print("\n".join(run_table(Path(x), "levers", LEVER_HEAD, lever_row)) + "\n")
    for x in a.oracle:
        print("\n".join(run_table(Path(x), "settings", ORACLE_HEAD, oracle_row)) + "\n")
    runs = [json.loads(Path(x).read_text()) for x in a.runs]
    if not runs:
        return 0
    for title, lines in [("first alerts", overview(runs)), ("causes", causes(runs)), ("by class", by_class(runs)),
                         ("steps of S = 6 first alerts", steps_of_s6(runs)), ("S = 3 confusion", confusion_s3(runs)),
                         ("trigger timing", trigger_timing(runs)), ("detector busy", busy(runs)),
                         ("later capture", later_capture(runs))] + [
                            (f"examples seed {d['seed']}", examples(d)) for d in runs]:
        print(f"\n### {title}\n")
        print("\n".join(lines))
    if a.csv_dir:
        for d in runs:
            write_csv(d, Path(a.csv_dir) / f"events_seed{d['seed']}.csv")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
