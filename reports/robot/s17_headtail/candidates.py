"""Offline candidates for the anchored depth (s17 headtail, step 2), on cached placements.

    PYTHONPATH=. python reports/robot/s17_headtail/candidates.py --cache /tmp/headtail --seeds 4 13 17 19 --method truth

Each candidate replays a placement's frames (one person, so no association) and is scored as the shipped
``Calibration.to_robot`` is (``common.replay``). ``stance``: while the person stands still, his pelvis's
anchored ground position is the median of its per-frame values since he stopped (the feet are planted, so
the floor crossing's drifting error averages out instead of following him), capped at ``--stance-frames``;
"still" comes from the truth (``oracle``, the candidate's best case) or from the lifter's own pelvis
(``detected``). ``nearer``: of the shipped estimate and the stance one, the one nearer the arm.
"""
from __future__ import annotations

from collections import deque

import numpy as np
from common import WALK_SPEED_MPS, cache_arguments, load, replay, summary

from edge_runtime.core.numeric import median_floats
from edge_runtime.core.skeleton import HIP
from edge_runtime.robot.calibration import ANCHOR_WINDOW_FRAMES, anchor_factor

MIN_STANCE_FRAMES = ANCHOR_WINDOW_FRAMES   # fewer still frames than this: the shipped estimate


def _ground_range(v: np.ndarray) -> float:
    return float(np.hypot(v[0], v[2]))


def stance_anchor(still_of, stance_frames: int, nearer: bool):
    """An ``anchor`` for :func:`common.replay`: ``still_of(cal, J, valid)`` -> (T,) bool, the frames in which
    the person is taken to stand still."""
    def anchor(cal, J, obs, valid):
        p = cal.params
        still = still_of(cal, J, valid)
        out = np.full_like(J, np.nan)
        window, stance = deque(maxlen=ANCHOR_WINDOW_FRAMES), deque(maxlen=stance_frames)
        for t in np.flatnonzero(valid):
            k, reason = anchor_factor(J[t], cal.A, cal.b, p, obs[t])
            hip_ray = cal.A @ J[t, HIP]
            plausible = reason is None and p.anchor_min_scale < k < p.anchor_max_scale
            if plausible:
                window.append(k)
            if not still[t]:
                stance.clear()
            elif plausible:
                stance.append((cal.b + k * hip_ray)[[0, 2]])
            k_now = median_floats(window) if window else k
            if len(stance) >= MIN_STANCE_FRAMES:
                g = np.median(np.array(stance), axis=0)          # the pelvis's ground position (x, z)
                k_st = float(np.hypot(*(g - cal.b[[0, 2]])) / _ground_range(hip_ray))
                if nearer:   # of the two, the one that puts the pelvis nearer the arm's base axis
                    k_now = min((k_now, k_st), key=lambda f: float(np.hypot(*(cal.b + f * hip_ray)[[0, 2]])))
                else:
                    k_now = k_st
            out[t] = cal.apply(k_now * J[t])
        return out
    return anchor


def still_truth(p):
    """The truth's stillness of placement ``p`` (pelvis ground speed under WALK_SPEED_MPS), as a ``still_of``."""
    hip = p["truth_m"][:, HIP][:, [0, 2]]
    speed = np.r_[np.inf, np.linalg.norm(np.diff(hip, axis=0), axis=1) * 30.0]
    return lambda cal, J, valid: speed < WALK_SPEED_MPS


STILL_FRAMES = 10   # the detector compares the lifter's pelvis over the last this many frames with the ten before


def still_detected(radius_m: float):
    """A causal ``still_of``: the person stands still while the median of the lifter's own pelvis (camera ->
    pelvis, robot axes) over the last STILL_FRAMES frames is within ``radius_m`` on the ground of its median
    over the STILL_FRAMES before (the lifter's depth drifts slowly, so its changes show motion even where its
    value is off)."""
    def still_of(cal, J, valid):
        h = J[:, HIP] @ cal.A.T
        out = np.zeros(len(J), bool)
        for t in range(2 * STILL_FRAMES, len(J)):
            a, b = h[t - STILL_FRAMES + 1: t + 1], h[t - 2 * STILL_FRAMES + 1: t - STILL_FRAMES + 1]
            a, b = a[np.isfinite(a).all(axis=1)], b[np.isfinite(b).all(axis=1)]
            if len(a) >= STILL_FRAMES // 2 and len(b) >= STILL_FRAMES // 2:
                d = np.median(a, axis=0) - np.median(b, axis=0)
                out[t] = np.hypot(d[0], d[2]) < radius_m
        return out
    return still_of


def main() -> None:
    ap = cache_arguments(__doc__)
    ap.add_argument("--stance-frames", type=int, default=90)
    ap.add_argument("--radius-m", type=float, nargs="*", default=[0.15, 0.25])
    a = ap.parse_args()
    variants = {"shipped": lambda p: None,
                "stance, oracle still": lambda p: stance_anchor(still_truth(p), a.stance_frames, False),
                "stance nearer, oracle still": lambda p: stance_anchor(still_truth(p), a.stance_frames, True),
                **{f"stance, detected still {r:g} m": (lambda p, r=r: stance_anchor(still_detected(r), a.stance_frames, False))
                   for r in a.radius_m},
                **{f"stance nearer, detected still {r:g} m": (lambda p, r=r: stance_anchor(still_detected(r), a.stance_frames, True))
                   for r in a.radius_m}}
    for name, make in variants.items():
        err, far, walk_err, still_err = [], [], [], []
        for s in a.seeds:
            for p in load(a.cache, s, a.method):
                r = replay(p, make(p))
                err.append(r["err"])
                far.append(r["farther"])
                walk_err.append(r["err"][r["walking"]])
                still_err.append(r["err"][~r["walking"]])
        w, st = np.concatenate(walk_err), np.concatenate(still_err)
        print(f"{name:>32}: {summary(err, far)}; walking {np.median(w):.3f} / {np.percentile(w, 95):.3f}, "
              f"still {np.median(st):.3f} / {np.percentile(st, 95):.3f} m")


if __name__ == "__main__":
    main()
