"""Would looming help as a second, independent measurement fused with the lifted head's line-of-sight rate?
From loom.py's per-frame rows (--rows): correlation of the two errors, and the RMS / p95 error of the fixed
inverse-variance blend w * looming + (1 - w) * head for the height measure (w from the two RMS errors).
usage: fuse.py ROWS.json"""
import json
import sys

import numpy as np

rows = [r for r in json.load(open(sys.argv[1])) if np.isfinite(r["los_height_lift"])]
e_h = np.array([r["los_head"] - r["los_true"] for r in rows])
e_l = np.array([r["los_height_lift"] - r["los_true"] for r in rows])
rms = lambda e: np.sqrt((e ** 2).mean())  # noqa: E731
w = rms(e_h) ** 2 / (rms(e_h) ** 2 + rms(e_l) ** 2)
for name, sel in (("all", np.ones(len(rows), bool)), ("walk-by", np.array([r["walkby"] for r in rows])),
                  ("shipped coming, true not", np.array([r["ship"] and not r["true"] for r in rows]))):
    b = w * e_l[sel] + (1 - w) * e_h[sel]
    print(f"{name}: n {sel.sum()} corr(head err, height-looming err) {np.corrcoef(e_h[sel], e_l[sel])[0, 1]:.2f}; "
          f"head {rms(e_h[sel]):.2f} / {np.percentile(abs(e_h[sel]), 95):.2f}; looming {rms(e_l[sel]):.2f} / "
          f"{np.percentile(abs(e_l[sel]), 95):.2f}; blend w {w:.2f}: {rms(b):.2f} / {np.percentile(abs(b), 95):.2f} (RMS / p95 m/s)")
