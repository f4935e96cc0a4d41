"""Which frames make the robot reaction's tail: the commanding frames of a prof_cycle.py run, ranked by their CPU
from the frame's due time to its command (the tick due at the same instant, which runs first, plus the frame's CPU
less the log made after the command), with their stages (ms).

    /work/main/.venv/bin/python reports/bench/s17_perf6/which_frames.py PROF.json [PROF2.json ...] [--top 12]

With several runs of one tree (the same frames: the scenario is deterministic), each frame's figures are the
median over the runs, which a loaded machine's preemption and cache noise move less than any one run's.

Frame k is due at k/30 s and the 100 Hz ticks at j/100 s: every third frame (k % 3 == 0) has tick 10k/3 due at the
same instant, run before it (bench/robot_cycle.py's _schedule). CPU only: the bench's wall clock adds preemption.
"""
from __future__ import annotations

import argparse
import json
from collections import defaultdict
from pathlib import Path

import numpy as np

STAGES = ("tracker", "lifter", "calibration", "monitor", "link_poll", "act", "escape", "plan_escape_turn",
          "backfires", "link_send", "people_log")


def to_command_ms(frames: list, ticks: list) -> list[tuple[int, float, float]]:
    """(frame index, tick-before CPU ms, due -> command CPU ms) of every commanding frame."""
    out = []
    for k, f in enumerate(frames):
        if not f.get("command"):
            continue
        tick_ms = ticks[10 * k // 3]["cpu"] * 1e3 if k % 3 == 0 and 10 * k // 3 < len(ticks) else 0.0
        out.append((k, tick_ms, tick_ms + (f["cpu"] - f.get("people_log", 0.0)) * 1e3))
    return out


def median_run(runs: list[dict]) -> tuple[list, list]:
    """Frames and ticks of ``runs`` with each number the median over the runs (the rest from the first)."""
    def med(items):
        return [{k: (float(np.median([it[k] for it in same])) if isinstance(v, float) else v) for k, v in same[0].items()}
                for same in zip(*items)]
    return med([r["frames"] for r in runs]), med([r["ticks"] for r in runs])


def kind(f: dict) -> str:
    return f"{f['command']}{' +escape plan' if f['escape_planned'] else ''}"


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("prof", nargs="+")
    ap.add_argument("--top", type=int, default=12)
    args = ap.parse_args()
    runs = [json.loads(Path(p).read_text()) for p in args.prof]
    if len({r["digest"] for r in runs}) != 1:
        raise SystemExit("runs of different decisions: not the same frames")
    frames, ticks = median_run(runs)
    rows = to_command_ms(frames, ticks)
    react = np.array([r[2] for r in rows])
    print(f"{len(rows)} commanding frames; due -> command CPU p50 {np.percentile(react, 50):.3f} "
          f"p99 {np.percentile(react, 99):.3f} max {react.max():.3f} ms")
    by = defaultdict(list)
    for k, _, ms in rows:
        by[kind(frames[k])].append(ms)
    print("| kind | n | p50 ms | max ms |\n|---|---|---|---|")
    for name, v in sorted(by.items(), key=lambda kv: -max(kv[1])):
        print(f"| {name} | {len(v)} | {np.median(v):.3f} | {max(v):.3f} |")
    print(f"\ntop {args.top} by due -> command CPU (ms):")
    print("| frame | kind | to command | tick before | " + " | ".join(STAGES) + " |")
    print("|---" * (4 + len(STAGES)) + "|")
    for k, tick_ms, ms in sorted(rows, key=lambda r: -r[2])[:args.top]:
        f = frames[k]
        print(f"| {k} | {kind(f)} | {ms:.2f} | {tick_ms:.2f} | "
              + " | ".join(f"{f.get(s, 0.0) * 1e3:.2f}" for s in STAGES) + " |")


if __name__ == "__main__":
    main()
