"""Time budget of the first alert on DEVELOPMENT drives (drive-eval seeds 5 and 1, distraction drives only).

    PYTHONPATH=/work/main nice -n 10 /work/main/.venv/bin/python /work/notes/s12-w/timebudget.py HOURS SEED[,SEED] OUT_PREFIX

The runtime's own decisions (WearableLoop with the shipped config and int8 step model, as
firmware_sim.scenarios.early_tuning.decide runs it, which tests/sim/test_early_tuning.py holds equal to
drive-eval's replay), scored by early_tuning.breakdown. Then, for the capture that alerted first (else the
first capture) of each distraction, the calibrated, class-weighted probabilities after S = 1..6 and why each
step before the first alert did not alert under the shipped policy.
"""
import json
import sys
from collections import Counter

import numpy as np

from edge_runtime import config
from edge_runtime.wearable import alerts, classifier, detector, loop, sources  # noqa: F401
from edge_runtime.wearable.classifier import Engine, needed_frames
from edge_runtime.wearable.detector import detect_triggers
from edge_runtime.wearable.labels import DISTRACTIONS
from firmware_sim.scenarios.drive_eval import held_out_drives
from firmware_sim.scenarios.early_tuning import breakdown, decide


def pct(v, q):
    v = np.asarray([x for x in v if x is not None and np.isfinite(x)], float)
    return float(np.percentile(v, q)) if v.size else float("nan")


def main(hours, seeds, out):
    cfg = config.load(None)
    eng = Engine.from_params(cfg.model)
    pol = cfg.alerts
    man = {int(k): v for k, v in eng.entry["early"]["min_confidence_by_steps"].items()}
    thr = {s: (pol.min_confidence_by_steps[s - 1] if pol.min_confidence_by_steps[s - 1] >= 0 else man[s])
           for s in range(1, 7)}
    w = np.asarray(pol.class_weights)
    classes = list(eng.classes)
    other = classes.index("Other")
    rows, all_events, false_alerts = [], [], []
    for seed in seeds:
        drives = [d for d in held_out_drives(hours, seed, 0.0, 30.0)]
        dec = decide(drives, eng, cfg)
        b = breakdown(drives, dec, cfg.detector.pre_frames, 100)
        all_events += b["events"]
        false_alerts += b["false_alerts"]
        for drive, ds in zip(drives, dec):
            trig = detect_triggers(drive.acc_mps2, cfg.detector)
            truth = [e for e in drive.events if e["label"] in DISTRACTIONS]
            for e in truth:
                # the captures of this distraction (trigger within [start - 1 s, end]), first one
                own = [t for t in trig if e["start_s"] - 1.0 <= t / 100 <= e["end_s"]]
                if not own:
                    continue
                t0 = own[0]
                x = drive.acc_mps2[t0 - 100:t0 + 600]
                if len(x) < 700:
                    continue
                p = np.stack([eng.classify_prefix(x[:needed_frames(s)], s) for s in range(1, 7)]) * w
                p /= p.sum(1, keepdims=True)
                mine = [d for d in ds if abs(d["t_trigger_s"] - t0 / 100) < 0.006]
                alerted = [d for d in mine if d["status"] in ("preliminary", "alert", "confirmed", "revised")]
                first = min(alerted, key=lambda d: d["t_alert_s"]) if alerted else None
                status6 = next((d["status"] for d in mine if d["steps"] == 6), None)
                rows.append({"seed": seed, "label": e["label"], "onset_s": e["start_s"], "dur_s": e["end_s"] - e["start_s"],
                             "trigger_delay_s": t0 / 100 - e["start_s"], "probs": p.tolist(),
                             "first_steps": first["steps"] if first else None,
                             "first_label": first["label"] if first else None,
                             "first_t_alert_s": first["t_alert_s"] if first else None, "status6": status6,
                             "continued": any(d["status"] == "continued" for d in mine)})
    json.dump({"events": all_events, "rows": rows, "false_alerts": false_alerts}, open(out + ".json", "w"))
    # ---- report
    L = [f"# Time budget of the first alert, development drive-eval seeds {seeds}, {hours:g} h each (distraction drives only)", "",
         f"Shipped config: thresholds by S {thr}, earliest_alert_step {pol.earliest_alert_step}, max_mean_other "
         f"{pol.max_mean_other}, class weights {list(w)}; model {eng.name}, step model {eng.streaming}.", ""]
    ev = all_events
    alerted = [r for r in ev if "first_steps" in r]
    td = [r["trigger_delay_s"] for r in ev]
    on2al = [r["onset_to_alert_s"] for r in alerted]
    ftd = [r["first_trigger_delay_s"] for r in alerted]
    tr2al = [r["onset_to_alert_s"] - r["first_trigger_delay_s"] for r in alerted]
    L += [f"{len(ev)} distractions, {len(alerted)} alerted (event recall {len(alerted) / len(ev):.3f}), "
          f"class right {np.mean([r['first_correct'] for r in alerted]):.3f}; {len(false_alerts)} false alerts.", "",
          "| segment | median (s) | p95 (s) | n |", "|---|---:|---:|---:|",
          f"| onset -> first trigger (any capture of the distraction) | {pct(td, 50):.2f} | {pct(td, 95):.2f} | {sum(x is not None for x in td)} |",
          f"| onset -> trigger of the capture that alerted first | {pct(ftd, 50):.2f} | {pct(ftd, 95):.2f} | {len(ftd)} |",
          f"| trigger -> first alert frame | {pct(tr2al, 50):.2f} | {pct(tr2al, 95):.2f} | {len(tr2al)} |",
          f"| onset -> first alert frame | {pct(on2al, 50):.2f} | {pct(on2al, 95):.2f} | {len(on2al)} |", "",
          f"Share of first alerts whose capture is not the distraction's first capture: "
          f"{np.mean([abs(r['first_trigger_delay_s'] - r['trigger_delay_s']) > 0.005 for r in alerted]):.3f}", "",
          "| first alert at S | n | share | class right | onset -> alert median (s) | p95 (s) |", "|---:|---:|---:|---:|---:|---:|"]
    by = Counter(r["first_steps"] for r in alerted)
    for s in sorted(by):
        rr = [r for r in alerted if r["first_steps"] == s]
        L.append(f"| {s} | {len(rr)} | {len(rr) / len(alerted):.3f} | {np.mean([r['first_correct'] for r in rr]):.3f} | "
                 f"{pct([r['onset_to_alert_s'] for r in rr], 50):.2f} | {pct([r['onset_to_alert_s'] for r in rr], 95):.2f} |")
    L += ["", f"Missed: {Counter(r['missed'] for r in ev if 'missed' in r)}", ""]
    # why it waited: per S < first_steps, on the first capture when it is the one that alerted
    L += ["## Why each earlier step did not alert (the distraction's first capture, when it is the one that alerted first)", "",
          "Reasons in the policy's order: S = 1 (earliest_alert_step = 2); top class Other; confidence below the step's "
          "threshold (split by whether the top class was right); max_mean_other (S >= 3).", "",
          "| S | steps passed | S=1 rule | top Other | below thr, top right | below thr, top wrong | mean-Other rule / other |",
          "|---:|---:|---:|---:|---:|---:|---:|"]
    y_of = {c: i for i, c in enumerate(classes)}
    reasons = {s: Counter() for s in range(1, 6)}
    for r in rows:
        fs = r["first_steps"]
        if fs is None or abs((r["first_t_alert_s"] or 0) - r["onset_s"] - 0) < 0:
            continue
        same = next((a for a in alerted if a["drive"] and abs(a["start_s"] - r["onset_s"]) < 1e-6
                     and abs(a["first_trigger_delay_s"] - r["trigger_delay_s"]) < 0.006), None)
        if same is None:
            continue
        p = np.asarray(r["probs"])
        for s in range(1, fs):
            top, cf = int(p[s - 1].argmax()), float(p[s - 1].max())
            if s < pol.earliest_alert_step:
                reasons[s]["S=1 rule"] += 1
            elif top == other:
                reasons[s]["top Other"] += 1
            elif cf < thr[s]:
                reasons[s]["below, right" if top == y_of[r["label"]] else "below, wrong"] += 1
            else:
                reasons[s]["mean-Other/other"] += 1
    for s in range(1, 6):
        c = reasons[s]
        L.append(f"| {s} | {sum(c.values())} | {c['S=1 rule']} | {c['top Other']} | {c['below, right']} | {c['below, wrong']} | {c['mean-Other/other']} |")
    # what a perfect or a looser policy could get from the same first captures (ignoring the event logic)
    L += ["", "## Bound from the first capture alone (each distraction's first capture; first S >= S_min whose top class is "
          "not Other with confidence >= t; onset -> that S's frame)", "",
          "| S_min | t | alerted | class right | onset -> alert median (s) | p95 (s) | share <= 2.0 s |", "|---:|---:|---:|---:|---:|---:|---:|"]
    for smin in (1, 2):
        for t in (0.0, 0.5, 0.7, 0.9, "shipped"):
            lat, ok = [], []
            for r in rows:
                p = np.asarray(r["probs"])
                for s in range(smin, 7):
                    tt = thr[s] if t == "shipped" else t
                    if p[s - 1].argmax() != other and p[s - 1].max() >= tt:
                        lat.append(r["trigger_delay_s"] + (needed_frames(s) - 1 - 100) / 100)
                        ok.append(p[s - 1].argmax() == y_of[r["label"]])
                        break
            lat = np.asarray(lat)
            L.append(f"| {smin} | {t} | {len(lat) / len(rows):.3f} | {np.mean(ok):.3f} | {np.median(lat):.2f} | "
                     f"{np.percentile(lat, 95):.2f} | {np.mean(lat <= 2.0):.3f} |")
    L += ["", "Trigger delay (onset -> first trigger) per class (first captures):", "",
          "| class | n | median (s) | p95 (s) | share <= 0.5 s | share > 1.5 s |", "|---|---:|---:|---:|---:|---:|"]
    for c in DISTRACTIONS:
        v = np.asarray([r["trigger_delay_s"] for r in rows if r["label"] == c])
        L.append(f"| {c} | {len(v)} | {np.median(v):.2f} | {np.percentile(v, 95):.2f} | {np.mean(v <= 0.5):.2f} | {np.mean(v > 1.5):.2f} |")
    open(out + ".md", "w").write("\n".join(L) + "\n")
    print("\n".join(L))


if __name__ == "__main__":
    main(float(sys.argv[1]), [int(s) for s in sys.argv[2].split(",")], sys.argv[3])
