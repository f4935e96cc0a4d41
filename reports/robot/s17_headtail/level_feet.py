"""The both-feet rule's threshold (``calibration.ANCHOR_LEVEL_FEET_M``) on cached placements (s17 headtail).

    PYTHONPATH=. python reports/robot/s17_headtail/level_feet.py --cache /tmp/headtail --seeds 4 13 17 19 --method truth --level-m 0.1 0.2 0.3 inf

Taking the lower of two noisy ankles picks the one whose keypoint noise points its ray down: a steeper ray,
a factor too small, the person placed nearer the camera than he is (diagnose.py: 80% of the truth tail's
frames). Each threshold is replayed through the shipped ``Calibration.to_robot``.
"""
from __future__ import annotations

import numpy as np
from common import cache_arguments, load, replay, summary

from edge_runtime.robot import calibration as C


def main() -> None:
    ap = cache_arguments(__doc__)
    ap.add_argument("--level-m", type=float, nargs="+", default=[0.1, 0.2, 0.3, np.inf])
    a = ap.parse_args()
    shipped = C.ANCHOR_LEVEL_FEET_M
    placements = [p for s in a.seeds for p in load(a.cache, s, a.method)]
    try:
        for level in a.level_m:
            C.ANCHOR_LEVEL_FEET_M = level
            rs = [replay(p) for p in placements]
            err, far = [r["err"] for r in rs], [r["farther"] for r in rs]
            le = np.concatenate([r["log_k_err"] for r in rs])
            low = np.concatenate([r["cam_h"] < 1.5 for r in rs])
            e = np.concatenate(err)
            print(f"level {level:g} m: {summary(err, far)}; factor log error mean {le.mean():+.4f} sd {le.std():.4f}; "
                  f"cameras under 1.5 m {np.median(e[low]):.3f} / {np.percentile(e[low], 95):.3f} m")
    finally:
        C.ANCHOR_LEVEL_FEET_M = shipped


def temporal_level_anchor(frames: int, level_m: float):
    """An ``anchor`` for :func:`common.replay` (one person): the shipped median of factors, but the feet's
    level test on the median of the ankles' height difference over the last ``frames`` frames (a raised
    swing foot stays up for a third of a second; a keypoint's noise changes sign), and the lower foot by
    that median's sign."""
    from collections import deque

    from edge_runtime.core.numeric import median_floats
    from edge_runtime.core.skeleton import L_ANKLE, R_ANKLE

    def anchor(cal, J, obs, valid):
        p = cal.params
        diffs, window = deque(maxlen=frames), deque(maxlen=C.ANCHOR_WINDOW_FRAMES)
        out = np.full_like(J, np.nan)
        shipped = C.ANCHOR_LEVEL_FEET_M
        try:
            for t in np.flatnonzero(valid):
                y = (J[t, [L_ANKLE, R_ANKLE]] @ cal.A.T)[:, 1]
                seen = obs[t, [L_ANKLE, R_ANKLE]] & np.isfinite(y)
                if seen.all():
                    diffs.append(float(y[0] - y[1]))
                o = obs[t].copy()
                if seen.all() and abs(median_floats(diffs)) > level_m:   # one foot raised: the lower one alone
                    o[R_ANKLE if median_floats(diffs) < 0 else L_ANKLE] = False
                C.ANCHOR_LEVEL_FEET_M = np.inf                            # else both feet (or the one seen)
                k, reason = C.anchor_factor(J[t], cal.A, cal.b, p, o)
                if reason is None and p.anchor_min_scale < k < p.anchor_max_scale:
                    window.append(k)
                out[t] = cal.apply((median_floats(window) if window else k) * J[t])
        finally:
            C.ANCHOR_LEVEL_FEET_M = shipped
        return out
    return anchor


def main_temporal() -> None:
    ap = cache_arguments(__doc__)
    ap.add_argument("--frames", type=int, nargs="+", default=[5, 9, 15])
    ap.add_argument("--level-m", type=float, nargs="+", default=[0.1, 0.15])
    a = ap.parse_args()
    placements = [p for s in a.seeds for p in load(a.cache, s, a.method)]
    for n in a.frames:
        for level in a.level_m:
            rs = [replay(p, temporal_level_anchor(n, level)) for p in placements]
            le = np.concatenate([r["log_k_err"] for r in rs])
            print(f"temporal level, median of {n} frames, {level:g} m: {summary([r['err'] for r in rs], [r['farther'] for r in rs])}; "
                  f"factor log error mean {le.mean():+.4f} sd {le.std():.4f}")


if __name__ == "__main__":
    import sys
    if "--frames" in sys.argv:
        main_temporal()
    else:
        main()
