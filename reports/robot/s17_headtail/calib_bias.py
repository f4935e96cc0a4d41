"""How much of the pnp tail is the calibration's own bias (s17 headtail, step 1).

    PYTHONPATH=. python reports/robot/s17_headtail/calib_bias.py --cache /tmp/headtail --seeds 4 13 17 19

The truth and pnp caches of a seed hold the same worker frames (the head-error tool draws the calibration walk
either way), so per placement the two anchorings differ by the calibration alone. Prints the per-placement
mean factor log error under each, their difference against the fit's camera-height error over the drop and
its pitch error, and the head error by camera height and ray depression for both.
"""
from __future__ import annotations

import numpy as np
from common import cache_arguments, load, replay

from edge_runtime.core.skeleton import HIP


def main() -> None:
    ap = cache_arguments(__doc__)
    a = ap.parse_args()
    rows = []
    for s in a.seeds:
        for pt, pp in zip(load(a.cache, s, "truth"), load(a.cache, s, "pnp")):
            assert np.array_equal(pt["truth_m"], pp["truth_m"], equal_nan=True)
            rt, rp = replay(pt), replay(pp)
            cal, cam = pp["cal"], pp["camera_m"]
            drop = cam[1] - cal.params.floor_y_m - cal.params.ankle_height_m
            # pitch error: the fitted and true directions of the camera -> pelvis ray (median frame), below horizontal
            hip = pp["truth_m"][:, HIP] - cam
            hip = hip[np.isfinite(hip).all(axis=1)]
            true_dir = np.median(hip / np.linalg.norm(hip, axis=1, keepdims=True), axis=0)
            R_true = pt["cal"].A
            fit_dir = cal.A @ np.linalg.solve(R_true, true_dir)   # the same camera ray through the fit
            pitch = np.degrees(np.arcsin(-fit_dir[1] / np.linalg.norm(fit_dir)) - np.arcsin(-true_dir[1]))
            rows.append((rt["log_k_err"].mean(), rp["log_k_err"].mean(), (cal.b[1] - cam[1]) / drop, pitch,
                         np.percentile(rt["err"], 95), np.percentile(rp["err"], 95), cam[1] - cal.params.floor_y_m))
    r = np.array(rows)
    d = r[:, 1] - r[:, 0]
    print(f"{len(r)} placements. per-placement mean factor log error: truth sd {r[:, 0].std():.4f}, pnp sd "
          f"{r[:, 1].std():.4f}; their difference (the calibration's part) sd {d.std():.4f}")
    print(f"  corr(difference, camera height error / drop) {np.corrcoef(d, r[:, 2])[0, 1]:+.2f}; "
          f"corr(difference, pitch error) {np.corrcoef(d, r[:, 3])[0, 1]:+.2f}; pitch error sd {r[:, 3].std():.2f} deg, "
          f"height error / drop sd {r[:, 2].std():.4f}")
    X = np.c_[np.ones(len(r)), r[:, 2], r[:, 3]]
    coef, *_ = np.linalg.lstsq(X, d, rcond=None)
    print(f"  least squares: difference = {coef[0]:+.4f} + {coef[1]:+.3f} * height error/drop + {coef[2]:+.4f} * pitch deg; "
          f"R^2 {1 - np.var(d - X @ coef) / np.var(d):.2f}")
    low = r[:, 6] < 1.5
    print(f"  per-placement p95 head error, median over placements: truth {np.median(r[:, 4]):.3f}, pnp {np.median(r[:, 5]):.3f} m; "
          f"cameras under 1.5 m: truth {np.median(r[low, 4]):.3f}, pnp {np.median(r[low, 5]):.3f} m ({low.sum()} placements)")


if __name__ == "__main__":
    main()
