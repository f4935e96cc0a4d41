"""Shared by the s17 headtail scripts: load a cache (``cache.py``) and replay a placement's frames
through an anchoring, per frame: the head's ground error, how much farther from the arm it is placed,
the applied factor against the factor that puts the pelvis at its true range, and which ankle anchored."""
from __future__ import annotations

import pickle
from pathlib import Path

import numpy as np

from edge_runtime.core.skeleton import HEAD, HIP, L_ANKLE, R_ANKLE
from edge_runtime.robot import calibration as C

WALK_SPEED_MPS = 0.3   # a frame whose true pelvis moves faster than this on the ground is "walking"


def cache_arguments(description: str | None = None):
    """The scripts' common command line: ``--cache DIR --seeds S... --method truth|pnp`` (a parser to extend)."""
    import argparse

    ap = argparse.ArgumentParser(description=description)
    ap.add_argument("--cache", required=True, help="cache.py's output directory")
    ap.add_argument("--seeds", type=int, nargs="+", required=True)
    ap.add_argument("--method", help="calibration method of the cache (truth, pnp)")
    return ap


def load(out_dir: str, seed: int, method: str) -> list[dict]:
    return pickle.loads((Path(out_dir) / f"cache_seed{seed}_{method}.pkl").read_bytes())


def ankle_choice(j, A, observed) -> str:
    """Which ankle ray(s) :func:`calibration.anchor_factor` uses: 'L', 'R', 'both' (its own rule)."""
    rays = j[[L_ANKLE, R_ANKLE]] @ A.T
    ok = np.isfinite(rays).all(axis=1)
    seen = ok & np.asarray(observed, bool)[[L_ANKLE, R_ANKLE]]
    ok = seen if seen.any() else ok
    if not ok.any():
        return "none"
    if ok.all() and abs(rays[0, 1] - rays[1, 1]) <= C.ANCHOR_LEVEL_FEET_M:
        return "both"
    if ok.all():
        return "L" if rays[0, 1] <= rays[1, 1] else "R"
    return "L" if ok[0] else "R"


def replay(p: dict, anchor=None) -> dict:
    """Per scored frame (valid, not warming up) of placement ``p``: ``anchor(cal, joints, observed)`` ->
    robot-frame joints per frame in order (default: the shipped ``Calibration.to_robot``)."""
    cal = p["cal"]
    cal._anchor = None
    J, obs, warm, truth = p["joints"], p["observed"], p["warming"], p["truth_m"]
    valid = np.isfinite(J).all(axis=(1, 2))
    out = np.full_like(J, np.nan)
    if anchor is None:
        for k in np.flatnonzero(valid):
            out[k] = cal.to_robot(J[k][None], obs[k][None])[0]
    else:
        out = anchor(cal, J, obs, valid)
    ok = valid & ~warm
    head, th = out[ok, HEAD], truth[ok, HEAD]
    raw_hip = J[ok, HIP] @ cal.A.T
    k_applied = np.linalg.norm(out[ok, HIP] - cal.b, axis=1) / np.linalg.norm(raw_hip, axis=1)
    k_true = np.linalg.norm(truth[ok, HIP] - cal.b, axis=1) / np.linalg.norm(raw_hip, axis=1)
    cam = p["camera_m"]
    hip_xz = truth[:, HIP][:, [0, 2]]
    speed = np.zeros(len(truth))
    speed[1:] = np.linalg.norm(np.diff(hip_xz, axis=0), axis=1) * 30.0
    return {
        "idx": np.flatnonzero(ok),
        "err": np.hypot(*(head - th)[:, [0, 2]].T),
        "farther": np.hypot(head[:, 0], head[:, 2]) - np.hypot(th[:, 0], th[:, 2]),
        "log_k_err": np.log(k_applied / k_true),
        "dist": np.hypot(*(truth[ok, HIP][:, [0, 2]] - cam[[0, 2]]).T),
        "cam_h": np.full(ok.sum(), cal.b[1] - cal.params.floor_y_m),
        "walking": speed[ok] > WALK_SPEED_MPS,
        "label": np.asarray(p["labels"])[ok],
    }


def summary(err, far) -> str:
    err, far = np.concatenate(err), np.concatenate(far)
    return (f"{np.median(err):.3f} / {np.percentile(err, 95):.3f} m; farther > 0 / 0.1 / 0.3 m: "
            f"{np.mean(far > 0):.3f} / {np.mean(far > 0.1):.3f} / {np.mean(far > 0.3):.3f}")
