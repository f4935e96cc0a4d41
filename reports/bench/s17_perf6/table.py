"""Per-stage CPU (ms) of prof_cycle.py runs, base against after, for ordinary, commanding and escape frames and the
ticks that plan an escape: each kind's frame CPU p50 / p99 / mean and each stage's mean (and p50 over the frames it
ran in), pooled over the runs of a side; and each run's digests.

    /work/main/.venv/bin/python reports/bench/s17_perf6/table.py --base ab_base_*.json --after ab_after_*.json
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

STAGES = ("tracker", "lifter", "rays", "calibration", "monitor", "separation", "people_log", "link_poll", "act",
          "escape", "escape_people", "plan_escape_turn", "backfires", "link_send")
KINDS = {"ordinary frames (no command, no escape plan)": lambda f: not f.get("command") and not f["escape_planned"],
         "commanding frames without an escape plan": lambda f: f.get("command") and not f["escape_planned"],
         "escape frames (plan_escape_turn ran)": lambda f: f["escape_planned"]}


def pooled(paths: list[str]) -> tuple[dict, list]:
    runs = [json.loads(Path(p).read_text()) for p in paths]
    kinds = {k: [f for r in runs for f in r["frames"] if keep(f)] for k, keep in KINDS.items()}
    kinds["ticks planning an escape"] = [t for r in runs for t in r["ticks"] if t["escape_planned"]]
    return kinds, [(Path(p).name, r["digest"], r["payload_digest"]) for p, r in zip(paths, runs)]


def ms(v, q=None) -> float:
    v = np.asarray(v, float) * 1e3
    return float(v.mean() if q is None else np.percentile(v, q)) if v.size else float("nan")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--base", nargs="+", required=True)
    ap.add_argument("--after", nargs="+", required=True)
    args = ap.parse_args()
    sides = {"base": pooled(args.base), "after": pooled(args.after)}
    for side, (_, digests) in sides.items():
        for name, d, p in digests:
            print(f"{side} {name}: decision digest {d[:8]}..{d[-4:]}, payload digest {p[:8]}..{p[-4:]}")
    for kind in sides["base"][0]:
        b, a = sides["base"][0][kind], sides["after"][0][kind]
        print(f"\n### {kind}: n {len(b)} / {len(a)}\n")
        print("| ms | base p50 | base p99 | base mean | after p50 | after p99 | after mean |\n|---|---|---|---|---|---|---|")
        print(f"| frame CPU | {ms([f['cpu'] for f in b], 50):.3f} | {ms([f['cpu'] for f in b], 99):.3f} | "
              f"{ms([f['cpu'] for f in b]):.3f} | {ms([f['cpu'] for f in a], 50):.3f} | "
              f"{ms([f['cpu'] for f in a], 99):.3f} | {ms([f['cpu'] for f in a]):.3f} |")
        for s in STAGES:
            vb, va = [f.get(s, 0.0) for f in b], [f.get(s, 0.0) for f in a]
            if any(vb) or any(va):
                print(f"| {s} | {ms(vb, 50):.3f} | {ms(vb, 99):.3f} | {ms(vb):.3f} | {ms(va, 50):.3f} | "
                      f"{ms(va, 99):.3f} | {ms(va):.3f} |")


if __name__ == "__main__":
    main()
