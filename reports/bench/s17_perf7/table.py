"""Per-stage CPU (ms) of prof_cycle.py runs: base against after (and optionally a third side), at the frames that
spiked in session 16's runs and over all frames; commanding frames' link_send by kind; every run's digests.

    /work/main/.venv/bin/python reports/bench/s17_perf7/table.py --side base ab2_base_{1,2,3}.json \
        --side after ab2_after_{1,2,3}.json [--side freeze freeze_{1,2,3}.json]

At a frame, a stage's figure is its median over a side's runs (the scenario is deterministic: the same frames).
Over all frames, the runs of a side are pooled (frame 0, the warm-up, left out).
"""
from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

import numpy as np

STAGES = ("tracker", "lifter", "calibration", "monitor", "people_log", "link_poll", "act", "link_send", "backfires")
FRAMES = {928: "calibration", 851: "calibration", 1248: "calibration", 1272: "calibration", 1202: "lifter",
          1739: "lifter", 1298: "lifter", 805: "link_send", 1397: "link_send", 989: "link_send", 1046: "link_send"}


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--side", nargs="+", action="append", required=True, metavar=("NAME", "RUN"))
    args = ap.parse_args()
    sides = {s[0]: [json.loads(Path(p).read_text()) for p in s[1:]] for s in args.side}
    names = list(sides)
    for name, runs in sides.items():
        for r in runs:
            print(f"{name}: digest {r['digest'][:8]}..{r['digest'][-4:]} payload {r['payload_digest'][:8]}.."
                  f"{r['payload_digest'][-4:]}")

    def at(name, i, key):
        return float(np.median([r["frames"][i].get(key, 0.0) for r in sides[name]])) * 1e3

    print("\n### The frames that spiked (per-frame medians over each side's runs, ms)\n")
    print("| frame | stage that spiked | " + " | ".join(f"{n} stage | {n} frame CPU" for n in names) + " |")
    print("|---|---|" + "---|---|" * len(names))
    for i, stage in FRAMES.items():
        cells = " | ".join(f"{at(n, i, stage):.2f} | {at(n, i, 'cpu'):.2f}" for n in names)
        print(f"| {i} | {stage} | {cells} |")

    print("\n### All frames (1..1799 of every run pooled, ms)\n")
    print("| stage | " + " | ".join(f"{n} p50 | {n} p99 | {n} max | {n} mean" for n in names) + " |")
    print("|---|" + "---|---|---|---|" * len(names))
    for key in ("cpu",) + STAGES:
        cells = []
        for n in names:
            v = np.array([f.get(key, 0.0) for r in sides[n] for f in r["frames"][1:]]) * 1e3
            cells.append(f"{np.percentile(v, 50):.3f} | {np.percentile(v, 99):.3f} | {v.max():.2f} | {v.mean():.3f}")
        print(f"| {'frame CPU' if key == 'cpu' else key} | " + " | ".join(cells) + " |")

    print("\n### Frame CPU p99 and max per run (ms)\n")
    for n in names:
        per = [np.array([f["cpu"] for f in r["frames"][1:]]) * 1e3 for r in sides[n]]
        print(f"- {n}: p99 " + ", ".join(f"{np.percentile(v, 99):.2f}" for v in per)
              + "; max " + ", ".join(f"{v.max():.2f} (frame {int(v.argmax()) + 1})" for v in per))

    print("\n### link_send in commanding frames, by command and frames sent (per-frame medians, ms)\n")
    print("| command | frames sent | n | " + " | ".join(f"{n} p50 | {n} max" for n in names) + " |")
    print("|---|---|---|" + "---|---|" * len(names))
    kinds = defaultdict(list)
    for i, f in enumerate(sides[names[0]][0]["frames"]):
        if f.get("command"):
            kinds[(f["command"], f["n_sent"])].append(i)
    for (cmd, n_sent), idx in sorted(kinds.items()):
        cells = []
        for n in names:
            v = np.array([at(n, i, "link_send") for i in idx])
            cells.append(f"{np.median(v):.3f} | {v.max():.3f}")
        print(f"| {cmd} | {n_sent} | {len(idx)} | " + " | ".join(cells) + " |")


if __name__ == "__main__":
    main()
