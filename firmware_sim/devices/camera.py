"""The simulated camera and 2D keypoint detector that watch the worker.

Camera
------
The dissertation's camera is one 100 deg wide-angle webcam about 6 m from the robot,
aimed at the work cell. :data:`CANONICAL` is its pinhole model: 1280 x 720 pixels,
``F = 640 / tan(50 deg)`` = 537.0 px, principal point at the image centre -- the camera the
lifter is trained for (the manifest's ``camera``). A :class:`Camera` adds a placement
(extrinsics: robot frame -> camera frame, ``x_cam = R x_robot + t``, OpenCV axes x right,
y down, z forward) and optionally OpenCV's radial/tangential distortion
(``k1, k2, p1, p2, k3``; projection by ``cv2.projectPoints``). :meth:`Camera.look_at`
places it; :func:`random_placement` draws placements as in the dissertation: 3-8 m
(horizontally) from the work cell, 1-3 m above the floor, aimed at the cell. Frame rates:
30 Hz (the lifter's rate) or 5.8 Hz (the dissertation's pipeline); :func:`resample` moves
a trajectory between rates.

Detector
--------
:func:`detect` turns joints seen by a camera into what a 2D pose detector
(Detectron2-like) reports per frame, (T, 17, 3) = x, y (pixels), score:

* Gaussian noise whose size is fixed on the body: ``sigma_m`` (2 cm) on the person,
  i.e. ``F * sigma_m / depth`` pixels -- a person twice as far is half as big in the
  image and so are the detector's errors -- times a per-joint factor (COCO's keypoint
  sigmas: wrists and ankles are harder than shoulders and hips), never below
  ``min_sigma_px``. Half the variance is white (frame-to-frame jitter), half slowly
  varying (AR(1) with time constant ``drift_tau_s``).
* Outliers: with probability ``p_outlier`` per joint and frame the point lands up to
  ``outlier_px`` away (scaled like the noise), with a lower score; with ``p_swap`` per
  frame the left and right limbs are swapped (a classic detector confusion).
* Missed joints: ``p_miss`` per joint and frame, in short bursts (``miss_burst_frames``);
  the whole person is missed with ``p_miss_frame``. A missed joint has score 0 and NaN
  coordinates. Joints outside the image or behind the camera are missed too.
* Scores: about 0.9 for a clean joint, falling with the joint's error.
* A real detector's scale (``coco_k`` > 0, :data:`REAL_DETECTOR`): the noise of joint ``j``
  is ``coco_k * COCO_SIGMAS[j] * s`` pixels, ``s`` the square root of the person's bounding
  box area in the image, as COCO's keypoint similarity (OKS) measures detectors; with
  ``coco_k`` = 1 the mean OKS is about 0.8, a good 2019-2023 detector. ``offset_sd_m`` adds a
  systematic offset per joint and person (a detector's hip is not the hip joint centre), fixed
  for the whole sequence. :func:`occlude` hides what a nearer person covers.

``fmt="coco"`` reports the 17 COCO keypoints instead (eyes and ears placed on the head by
:func:`edge_runtime.robot.keypoints.h36m_to_coco_3d`), so that the runtime's COCO -> H36M
mapping is exercised. :func:`write_jsonl` writes what the runtime reads
(:func:`edge_runtime.robot.keypoints.read_keypoints_jsonl`), one frame per line::

    {"t": s, "frame": k, "format": "h36m"|"coco", "people": [{"id": 0, "keypoints": [[x, y, score] x 17]}]}

with ``null`` coordinates for a missed joint and ``"people": []`` when nobody was detected.
"""
from __future__ import annotations

import itertools
import json
import math
import os
import warnings
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from edge_runtime.core import skeleton as sk
from edge_runtime.robot.keypoints import CameraModel, h36m_to_coco_3d, normalize_screen

WIDTH_PX, HEIGHT_PX = 1280, 720
HFOV_DEG = 100.0
F_PX = (WIDTH_PX / 2) / math.tan(math.radians(HFOV_DEG / 2))
CANONICAL = CameraModel(F_PX, F_PX, WIDTH_PX / 2, HEIGHT_PX / 2, WIDTH_PX, HEIGHT_PX)
"""The lifter's camera: 1280 x 720, 100 deg horizontal field of view, no distortion."""
RATES_HZ = (30.0, 5.8)
CELL_TARGET_M = (0.0, 1.0 - sk.BASE_HEIGHT_M, 0.9)
"""Where placed cameras aim by default: 1 m above the floor, 0.9 m in front of the Sawyer base."""
TYPICAL_WEBCAM_DIST = (-0.30, 0.09, 0.0, 0.0, -0.01)
"""Barrel distortion of a typical 100 deg webcam (k1, k2, p1, p2, k3), for tests and demos."""

# per-joint difficulty (H36M order), from COCO's keypoint sigmas (shoulder 0.079, elbow 0.072,
# wrist 0.062, hip 0.107, knee 0.087, ankle 0.089, nose 0.026) relative to the shoulders, with
# the hands and feet made harder (they move fastest and blur); derived torso joints average theirs.
JOINT_NOISE = np.array([1.0, 1.1, 1.1, 1.3, 1.1, 1.1, 1.3, 1.0, 0.9, 0.6, 1.1,
                        0.9, 1.1, 1.5, 0.9, 1.1, 1.5])


@dataclass(frozen=True)
class Camera:
    """Intrinsics + extrinsics. ``R`` (3, 3) and ``t`` (3,) map robot-frame metres to camera-frame metres."""

    intrinsics: CameraModel = CANONICAL
    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    t: np.ndarray = field(default_factory=lambda: np.zeros(3))
    rate_hz: float = 30.0

    @classmethod
    def look_at(cls, eye_m, target_m=CELL_TARGET_M, intrinsics: CameraModel = CANONICAL, roll_deg: float = 0.0,
                rate_hz: float = 30.0) -> "Camera":
        """A camera at ``eye_m`` (robot frame) whose optical axis passes through ``target_m``, image
        "up" as close to the robot's +y as possible, then rolled by ``roll_deg`` about the axis."""
        eye, target = np.asarray(eye_m, float), np.asarray(target_m, float)
        z = target - eye
        if not np.isfinite(z).all() or np.linalg.norm(z) < 1e-6:
            raise ValueError("look_at: eye and target must be distinct finite points")
        z /= np.linalg.norm(z)
        x = np.cross(z, [0.0, 1.0, 0.0])             # image right = forward x world-up
        if np.linalg.norm(x) < 1e-6:
            raise ValueError("look_at: the optical axis must not be vertical")
        x /= np.linalg.norm(x)
        y = np.cross(z, x)                            # image down; (x, y, z) right-handed
        R = np.stack([x, y, z])
        r = math.radians(roll_deg)
        roll = np.array([[math.cos(r), -math.sin(r), 0], [math.sin(r), math.cos(r), 0], [0, 0, 1]])
        R = roll @ R
        return cls(intrinsics, R, -R @ eye, float(rate_hz))

    @property
    def position_m(self) -> np.ndarray:
        """The optical centre in the robot frame."""
        return -self.R.T @ self.t

    def with_intrinsics(self, intrinsics: CameraModel) -> "Camera":
        """The same placement with other intrinsics (e.g. with distortion)."""
        return Camera(intrinsics, self.R, self.t, self.rate_hz)

    def to_camera(self, points_m) -> np.ndarray:
        """Robot-frame points (..., 3) -> camera-frame points (..., 3), metres."""
        return np.asarray(points_m, float) @ self.R.T + self.t

    def to_robot(self, points_cam_m) -> np.ndarray:
        """Camera-frame points (..., 3) -> robot frame."""
        return (np.asarray(points_cam_m, float) - self.t) @ self.R

    def project(self, points_m) -> np.ndarray:
        """Pixels (..., 2) of robot-frame points (..., 3), distortion included (``cv2.projectPoints``);
        points less than 5 cm in front of the camera are NaN."""
        import cv2

        p = np.asarray(points_m, float)
        cam = self.to_camera(p).reshape(-1, 3)
        out = np.full((len(cam), 2), np.nan)
        front = cam[:, 2] > 0.05
        if front.any():
            uv, _ = cv2.projectPoints(cam[front].reshape(-1, 1, 3), np.zeros(3), np.zeros(3),
                                      self.intrinsics.K, self.intrinsics.dist_array)
            out[front] = uv.reshape(-1, 2)
        return out.reshape(p.shape[:-1] + (2,))

    def in_image(self, uv) -> np.ndarray:
        """(...,) whether pixels lie inside the image."""
        uv = np.asarray(uv, float)
        with np.errstate(invalid="ignore"):
            return ((uv[..., 0] >= 0) & (uv[..., 0] < self.intrinsics.width_px)
                    & (uv[..., 1] >= 0) & (uv[..., 1] < self.intrinsics.height_px))

    def to_dict(self) -> dict:
        """JSON-ready: intrinsics (as the runtime's camera files), R, t, position and rate."""
        return {**self.intrinsics.to_dict(), "R": self.R.tolist(), "t_m": self.t.tolist(),
                "position_m": self.position_m.tolist(), "rate_hz": self.rate_hz}


def random_placement(rng: np.random.Generator, target_m=CELL_TARGET_M, distance_m=(3.0, 8.0),
                     height_m=(1.0, 3.0), azimuth_deg=(-110.0, 110.0), aim_jitter_m: float = 0.3,
                     roll_sd_deg: float = 2.0, intrinsics: CameraModel = CANONICAL, rate_hz: float = 30.0) -> Camera:
    """A camera as in the dissertation: ``distance_m`` from the cell (horizontal), ``height_m`` above the
    floor, at an azimuth about the cell measured from +z (the work side), aimed at the cell (+- jitter)."""
    tgt = np.asarray(target_m, float)
    d = rng.uniform(*distance_m)
    az = math.radians(rng.uniform(*azimuth_deg))
    eye = np.array([tgt[0] + d * math.sin(az), rng.uniform(*height_m) - sk.BASE_HEIGHT_M, tgt[2] + d * math.cos(az)])
    aim = tgt + rng.normal(0.0, aim_jitter_m, 3) * np.array([1.0, 0.5, 1.0])
    return Camera.look_at(eye, aim, intrinsics, rng.normal(0.0, roll_sd_deg), rate_hz)


def resample(joints_m: np.ndarray, from_hz: float, to_hz: float) -> np.ndarray:
    """Linear interpolation of a trajectory (T, ...) from one frame rate to another (same start time)."""
    j = np.asarray(joints_m, float)
    t_old = np.arange(len(j)) / from_hz
    t_new = np.arange(int(math.floor(t_old[-1] * to_hz + 1e-9)) + 1) / to_hz
    flat = j.reshape(len(j), -1)
    out = np.stack([np.interp(t_new, t_old, flat[:, k]) for k in range(flat.shape[1])], 1)
    return out.reshape((len(t_new),) + j.shape[1:])


# --- the detector -------------------------------------------------------------------------------
@dataclass(frozen=True)
class DetectorNoise:
    """How a 2D pose detector errs. Lengths on the body in metres, in the image in pixels."""

    sigma_m: float = 0.02            #: position noise on the body (m, 1 sd), before the per-joint factor
    min_sigma_px: float = 0.8        #: noise floor in pixels
    drift_tau_s: float = 0.5         #: time constant of the slowly varying half of the noise (s)
    p_outlier: float = 0.005         #: chance per joint and frame of a gross error
    outlier_m: float = 0.35          #: size of a gross error on the body (m, uniform up to this)
    p_swap: float = 0.003            #: chance per frame that left and right are swapped
    p_miss: float = 0.005            #: chance per joint and frame that a burst of misses starts
    miss_burst_frames: int = 4       #: mean length of a burst of misses (frames)
    p_miss_frame: float = 0.003      #: chance per frame that the person is not detected at all
    coco_k: float = 0.0              #: > 0: noise sd = coco_k * COCO sigma * sqrt(box area) (px), not sigma_m
    offset_sd_m: float = 0.0         #: systematic per-joint offset on the body (m, 1 sd), fixed per sequence

    def scaled(self, k: float) -> "DetectorNoise":
        """Noise and error rates multiplied by ``k`` (0: a perfect detector)."""
        return DetectorNoise(self.sigma_m * k, self.min_sigma_px * k, self.drift_tau_s, self.p_outlier * k,
                             self.outlier_m, self.p_swap * k, self.p_miss * k, self.miss_burst_frames,
                             self.p_miss_frame * k, self.coco_k * k, self.offset_sd_m * k)


PERFECT = DetectorNoise().scaled(0.0)
REAL_DETECTOR = DetectorNoise(coco_k=1.0, offset_sd_m=0.03, p_outlier=0.01, p_swap=0.005, p_miss=0.01,
                              p_miss_frame=0.005)
"""A real 2D detector's scale (module docstring): COCO sigmas at the person's size in the image,
systematic joint offsets, more misses and gross errors than the default."""
COCO_SIGMAS = np.array([0.026, 0.025, 0.025, 0.035, 0.035, 0.079, 0.079, 0.072, 0.072, 0.062, 0.062,
                        0.107, 0.107, 0.087, 0.087, 0.089, 0.089])
"""COCO's per-keypoint sigmas (Ronchi & Perona 2017), COCO-17 order."""
COCO_SIGMAS_H36M = np.array([0.107, 0.107, 0.087, 0.089, 0.107, 0.087, 0.089, 0.093, 0.079, 0.026, 0.035,
                             0.079, 0.072, 0.062, 0.079, 0.072, 0.062])
"""The same for H36M-17 (pelvis and spine from the hips and shoulders, head from the ears)."""

_SWAP = np.arange(17)
_SWAP[list(sk.JOINTS_LEFT)] = sk.JOINTS_RIGHT
_SWAP[list(sk.JOINTS_RIGHT)] = sk.JOINTS_LEFT
_COCO_SWAP = np.array([0, 2, 1, 4, 3, 6, 5, 8, 7, 10, 9, 12, 11, 14, 13, 16, 15])   # COCO-17 left <-> right


def _bursts(rng: np.random.Generator, shape: tuple[int, int], p_start: float, mean_len: int) -> np.ndarray:
    """(T, J) bool: runs of ~mean_len frames starting with probability p_start per cell."""
    start = rng.random(shape) < p_start
    out = np.zeros(shape, bool)
    for t, j in zip(*np.nonzero(start)):
        out[t: t + 1 + rng.poisson(max(mean_len - 1, 0)), j] = True
    return out


def detect(camera: Camera, joints_m: np.ndarray, rng: np.random.Generator, noise: DetectorNoise = DetectorNoise(),
           fmt: str = "h36m") -> np.ndarray:
    """Detector output (T, 17, 3): x, y (pixels of ``camera``), score, for robot-frame joints (T, 17, 3)
    sampled at the camera's rate. Missed joints: NaN coordinates, score 0 (see the module docstring)."""
    if fmt not in ("h36m", "coco"):
        raise ValueError(f"fmt: expected 'h36m' or 'coco', got {fmt!r}")
    j = np.asarray(joints_m, float)
    if j.ndim != 3 or j.shape[1:] != (17, 3):
        raise ValueError(f"joints_m: expected (T, 17, 3), got {j.shape}")
    pts = h36m_to_coco_3d(j) if fmt == "coco" else j
    T = len(pts)
    depth = camera.to_camera(pts)[..., 2]
    uv = camera.project(pts)
    f = camera.intrinsics.fx_px
    per_joint = JOINT_NOISE if fmt == "h36m" else np.ones(17)
    with np.errstate(invalid="ignore", divide="ignore"):
        px_per_m = np.where(depth > 0.05, f / depth, np.nan)
    if noise.offset_sd_m:
        uv = uv + rng.normal(0.0, noise.offset_sd_m, (1, 17, 2)) * px_per_m[..., None]
    if noise.coco_k > 0:  # OKS-scaled: COCO sigma of the joint times the person's size in the image
        with np.errstate(invalid="ignore"):
            span = np.nanmax(uv, axis=1) - np.nanmin(uv, axis=1)                            # (T, 2)
        size_px = np.sqrt(np.maximum(span[:, 0] * span[:, 1], 1.0))
        sigmas = COCO_SIGMAS_H36M if fmt == "h36m" else COCO_SIGMAS
        sigma = np.maximum(noise.coco_k * sigmas[None, :] * size_px[:, None], noise.min_sigma_px)
    else:
        sigma = np.maximum(noise.sigma_m * px_per_m * per_joint, noise.min_sigma_px)   # (T, 17)
    # half white jitter, half AR(1) drift
    a = math.exp(-1.0 / (max(noise.drift_tau_s, 1e-6) * camera.rate_hz))
    drift = np.empty((T, 17, 2))
    x = rng.normal(size=(17, 2))
    innov = rng.normal(size=(T, 17, 2)) * math.sqrt(1 - a * a)
    for t in range(T):
        x = a * x + innov[t]
        drift[t] = x
    err = (rng.normal(size=(T, 17, 2)) + drift) * math.sqrt(0.5) * sigma[..., None]
    outlier = rng.random((T, 17)) < noise.p_outlier
    n_out = int(outlier.sum())
    if n_out:
        ang = rng.uniform(0, 2 * math.pi, n_out)
        r = rng.uniform(0.3, 1.0, n_out) * noise.outlier_m * px_per_m[outlier]
        err[outlier] += np.stack([np.cos(ang), np.sin(ang)], 1) * r[:, None]
    det = uv + err
    swap = rng.random(T) < noise.p_swap
    det[swap] = det[swap][:, _SWAP if fmt == "h36m" else _COCO_SWAP]
    # scores: ~0.9 when clean, lower with the error in units of the joint's sigma
    with np.errstate(invalid="ignore"):
        rel = np.nan_to_num(np.linalg.norm(err, axis=-1) / sigma)
    score = np.clip(0.93 - 0.08 * rel + rng.normal(0, 0.03, (T, 17)), 0.05, 1.0)
    missed = _bursts(rng, (T, 17), noise.p_miss, noise.miss_burst_frames)
    missed |= (rng.random(T) < noise.p_miss_frame)[:, None]
    missed |= ~camera.in_image(det) | ~np.isfinite(det).all(-1)
    det[missed] = np.nan
    score[missed] = 0.0
    return np.concatenate([det, score[..., None]], axis=-1)



def occlude(keypoints: list[np.ndarray], depth_m: list[np.ndarray], rng: np.random.Generator,
            p_hidden: float = 0.85, shrink: float = 0.7) -> list[np.ndarray]:
    """Several people's detector output ((T, 17, 3) each, same frames) with what a nearer person
    covers hidden: a keypoint of a farther person (``depth_m`` (T,) per person: his distance
    from the camera) inside a nearer person's keypoint box, narrowed to ``shrink`` of its width
    (a body is no box), is missed with probability ``p_hidden`` (NaN, score 0)."""
    out = [np.array(k, float) for k in keypoints]
    for a, b in itertools.permutations(range(len(out)), 2):  # a hides b where a is nearer
        front = np.asarray(depth_m[a]) < np.asarray(depth_m[b])
        with warnings.catch_warnings():  # a frame in which a is not seen at all hides nothing
            warnings.simplefilter("ignore", RuntimeWarning)
            lo, hi = np.nanmin(keypoints[a][..., :2], axis=1), np.nanmax(keypoints[a][..., :2], axis=1)
        mid, half = (lo[:, 0] + hi[:, 0]) / 2, (hi[:, 0] - lo[:, 0]) / 2 * shrink
        x, y = out[b][..., 0], out[b][..., 1]
        with np.errstate(invalid="ignore"):
            inside = ((np.abs(x - mid[:, None]) <= half[:, None]) & (y >= lo[:, 1:2]) & (y <= hi[:, 1:2])
                      & front[:, None])
        hidden = inside & (rng.random(inside.shape) < p_hidden)
        out[b][hidden] = [np.nan, np.nan, 0.0]
    return out


def to_model_input(keypoints_px: np.ndarray, camera: Camera | None = None) -> np.ndarray:
    """H36M keypoints (..., 17, 2|3) in pixels of ``camera`` (None: already canonical pixels) -> the lifter's
    normalised canonical coordinates (..., 17, 2): undistorted with ``cv2.undistortPoints`` when needed,
    then ``u/w*2 - 1``, ``v/w*2 - h/w``."""
    px = np.asarray(keypoints_px, float)[..., :2]
    if camera is not None:
        px = camera.intrinsics.to_camera(px, CANONICAL)
    return normalize_screen(px, WIDTH_PX, HEIGHT_PX).astype(np.float32)


def write_jsonl(path: str | os.PathLike, keypoints: np.ndarray, rate_hz: float, fmt: str = "h36m",
                person_id: int = 0, t0_s: float = 0.0) -> Path:
    """Write detector output (T, 17, 3) as JSON lines (module docstring); a frame with every joint missed
    is written with ``"people": []``. Returns the path."""
    kp = np.asarray(keypoints, float)
    p = Path(path)
    p.parent.mkdir(parents=True, exist_ok=True)
    with open(p, "w", encoding="utf-8") as f:
        for k, frame in enumerate(kp):
            seen = np.isfinite(frame[:, :2]).all(1)
            people = []
            if seen.any():
                pts = [[round(float(x), 2), round(float(y), 2), round(float(s), 3)] if ok else [None, None, 0.0]
                       for (x, y, s), ok in zip(frame, seen)]
                people.append({"id": person_id, "keypoints": pts})
            f.write(json.dumps({"t": t0_s + k / rate_hz, "frame": k, "format": fmt,
                                "people": people}) + "\n")
    return p
