"""Onset -> trigger for the shipped detector and simple variants, on the selection cohort's recordings
(seed 1000, 12 subjects x 6 trials x 10 min = 12 h; no held-out data). Triggers are taken greedily with the
shipped 6 s pause (edge_runtime.wearable.detector._greedy_triggers).

    PYTHONPATH=/work/main nice -n 10 /work/main/.venv/bin/python /work/notes/s12-w/detector_variants.py > /work/notes/s12-w/detector_variants.md

Variants: P3 on x (shipped, |ax[T]-ax[T-199]|), the same on all 3 axes (Euclidean norm of the change), and a
shorter look-back (0.5 s). Per variant and threshold: distractions triggered within [start-1 s, end], onset -> first
trigger median / p95, triggers per hour outside every truth event (plain driving) and inside Other motions.
"""
import numpy as np

from edge_runtime.wearable.detector import _greedy_triggers
from firmware_sim.devices.wrist import TRIALS, make_subjects, simulate_trial

recs = [simulate_trial(s, tr, 1000, 10.0) for s in make_subjects(12, 1000) for tr in TRIALS]
hours = sum(len(r.acc_mps2) for r in recs) / 100 / 3600


def feat(a, kind, lag):
    d = np.full(len(a), np.nan)
    if kind == "x":
        d[lag:] = np.abs(a[lag:, 0] - a[:-lag, 0])
    else:
        d[lag:] = np.linalg.norm(a[lag:] - a[:-lag], axis=1)
    return d


print(f"# Detector variants: onset -> trigger on the selection cohort ({hours:.1f} h, 72 recordings)\n")
print("| feature | look-back (s) | threshold (m/s^2) | distractions triggered | onset -> trigger median (s) | p95 (s) | share <= 0.5 s | triggers/h, plain driving | triggers/h in Other motions |")
print("|---|---:|---:|---:|---:|---:|---:|---:|---:|")
for kind, lag, thrs in (("x (shipped P3)", 199, (4.0, 5.0, 6.0)), ("3-axis norm", 199, (5.0, 6.0, 7.0, 8.0)),
                        ("x", 49, (3.0, 4.0, 5.0)), ("3-axis norm", 49, (4.0, 5.0, 6.0))):
    for thr in thrs:
        delays, n_dis, drive_trig, other_trig = [], 0, 0, 0
        for r in recs:
            f = feat(r.acc_mps2.astype(np.float64), "x" if kind.startswith("x") else "3", lag)
            with np.errstate(invalid="ignore"):
                cand = np.flatnonzero(f > thr)
            trig = np.asarray(_greedy_triggers(cand, lag, 600)) / 100.0
            for e in r.events:
                inside = trig[(trig >= e.start_s - 1.0) & (trig <= e.end_s)]
                if e.label != "Other":
                    n_dis += 1
                    if inside.size:
                        delays.append(inside[0] - e.start_s)
            for t in trig:
                owner = [e for e in r.events if e.start_s - 1.0 <= t <= e.end_s]
                if not owner:
                    drive_trig += 1
                elif all(e.label == "Other" for e in owner):
                    other_trig += 1
        d = np.asarray(delays)
        print(f"| {kind} | {(lag + 1) / 100:.1f} | {thr} | {len(d)} of {n_dis} | {np.median(d):.2f} | {np.percentile(d, 95):.2f} | "
              f"{np.mean(d <= 0.5):.2f} | {drive_trig / hours:.1f} | {other_trig / hours:.1f} |")
