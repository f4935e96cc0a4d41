"""Paired ratios against the shipped int8 (ort_ab's ``base+fastrun`` row) from ort_ab.py result files:
per repeat, candidate p50 / shipped p50 of the same repeat; the median and range over repeats.

    python reports/lifter/s19_fold2/paired.py results/ab1.json [...]
"""
import json
import sys

import numpy as np

for f in sys.argv[1:]:
    d = json.load(open(f))
    rows = d["rows"]
    base = np.array(rows["base+fastrun"]["p50s_us"])
    print(f"{f} ({d['utc']}, load {d.get('loadavg')}): " + ", ".join(
        f"{k.split(':')[0]} {np.median(np.array(r['p50s_us']) / base):.3f} "
        f"[{(np.array(r['p50s_us']) / base).min():.2f}-{(np.array(r['p50s_us']) / base).max():.2f}]"
        for k, r in rows.items() if k != "base+fastrun"))
