"""Diff two `firmware_sim hrc --json` reports field by field: every path whose value differs (lists of scenarios
by index). Usage: compare_hrc.py BEFORE.json AFTER.json"""
import json
import sys
from collections import Counter


def walk(a, b, path, out):
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            if k not in a or k not in b:
                out.append((f"{path}.{k}", "missing on one side", None)); continue
            walk(a[k], b[k], f"{path}.{k}", out)
    elif isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
        for i, (x, y) in enumerate(zip(a, b)):
            walk(x, y, f"{path}[{i}]", out)
    elif a != b:
        out.append((path, a, b))

A, B = (json.load(open(p)) for p in sys.argv[1:3])
out = []
walk(A, B, "", out)
n = len(A.get("details", []))
print(f"scenarios {n} / {len(B.get('details', []))}; differing leaves: {len(out)}")
import re

kinds = Counter(re.sub(r"\[\d+\]", "[]", p) for p, _, _ in out)
for k, c in kinds.most_common():
    print(f"  {c:5d}  {k}")
for p, a, b in out[:15]:
    print("   e.g.", p, str(a)[:80], "->", str(b)[:80])
