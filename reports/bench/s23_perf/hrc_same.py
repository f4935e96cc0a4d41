"""Closed-loop equivalence of two trees: two `python -m firmware_sim hrc --json` reports of the same run (scenario
suite, seed, link, perception) must agree in every field but the wall-clock ones (reaction times, the runtime's
CPU share, which a busy machine moves).

    python reports/bench/s23_perf/hrc_same.py BEFORE.json AFTER.json [--out RESULT.txt]

Prints each scenario's decisions side by side (min separation, stops, retractions, productive time, speed
changes, halts, false alarms, zone entries, max state, collision) and every leaf that differs, the timing
ones counted apart; exit 1 if anything but timing differs.
"""
from __future__ import annotations

import argparse
import json
import re
import sys
from collections import Counter

TIMING = re.compile(r"(^|\.)(reaction_ms|runtime_cpu_share)(\.|\[|$)")
"""Leaves measured on the wall clock (or the process's CPU): allowed to differ."""
SHOWN = ("min_separation_m", "stops", "retracts", "productive_s", "speed_changes", "halts", "false_alarms",
         "unreachable", "invalid", "collision", "max_state", "frames")


def leaves(a, b, path=""):
    """Every (path, a, b) where the two reports differ (lists of equal length element by element)."""
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if k not in a or k not in b:
                yield f"{path}.{k}", a.get(k, "<missing>"), b.get(k, "<missing>")
            else:
                yield from leaves(a[k], b[k], f"{path}.{k}")
    elif isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        for i, (x, y) in enumerate(zip(a, b)):
            yield from leaves(x, y, f"{path}[{i}]")
    elif a != b:
        yield path, a, b


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("before")
    ap.add_argument("after")
    ap.add_argument("--out", default="")
    args = ap.parse_args()
    a, b = (json.load(open(p)) for p in (args.before, args.after))
    lines = [f"before: {args.before}", f"after:  {args.after}",
             f"run: scenario {a.get('scenario')} seed {a.get('seed')} link {a.get('link')} perception "
             f"{a.get('perception')}; scenarios {len(a.get('details', []))} / {len(b.get('details', []))}", ""]
    lines.append(f"{'scenario':10s} " + " ".join(f"{k:>16s}" for k in SHOWN))
    for x, y in zip(a.get("details", []), b.get("details", [])):
        lines.append(f"{x['name']:10s} " + " ".join(
            f"{str(x.get(k)):>16s}" if x.get(k) == y.get(k) else f"{x.get(k)}->{y.get(k)}".rjust(16) for k in SHOWN))
    diff = list(leaves(a, b))
    timing = [d for d in diff if TIMING.search(d[0])]
    other = [d for d in diff if not TIMING.search(d[0])]
    lines += ["", f"leaves differing: {len(diff)}; of them wall-clock timing ({TIMING.pattern}): {len(timing)}; "
              f"anything else: {len(other)}"]
    for k, n in Counter(re.sub(r"\[\d+\]", "[]", p) for p, _, _ in timing).most_common():
        lines.append(f"  timing {n:4d}  {k}")
    lines += [f"  DIFFERS {p}: {str(x)[:80]} -> {str(y)[:80]}" for p, x, y in other]
    lines.append("RESULT: " + ("the same decisions (only timing differs)" if not other else "NOT the same"))
    text = "\n".join(lines)
    print(text)
    if args.out:
        open(args.out, "w").write(text + "\n")
    return 1 if other else 0


if __name__ == "__main__":
    sys.exit(main())
