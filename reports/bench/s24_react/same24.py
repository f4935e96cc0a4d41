"""Two trees' traces of the same recorded inputs (frame24.py, the bench's robot scenario on its simulated clock),
compared command by command: every frame's state, reason, distance (to the bit), command and its kind, the
per-person log, and every CAN frame the runtime handed to the bus in each frame and tick (id and bytes, E2E counter
and CRC included). Prints the counts of each command kind, the first differences if any, and exits 1 on any.

    python reports/bench/s24_react/same24.py BASE.json MINE.json [--out RESULT.txt]
"""
from __future__ import annotations

import argparse
import json
import sys
from collections import Counter
from pathlib import Path


def commands(trace: list) -> Counter:
    """How many frames sent each kind of command, and how many CAN frames frames and ticks sent."""
    c = Counter(f"frame:{e['kind']}" for e in trace if "frame" in e and e["kind"])
    c["can frames sent in frames"] = sum(len(e["sent"]) for e in trace if "frame" in e)
    c["can frames sent in ticks"] = sum(len(e["sent"]) for e in trace if "tick_after_frame" in e)
    return c


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("base")
    ap.add_argument("mine")
    ap.add_argument("--out", default="")
    a = ap.parse_args()
    runs = [json.loads(Path(p).read_text()) for p in (a.base, a.mine)]
    traces = [r["trace"] for r in runs]
    lines = [f"base: {runs[0]['tree']} ({a.base})", f"mine: {runs[1]['tree']} ({a.mine})",
             f"{runs[0]['seconds']:g} s simulated; entries (frames and commanding ticks): {len(traces[0])} / "
             f"{len(traces[1])}; trace digests {runs[0]['trace_digest'][:16]} / {runs[1]['trace_digest'][:16]}"]
    if "stage_digest" in runs[0] and "stage_digest" in runs[1]:
        lines.append(f"stage digests {runs[0]['stage_digest'][:16]} / {runs[1]['stage_digest'][:16]}: "
                     f"{'the same' if runs[0]['stage_digest'] == runs[1]['stage_digest'] else 'DIFFER'}")
    counts = [commands(t) for t in traces]
    for key in sorted(set(counts[0]) | set(counts[1])):
        lines.append(f"  {key:28s} {counts[0][key]:6d} {counts[1][key]:6d}")
    diffs = [(i, x, y) for i, (x, y) in enumerate(zip(*traces)) if x != y]
    if len(traces[0]) != len(traces[1]):
        diffs.append((min(map(len, traces)), "<length>", "<length>"))
    for i, x, y in diffs[:10]:
        lines.append(f"DIFFERS at entry {i}:\n  base {json.dumps(x)[:300]}\n  mine {json.dumps(y)[:300]}")
    same = not diffs and runs[0].get("status") == runs[1].get("status")
    lines.append(f"loop counters the same: {runs[0].get('status') == runs[1].get('status')}")
    lines.append("RESULT: " + ("every decision, command and CAN byte the same" if same else f"NOT the same "
                                                                                        f"({len(diffs)} entries)"))
    text = "\n".join(lines)
    print(text)
    if a.out:
        Path(a.out).write_text(text + "\n")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
