"""Session 24 (issue 12): a validation cohort for the recipe's choices, separate from training and from the drives.

    PYTHONPATH=. OMP_NUM_THREADS=1 python reports/wearable/stream_s24/val.py cohort
    PYTHONPATH=. OMP_NUM_THREADS=1 python reports/wearable/stream_s24/val.py probs CKPT_DIR NAME
    PYTHONPATH=. python reports/wearable/stream_s24/val.py causes NAME W HOP_MULT K THR OFF_S

The cohort: ``simulate_cohort(20, seed=VAL_COHORT, 15 min)`` (cohort seed 3; training uses 0, 1, 2; drive-eval's
drivers come from seeds 900000+ and 950000+), 120 recordings, 30 h: the five exp trials hold distractions, the
baseline trial Other motions only. Cached in /work/s9-runs/stream24 (not committed).

``causes`` scores a policy (session 21's policy.py, drive-eval's frame scoring) on the cohort and splits its false
alerts by cause as stream_s23/causes.py does (the Other motion whose span +- 1 s holds the alert, else the hand's
return within 5 s after a distraction's end, else elsewhere), with each Other kind's count of motions, and the
onset -> first alert per distraction class.
"""
from __future__ import annotations

import collections
import json
import sys
from pathlib import Path

import numpy as np
import torch

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parent / "stream_s21"))
from data import load_streams, save_streams  # noqa: E402
from policy import Policy, alerts, score_drives  # noqa: E402
from probs import drive_probs  # noqa: E402

DIR = Path("/work/s9-runs/stream24")
VAL_COHORT = 3
STEM = DIR / f"cohort_seed{VAL_COHORT}"


def probs_path(name: str, w: float) -> Path:
    return DIR / f"probs_{name}_cohort{VAL_COHORT}_w{w:g}.npz"


def cause_of(t: float, dis: list[dict], oth: list[dict]) -> str | None:
    """None: the alert is a distraction's (drive-eval credits frames from 2 s before the start to the end)."""
    if any(e["start_s"] - 2.0 <= t <= e["end_s"] for e in dis):
        return None
    o = next((e for e in oth if e["start_s"] - 1.0 <= t <= e["end_s"] + 1.0), None)
    if o:
        return o.get("kind", "Other")
    return "return" if any(e["end_s"] < t <= e["end_s"] + 5.0 for e in dis) else "elsewhere"


def main(argv: list[str]) -> int:
    what = argv[0]
    if what == "cohort":
        from firmware_sim.devices.wrist import simulate_cohort

        DIR.mkdir(parents=True, exist_ok=True)
        recs = [(f"subject {r.subject_id} {r.trial}", r.acc_mps2, [e.to_json() for e in r.events],
                 "baseline" if r.trial == "baseline" else "distraction")
                for r in simulate_cohort(20, seed=VAL_COHORT, minutes_per_trial=15.0)]
        save_streams(DIR, STEM.name, recs)
        print(f"{STEM}: {len(recs)} recordings")
        return 0
    recs = load_streams(STEM)
    if what == "probs":
        from models.stream_train import load_stream_checkpoint

        torch.set_num_threads(1)
        model, _ = load_stream_checkpoint(argv[1])
        for w in (3.0, 4.0):
            arrays = {}
            for k, d in enumerate(recs):
                arrays[f"t{k}"], arrays[f"p{k}"] = drive_probs(model, d["acc_mps2"], w, 3)
            np.savez(probs_path(argv[2], w), **arrays)
            print(probs_path(argv[2], w), flush=True)
        return 0
    name, w, hop, k, thr, off = argv[1], float(argv[2]), int(argv[3]), int(argv[4]), float(argv[5]), float(argv[6])
    z = np.load(probs_path(name, w))
    pol = Policy(w, hop, "top", k, thr, off)
    decs = [alerts(z[f"t{i}"], z[f"p{i}"], pol) for i in range(len(recs))]
    figs, _ = score_drives(recs, decs)
    causes, motions, lat = collections.Counter(), collections.Counter(), collections.defaultdict(list)
    for d, dec in zip(recs, decs):
        dis = [e for e in d["events"] if e["label"] != "Other"]
        oth = [e for e in d["events"] if e["label"] == "Other"]
        motions.update(e.get("kind", "Other") for e in oth)
        for a in dec:
            c = cause_of(a["t_alert_s"], dis, oth)
            if c:
                causes[c] += 1
        for e in dis:  # the first alert in [start, end]: the onset -> alert by class
            t = [a["t_alert_s"] for a in dec if e["start_s"] <= a["t_alert_s"] <= e["end_s"]]
            if t:
                lat[e["label"]].append(min(t) - e["start_s"])
    out = {"policy": pol.__dict__, "figures": figs, "false_by_cause": dict(causes.most_common()),
           "other_motions": dict(motions.most_common()),
           "latency_by_class": {c: {"n": len(v), "median_s": round(float(np.median(v)), 3),
                                    "p95_s": round(float(np.percentile(v, 95)), 3)} for c, v in sorted(lat.items())}}
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
