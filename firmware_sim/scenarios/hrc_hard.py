"""The harder scenario suite of ``python -m firmware_sim hrc --scenario hard:N`` (issue 13).

Random scenarios (:func:`hard_scenarios`), deterministic from the seed, each with one to three
workers who do not react to the arm:

* **Paths.** Curved paths with turns (three or four waypoints, rounded corners), stop-and-go
  (a pause of 0.5-2 s part way), a speed per leg between 0.5 and 2.0 m/s (running bursts
  above ISO 13855's 1.6 m/s walking speed), later entries (a second or third worker appears
  up to 3 s after the first).
* **Kinds.** ``approach``: a curved walk to the task's outermost point that stops 0.4-0.9 m
  short of it, and half of them then reach an arm toward the tool (``reach_s``);
  ``pass``: a curved walk past the front of the cell (nearest to the base's axis 1.1-2.0 m);
  ``walkby``: background traffic, a path that stays 2.5-4.5 m from the base's axis and never
  comes within the protective distance (the false-stop figure is counted on these).
* **Camera.** 3-8 m from the cell, 1-3 m high (:func:`firmware_sim.devices.camera.random_placement`),
  so workers leave the picture at its edges.
* **Detector noise** at a real 2D detector's scale (:func:`coco_noise`): per joint, COCO's
  keypoint sigma times the person's pixel size, half white and half slowly drifting, plus a
  systematic offset per joint and person (a detector trained on COCO labels its hips and
  head elsewhere than the H36M joints), on top of the simulated detector's misses, outliers
  and left-right swaps.
* **Occlusion** (:func:`occlude`): a joint whose line of sight passes through another worker's
  body or the arm's links is missed; one hidden behind its own trunk is reported with a
  low score and twice the error, as detectors guess such joints.
* **Calibration** through the runtime's own procedure: the calibration walk is recorded and
  :func:`edge_runtime.robot.calibration.from_recording` finds the three stands itself (no
  true labels).

Collisions are judged as in every hrc scenario: any true joint of any worker within 0.10 m of
the arm's collision spheres or the end effector (:mod:`firmware_sim.scenarios.hrc_world`).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from edge_runtime.core import skeleton as sk
from edge_runtime.robot.hazard import body_spheres

COCO_SIGMAS_H36M = np.array([0.107, 0.107, 0.087, 0.089, 0.107, 0.087, 0.089,   # pelvis, hips, knees, ankles
                             0.093, 0.079, 0.035, 0.035,                        # spine, thorax, neck/nose, head
                             0.079, 0.072, 0.062, 0.079, 0.072, 0.062])         # shoulders, elbows, wrists
"""COCO's per-keypoint sigmas (Lin et al. 2014; shoulder 0.079, elbow 0.072, wrist 0.062, hip 0.107,
knee 0.087, ankle 0.089, nose 0.026, ears 0.035) on the H36M joints; the derived trunk joints take
their neighbours'."""
PERSON_SCALE_OF_HEIGHT = 0.63
"""A standing person's COCO scale s = sqrt(box area) is about 0.63 of his height (box 0.4 H wide)."""
TRUNK = (sk.HIP, sk.SPINE, sk.THORAX)
TRUNK_RADIUS_M = 0.13
"""The trunk that hides a person's own far-side joints (m)."""


@dataclass(frozen=True)
class HardNoise:
    """A real 2D detector's errors, in units of COCO's keypoint sigmas (see the module docstring)."""

    sigma_scale: float = 1.0
    """Per-axis error sd = this x COCO sigma x the person's pixel scale: 1.0 is a detector whose
    mean keypoint similarity (OKS) is about 0.8, a good one (COCO keypoint AP about 0.75)."""
    offset_scale: float = 0.5
    """Systematic offset per joint and person, sd in the same units."""
    drift_tau_s: float = 0.5
    """Time constant of the slowly varying half of the error (s)."""
    self_occluded_score: float = 0.35
    """Score of a joint hidden behind its own trunk (it is guessed, with twice the error)."""


def coco_noise(camera, joints_m: np.ndarray, keypoints: np.ndarray, height_m: float, rng: np.random.Generator,
               noise: HardNoise = HardNoise()) -> np.ndarray:
    """``keypoints`` (T, 17, 3) of one person with a real detector's error added to x, y (pixels):
    COCO sigma x the person's pixel scale (his COCO scale s in metres over the depth of his pelvis,
    times the focal length), half white, half AR(1) drift, plus a fixed offset per joint."""
    kp = keypoints.copy()
    T = len(kp)
    depth = camera.to_camera(joints_m[:, sk.HIP])[:, 2]
    with np.errstate(invalid="ignore", divide="ignore"):
        s_px = np.where(depth > 0.1, camera.intrinsics.fx_px * PERSON_SCALE_OF_HEIGHT * height_m / depth, np.nan)
    sd = noise.sigma_scale * COCO_SIGMAS_H36M[None, :] * s_px[:, None]            # (T, 17) px
    a = math.exp(-1.0 / (noise.drift_tau_s * camera.rate_hz))
    drift = np.empty((T, 17, 2))
    x = rng.normal(size=(17, 2))
    for t in range(T):
        x = a * x + math.sqrt(1 - a * a) * rng.normal(size=(17, 2))
        drift[t] = x
    err = (rng.normal(size=(T, 17, 2)) + drift) * math.sqrt(0.5) * sd[..., None]
    offset = rng.normal(size=(17, 2)) * noise.offset_scale * COCO_SIGMAS_H36M[:, None]
    err += offset[None] * s_px[:, None, None]
    kp[..., :2] += np.nan_to_num(err)
    outside = ~camera.in_image(kp[..., :2])
    kp[outside] = [np.nan, np.nan, 0.0]
    return kp


def _ray_blocked(eye: np.ndarray, points: np.ndarray, centres: np.ndarray, radii: np.ndarray) -> np.ndarray:
    """(N,) whether the segment from ``eye`` to each point (N, 3) passes through one of the spheres
    (M, 3)/(M,) on its way (not at the point itself: the last 5 cm are left out)."""
    d = points - eye                                                   # (N, 3)
    L = np.linalg.norm(d, axis=1)
    u = d / np.maximum(L, 1e-9)[:, None]
    rel = centres[None] - eye                                          # (1, M, 3)
    t = (rel * u[:, None]).sum(-1)                                     # (N, M) along the ray
    perp = np.linalg.norm(rel - t[..., None] * u[:, None], axis=-1)
    return ((perp < radii[None]) & (t > 0) & (t < L[:, None] - 0.05)).any(1)


def occlude(eye_m, joints_m: np.ndarray, present: np.ndarray, arm_spheres=None) -> tuple[np.ndarray, np.ndarray]:
    """For one camera frame: (W, 17) joints hidden by another worker or the arm, and (W, 17)
    joints hidden behind their own trunk. ``joints_m`` (W, 17, 3) robot frame, ``present`` (W,),
    ``arm_spheres`` (centres (K, 3), radii (K,)) or None."""
    eye = np.asarray(eye_m, float)
    W = len(joints_m)
    hidden = np.zeros((W, 17), bool)
    behind_self = np.zeros((W, 17), bool)
    for w in range(W):
        if not present[w]:
            continue
        blockers = [body_spheres(joints_m[o]) for o in range(W) if o != w and present[o]]
        if arm_spheres is not None:
            blockers.append(arm_spheres)
        if blockers:
            c = np.concatenate([b[0] for b in blockers])
            r = np.concatenate([b[1] for b in blockers])
            hidden[w] = _ray_blocked(eye, joints_m[w], c, r)
        own = joints_m[w, list(TRUNK)]
        others = np.array([j not in TRUNK for j in range(17)])
        behind_self[w, others] = _ray_blocked(eye, joints_m[w, others], own, np.full(len(TRUNK), TRUNK_RADIUS_M))
    return hidden, behind_self & ~hidden
