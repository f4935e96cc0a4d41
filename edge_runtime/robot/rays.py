"""The viewing rays of a person's 2D keypoints, in the lifter's camera frame.

A person the lifter cannot lift (a joint missing for longer than it holds one, the first frames
of his window) is still on the picture: each keypoint he shows is a ray from the camera centre,
in the same camera frame the lifter's joints are in (the canonical camera's, x right, y down,
z forward), so the calibration that maps lifted joints into the robot frame maps these rays
too. :func:`edge_runtime.robot.hazard.ray_separation_m` bounds where he can be from them.
"""
from __future__ import annotations

import numpy as np

from edge_runtime.core.skeleton import N_JOINTS
from edge_runtime.robot.keypoints import CameraModel, to_h36m


def keypoint_rays(keypoints, camera: CameraModel | None, canonical: CameraModel, keypoint_format: str = "h36m",
                  min_score: float = 0.3) -> np.ndarray:
    """(17, 3) ray directions (x/z, y/z, 1) in the canonical camera's frame of keypoints (17, 3)
    (x, y pixels of ``camera``, score; (17, 2): every score 1) in ``keypoint_format``; NaN rows for
    a keypoint not seen (non-finite, or scored below ``min_score``, the lifter's threshold).
    ``camera`` None: the keypoints are canonical-camera pixels already."""
    kp = np.asarray(keypoints, dtype=np.float64)
    out = np.full((N_JOINTS, 3), np.nan)
    if kp.ndim != 2 or kp.shape[0] != N_JOINTS or kp.shape[1] not in (2, 3):
        return out
    if kp.shape[1] == 2:
        with_score = np.ones((N_JOINTS, 3))
        with_score[:, :2] = kp
        kp = with_score
    kp = to_h36m(kp, keypoint_format)
    finite = np.isfinite(kp)
    ok = finite[:, 0] & finite[:, 1] & (kp[:, 2] >= min_score)
    if not ok.any():
        return out
    px = kp[ok, :2] if camera is None else camera.to_camera(kp[ok, :2], canonical)
    c = canonical
    rays = np.ones((len(px), 3))
    rays[:, 0] = (px[:, 0] - c.cx_px) / c.fx_px
    rays[:, 1] = (px[:, 1] - c.cy_px) / c.fy_px
    finite = np.isfinite(rays)
    rays[~(finite[:, 0] & finite[:, 1])] = np.nan
    out[ok] = rays
    return out


def lifter_rays(lifter, keypoints) -> np.ndarray:
    """:func:`keypoint_rays` with a ``StreamingLifter``'s cameras, keypoint format and score threshold."""
    return keypoint_rays(keypoints, lifter.camera, lifter.canonical_camera, lifter.keypoint_format,
                         lifter.params.min_score)
