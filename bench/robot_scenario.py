"""The robot bench's people: two simulated workers whose paths make the runtime send every kind of command.

Made by the parent process with firmware_sim (:func:`prepare_workers`) and handed to the
measuring child (:mod:`bench.robot_cycle`) as an ``.npz`` file, as the wearable bench hands
over its drive. Robot frame: x, y up (floor at y = -0.914), z toward the work side; the
arm's base at the origin.

* **The reacher** (1.75 m) walks at 1.4 m/s from 2.6 m in front of the base to 0.95 m from it,
  stands there working with his hands toward the arm (reaching 0.5 m, now and then 0.7 m) for
  ``REACH_STAND_S``, walks back and waits ``AWAY_STAND_S``: on the way in the arm slows (speed
  overrides from speed-and-separation monitoring), stops and retracts; while he stands within
  reach the runtime plans escape turns about the base (``plan_escape_turn``, the costly path);
  once he is away it resumes.
* **The passer-by** (1.65 m) walks across the cell and back at 0.6 m/s on a zigzag 1.75-2.05 m
  in front of the base, in and out of the band where the arm's speed limit changes: a speed
  override in most frames that cross a step of ``[zones] speed_step`` while the reacher is away,
  and a second person in every frame.

The mix was chosen to give many commands a second, not to be typical of a cell: the shipped
configuration sends a command only when what the arm should do changes. How many of each kind
a run gives depends on the configuration (with ``[zones] stop_time_scales`` on, the arm works
slowly closer in and the reacher makes it retract rather than stop, so stops become rare) and, in
real time on a loaded machine, on the load (late frames merge changes): the report of a run says
what it got. Both workers are always in the camera's view, noise-free (score 1): no lift is ever
invalid, so the unseen-person path is not timed. The paths repeat until the run's length is covered.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np

CAMERA_POSITION_M = (0.0, 1.0, 7.0)
"""Robot-frame camera position (m): 7 m in front of the base, 1.0 m above its top (1.9 m above the
floor), so both workers stay in the 100-degree canonical image."""
CAMERA_FROM_ROBOT = np.array([[1.0, 0.0, 0.0], [0.0, -1.0, 0.0], [0.0, 0.0, -1.0]])
"""Rotation robot -> OpenCV camera axes for a camera looking along the robot's -z."""
FRAME_RATE_HZ = 30.0
REACH_XZ_M = (0.2, 0.95)
"""Where the reacher stands (robot x, z; m): within the arm's reach (whole-body separation below
``[zones] reach_retract_m`` with his hands out), so level 2 lasts and escape turns are planned."""
AWAY_XZ_M = (0.3, 2.6)
"""Where the reacher comes from and goes back to (m): beyond the speed-scaling band's far edge."""
REACH_STAND_S = 2.0
"""How long the reacher stands at the arm per visit (s): escape turns are planned again every
``[robot_loop] escape_replan_s`` (0.5 s) while it lasts."""
AWAY_STAND_S = 7.0
"""How long the reacher waits away from the arm (s): the passer-by's speed overrides happen then."""
PASS_XZ_M = ((-2.4, 2.05), (-1.8, 1.75), (-1.2, 2.05), (-0.6, 1.75), (0.0, 2.05), (0.6, 1.75), (1.2, 2.05),
             (1.8, 1.75), (2.4, 2.05))
"""The passer-by's zigzag across the cell (m), walked there and back: its near corners put him at the
slow end of the speed-scaling band, its far ones beyond it."""


def project(joints_m: np.ndarray, camera, keypoint_format: str = "h36m") -> np.ndarray:
    """Pixels (..., 17, 3: u, v, score 1) of robot-frame H36M joints seen by ``camera`` (a
    ``CameraModel``, or a manifest entry's ``camera`` dict) at :data:`CAMERA_POSITION_M`, in
    ``keypoint_format`` order ("coco": eyes and ears placed on the head as the simulated camera does)."""
    from edge_runtime.robot.keypoints import CameraModel, h36m_to_coco_3d

    cam = camera if isinstance(camera, CameraModel) else CameraModel.from_dict(camera)
    pts = h36m_to_coco_3d(joints_m) if keypoint_format == "coco" else np.asarray(joints_m, float)
    p = (pts - np.asarray(CAMERA_POSITION_M)) @ CAMERA_FROM_ROBOT.T
    if cam.dist:  # what a lens with this distortion puts on the sensor
        import cv2

        uv, _ = cv2.projectPoints(p.reshape(-1, 3), np.zeros(3), np.zeros(3), cam.K, cam.dist_array)
        uv = uv.reshape(p.shape[:-1] + (2,))
    else:
        uv = p[..., :2] / p[..., 2:3] * [cam.fx_px, cam.fy_px] + [cam.cx_px, cam.cy_px]
    return np.concatenate([uv, np.ones(uv.shape[:-1] + (1,))], axis=-1)


def _reacher_cycle(rng: np.random.Generator) -> np.ndarray:
    from firmware_sim.people.human import Body, heading_towards
    from firmware_sim.people.motions import concat, stand, walk, work_at

    body = Body.from_height(1.75)
    toward = heading_towards(REACH_XZ_M, (0.0, 0.0))
    away = heading_towards(REACH_XZ_M, AWAY_XZ_M)
    parts = [walk(body, (AWAY_XZ_M, REACH_XZ_M), 1.4, FRAME_RATE_HZ, rng=rng),
             work_at(body, REACH_XZ_M, toward, REACH_STAND_S, reach_m=0.5, rate_hz=FRAME_RATE_HZ, rng=rng),
             walk(body, (REACH_XZ_M, AWAY_XZ_M), 1.4, FRAME_RATE_HZ, rng=rng),
             stand(body, AWAY_XZ_M, away + np.pi, AWAY_STAND_S, FRAME_RATE_HZ, rng=rng)]
    return np.asarray(concat(parts).joints_m, float)


def _passer_cycle(rng: np.random.Generator) -> np.ndarray:
    from firmware_sim.people.human import Body
    from firmware_sim.people.motions import concat, walk

    body = Body.from_height(1.65)
    there, back = PASS_XZ_M, PASS_XZ_M[::-1]
    return np.asarray(concat([walk(body, there, 0.6, FRAME_RATE_HZ, corner_radius_m=0.3, rng=rng),
                              walk(body, back, 0.6, FRAME_RATE_HZ, corner_radius_m=0.3, rng=rng)]).joints_m, float)


def _repeated(cycle: np.ndarray, n: int, offset: int = 0) -> np.ndarray:
    return cycle[(np.arange(n) + offset) % len(cycle)]


def prepare_workers(out_npz: str | Path, seconds: float, lifter: dict | None, seed: int = 0, camera=None,
                    keypoint_format: str = "h36m") -> Path:
    """Both workers' robot-frame joints ``joints_robot_m`` (T, 2, 17, 3) at 30 Hz for ``seconds`` and,
    when a ``lifter`` (a manifest entry) is shipped, their pixels ``keypoints_px`` (T, 2, 17, 3) seen by
    ``camera`` (a ``CameraModel``; None: the lifter's canonical camera) in ``keypoint_format`` order.
    Uses firmware_sim (parent process only)."""
    rng = np.random.default_rng(seed)
    n = max(1, int(round(seconds * FRAME_RATE_HZ)))
    reacher, passer = _reacher_cycle(rng), _passer_cycle(rng)
    # the passer-by starts mid-crossing, so he is not at the reacher's side of the cell every visit
    joints = np.stack([_repeated(reacher, n), _repeated(passer, n, len(passer) // 3)], axis=1)
    data = {"joints_robot_m": joints}
    if lifter is not None:
        data["keypoints_px"] = project(joints, lifter["camera"] if camera is None else camera, keypoint_format)
    np.savez(out_npz, **data)
    return Path(out_npz)
