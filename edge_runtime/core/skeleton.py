"""The 17-joint Human3.6M skeleton and the frames every robot-side module shares.

Joint order and parents are VideoPose3D's (``h36m_skeleton`` after its
``remove_joints``), so a lifter trained here reads and writes the same layout:

====  ==============  ======
idx   joint           parent
====  ==============  ======
0     hip (pelvis)    -
1     right_hip       0
2     right_knee      1
3     right_ankle     2
4     left_hip        0
5     left_knee       4
6     left_ankle      5
7     spine           0
8     thorax          7
9     neck_nose       8
10    head            9
11    left_shoulder   8
12    left_elbow      11
13    left_wrist      12
14    right_shoulder  8
15    right_elbow     14
16    right_wrist     15
====  ==============  ======

Frames (all lengths in metres):

* **robot frame** -- origin on the top surface of the Sawyer's base, ``y`` up,
  ``x`` and ``z`` horizontal, the arm's work side toward ``+z``; the floor is
  ``y = -base_height_m`` (0.914 m on the standard pedestal). Right-handed.
  The dissertation's calibration markers sit on the floor at ``(0, floor, 1)``,
  ``(1, floor, 1)`` and ``(0, floor, 2)``. (The dissertation writes the floor
  as ``+H_base``, i.e. a ``y``-down frame; we keep ``y`` up so that heights
  above the floor are ``y + base_height_m``.)
* **camera frame** -- OpenCV's: ``x`` right, ``y`` down, ``z`` forward along
  the optical axis.
* "Ground-projected" distances drop the ``y`` component of the robot frame.
"""
from __future__ import annotations

import numpy as np

JOINTS: tuple[str, ...] = (
    "hip", "right_hip", "right_knee", "right_ankle", "left_hip", "left_knee", "left_ankle",
    "spine", "thorax", "neck_nose", "head",
    "left_shoulder", "left_elbow", "left_wrist", "right_shoulder", "right_elbow", "right_wrist",
)
PARENTS: tuple[int, ...] = (-1, 0, 1, 2, 0, 4, 5, 0, 7, 8, 9, 8, 11, 12, 8, 14, 15)
N_JOINTS = len(JOINTS)
INDEX: dict[str, int] = {name: i for i, name in enumerate(JOINTS)}

JOINTS_LEFT: tuple[int, ...] = (4, 5, 6, 11, 12, 13)
JOINTS_RIGHT: tuple[int, ...] = (1, 2, 3, 14, 15, 16)

HIP, R_HIP, R_KNEE, R_ANKLE, L_HIP, L_KNEE, L_ANKLE = range(7)
SPINE, THORAX, NECK, HEAD = 7, 8, 9, 10
L_SHOULDER, L_ELBOW, L_WRIST, R_SHOULDER, R_ELBOW, R_WRIST = range(11, 17)


def _mask(value: bool) -> np.ndarray:
    mask = np.full(N_JOINTS, value)
    mask.setflags(write=False)
    return mask


NO_JOINTS = _mask(False)
"""A read-only (17,) mask of no joint, shared: a lifted pose's ``held`` and ``missing`` when no joint is (the usual
frame), so that a reader knows it by identity instead of a pass over it (numpy's per-call cost, at every frame)."""
ALL_JOINTS = _mask(True)
"""A read-only (17,) mask of every joint, shared: the joints usable and observed when all are (the usual frame)."""

ROBOT_UP_AXIS = 1                 # y is up in the robot frame
BASE_HEIGHT_M = 0.914             # top of the Sawyer base above the floor on the standard pedestal


def bones() -> list[tuple[int, int]]:
    """(parent, child) pairs, for drawing and for bone-length checks."""
    return [(p, c) for c, p in enumerate(PARENTS) if p >= 0]
