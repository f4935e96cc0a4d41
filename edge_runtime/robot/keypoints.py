"""2D keypoint inputs for the pose lifter: formats, the COCO-17 -> H36M-17 mapping,
JSON lines, person selection and camera models (numpy + OpenCV, no torch).

Formats
=======
``h36m``: the lifter's own 17 joints, in :mod:`edge_runtime.core.skeleton`'s order.
``coco``: the 17 COCO keypoints that Detectron2, OpenPose (its COCO-17 subset),
MMPose, YOLO-pose and most 2D detectors write::

    0 nose  1 left_eye  2 right_eye  3 left_ear  4 right_ear  5 left_shoulder
    6 right_shoulder  7 left_elbow  8 right_elbow  9 left_wrist  10 right_wrist
    11 left_hip  12 right_hip  13 left_knee  14 right_knee  15 left_ankle  16 right_ankle

A keypoint array is ``(..., 17, 3)``: x, y in image pixels and a detector score in
[0, 1]; ``(..., 17, 2)`` means every score is 1. A NaN coordinate means "not seen".

COCO-17 -> H36M-17, joint by joint (:func:`coco_to_h36m`)
=========================================================
Limbs are the same points in both sets; the torso and head joints of Human3.6M
have no COCO counterpart and are built from the nearest COCO points:

==  ==============  ===========================================================
0   hip (pelvis)    midpoint of COCO left_hip (11) and right_hip (12): H36M's
                    pelvis is the centre of the hip joints
1-3 right hip, knee, ankle = COCO 12, 14, 16
4-6 left hip, knee, ankle  = COCO 11, 13, 15
7   spine           pelvis + 0.45 * (thorax - pelvis): where the simulated bodies
                    the shipped lifter learnt from put it (firmware_sim.people.human's
                    SPINE_AT); Human3.6M's own skeleton has it at 0.48 (pelvis ->
                    spine 233 mm, spine -> thorax 257 mm)
8   thorax          midpoint of the shoulders (5, 6): H36M's thorax is the base
                    of the neck, between the shoulder joints
9   neck_nose       COCO nose (0): VideoPose3D's joint 9 is the nose
10  head            the top of the head, extrapolated from the ears:
                    ``e + HEAD_UP * (e - thorax)`` with ``e`` the midpoint of the
                    ears, ``HEAD_UP`` = 0.5. With anthropometric proportions
                    (thorax at 0.818 of body height, ears at about 0.93, head top
                    1.0; docs/design.md section 5) the ears lie two thirds of the way from
                    thorax to head top, hence 1/2. When the ears are missing or
                    score under half the eyes' score (a face turned to the camera
                    hides them) the eyes' midpoint stands in for ``e`` (it lies a
                    few cm in front of the ears: up to 7 % of the body's height off
                    in a profile view, so the ears are preferred)
11-13 left shoulder, elbow, wrist  = COCO 5, 7, 9
14-16 right shoulder, elbow, wrist = COCO 6, 8, 10
==  ==============  ===========================================================

A derived joint's score is the lowest score of the points it is made from, and
it is NaN when any of them is NaN: a joint built from a missing point is itself
missing, never invented. :func:`h36m_to_coco_3d` is the inverse used to make
COCO keypoints from a 3D H36M skeleton (the simulator, and the round-trip test):
it places ears and eyes on a head of standard proportions.

JSON lines (:func:`read_keypoints_jsonl`)
=========================================
One object per line (a frame)::

    {"t": 0.033, "frame": 1, "format": "coco",
     "people": [{"id": 0, "keypoints": [[x, y, score], ... 17]}]}

``t`` (s) may be missing when ``frame`` is given (t = frame / fps); ``keypoints``
may also be a flat list ``[x0, y0, s0, x1, ...]`` (51 numbers, or 34 without
scores), and a coordinate may be ``null`` (not seen). ``format`` is optional
and, when present, must agree with the format the reader was asked for.
Blank lines are skipped. Anything else is a :class:`KeypointInputError` naming
the file and the line. A person with fewer than 17 keypoints is passed on as
given (shape (n, 3)): the lifter counts every joint of such a frame as missing
(held for a few frames, then the frame is invalid). :class:`PersonTracker` gives every
person seen a stable id across frames (who is who), so each is lifted with his own
temporal window and judged by the hazard monitor; :class:`PersonSelector` picks one
person to follow (``lift --person largest|confident|id:N``).

Who is who (:class:`PersonTracker`)
===================================
Tracking is part of the input step, on 2D keypoints, because that is where identity is
visible: a person's keypoints move a little between frames,
and nothing downstream can repair a swap (a lifter window holding
two people's frames lifts neither). Each track predicts its keypoints at constant image
velocity; a detection is matched to the track whose prediction is nearest (the median over the
joints, in units of the track's size in the image, so the same gate holds near and far; the
size comes from his bones, so a half-hidden person keeps his). The assignment with the most
pairs and the least cost is searched exhaustively for up to four people in a frame (greedy
beyond: no solver on the box). A track unseen for up to ``max_lost_s`` keeps its id and is
matched again within a gate that grows with the time it was gone (a person occluded while
crossing, or leaving the image and coming back); the exporter's own id, when it sends one, is
kept as ``source_id`` but never trusted over the motion (exporters reuse ids). Detections with
fewer than ``min_joints`` keypoints are not tracked. Measured by ``python -m firmware_sim
crossings`` (reports/lifter/perception.md).

Camera models (:class:`CameraModel`)
====================================
Intrinsics K (pixels), distortion in OpenCV's order (k1, k2, p1, p2[, k3[, k4,
k5, k6[, s1, s2, s3, s4[, tau_x, tau_y]]]]) and the image size. Pixels of a
real camera are undistorted with ``cv2.undistortPoints`` and re-projected with
the lifter's canonical camera (:meth:`CameraModel.to_camera`), then normalised
as VideoPose3D does (:func:`normalize_screen`): ``u/w*2 - 1``, ``v/w*2 - h/w``.
"""
from __future__ import annotations

import itertools
import math
import os
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Iterator, Sequence

import numpy as np

from edge_runtime import config
from edge_runtime.core import skeleton as sk
from edge_runtime.core import strict_json
from edge_runtime.core.memo import Recent
from edge_runtime.core.skeleton import HEAD, HIP, L_SHOULDER, N_JOINTS, NECK, R_SHOULDER, SPINE, THORAX
from edge_runtime.errors import InputError

FORMATS = ("coco", "h36m")
COCO_JOINTS: tuple[str, ...] = (
    "nose", "left_eye", "right_eye", "left_ear", "right_ear", "left_shoulder", "right_shoulder",
    "left_elbow", "right_elbow", "left_wrist", "right_wrist", "left_hip", "right_hip",
    "left_knee", "right_knee", "left_ankle", "right_ankle",
)
C_NOSE, C_L_EYE, C_R_EYE, C_L_EAR, C_R_EAR, C_L_SHOULDER, C_R_SHOULDER = range(7)
C_L_HIP, C_R_HIP = 11, 12

COPIED_FROM_COCO: dict[int, int] = {1: 12, 2: 14, 3: 16, 4: 11, 5: 13, 6: 15, 9: C_NOSE,
                                    11: 5, 12: 7, 13: 9, 14: 6, 15: 8, 16: 10}
"""H36M joint -> the COCO keypoint it is a copy of."""
HEAD_UP = 0.5
"""Head top = ear midpoint + HEAD_UP * (ear midpoint - thorax) (see the module docstring)."""
SPINE_FRACTION = 0.45
"""Spine = pelvis + SPINE_FRACTION * (thorax - pelvis)."""
EYES_FOR_EARS = 0.5
"""The eyes stand in for the ears when the ears score below this fraction of the eyes' score."""

UNDISTORT_CRITERIA = (3, 50, 1e-6)  # cv2.TERM_CRITERIA_COUNT | EPS: 50 iterations or 1e-6
"""Iterations for ``cv2.undistortPoints``: OpenCV's default (5 iterations) leaves up to
0.7 px in the corners of a wide-angle lens (k1 = -0.28); this leaves < 0.01 px."""

# head geometry for h36m_to_coco_3d (m): ears two thirds of the way thorax -> head top
_EAR_HALF_WIDTH_M = 0.075
_EYE_FORWARD_M = 0.08
_EYE_HALF_WIDTH_M = 0.032


MAX_COORDINATE_PX = 1e6
"""A keypoint coordinate beyond this many pixels from the image origin is refused: no camera
has such an image, and the lifter's float32 input would turn it into inf."""
MAX_IMAGE_PX = 100_000
"""A camera image wider or taller than this many pixels is refused (and a focal length
beyond 100 times it)."""
MAX_TIMESTAMP_S = 1e10
"""A frame time beyond +-this is refused (Unix time is 1.7e9 s): time arithmetic on larger
ones (gaps, replay pacing) overflows or loses the frame period to rounding."""
MAX_FRAME = 2**53
"""Frame numbers above this are refused (t = frame / fps must stay exact)."""


class KeypointInputError(InputError):
    """Malformed keypoint input; the message names the file and the line."""


# ---------------------------------------------------------------------------- formats


def as_keypoints(kp, n_joints: int | None = N_JOINTS) -> np.ndarray:
    """``kp`` as float64 (..., J, 3) (x, y, score); (..., J, 2) gets score 1.

    ``n_joints`` None accepts any joint count (the lifter checks it)."""
    a = np.asarray(kp, dtype=np.float64)
    if a.ndim < 2 or a.shape[-1] not in (2, 3) or (n_joints is not None and a.shape[-2] != n_joints):
        want = f"{n_joints}" if n_joints is not None else "J"
        raise ValueError(f"keypoints of shape {a.shape}, expected (..., {want}, 2 or 3)")
    if a.shape[-1] == 2:
        a = np.concatenate([a, np.ones(a.shape[:-1] + (1,))], axis=-1)
    return a


def _weights(rows: dict[int, dict[int, float]]) -> np.ndarray:
    """(17, 17) matrix: H36M joint <- weighted sum of COCO keypoints."""
    w = np.zeros((N_JOINTS, len(COCO_JOINTS)))
    for h, sources in rows.items():
        for c, v in sources.items():
            w[h, c] = v
    return w


def _head_row(pair: tuple[int, int]) -> dict[int, float]:
    """Head top = e + HEAD_UP * (e - thorax), e the midpoint of ``pair`` (ears or eyes)."""
    a, b = (1 + HEAD_UP) / 2, -HEAD_UP / 2
    return {pair[0]: a, pair[1]: a, C_L_SHOULDER: b, C_R_SHOULDER: b}


_F = SPINE_FRACTION / 2
_ROWS = {**{h: {c: 1.0} for h, c in COPIED_FROM_COCO.items()},
         HIP: {C_L_HIP: 0.5, C_R_HIP: 0.5},
         THORAX: {C_L_SHOULDER: 0.5, C_R_SHOULDER: 0.5},
         SPINE: {C_L_HIP: 0.5 - _F, C_R_HIP: 0.5 - _F, C_L_SHOULDER: _F, C_R_SHOULDER: _F}}
W_EARS = _weights({**_ROWS, HEAD: _head_row((C_L_EAR, C_R_EAR))})
"""COCO -> H36M weights with the head from the ears."""
W_EYES = _weights({**_ROWS, HEAD: _head_row((C_L_EYE, C_R_EYE))})
"""The same with the head from the eyes."""


def _sources(w: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(``w != 0``, (H, S) the COCO keypoints each row of ``w`` sums (its nonzero weights, in order) padded with its
    first, (H, S) their weights padded with 0)."""
    rows = [np.flatnonzero(r) for r in w]
    n = max(len(r) for r in rows)
    weights = np.array([np.concatenate([r_w[r], np.zeros(n - len(r))]) for r, r_w in zip(rows, w)])
    return w != 0, np.array([np.concatenate([r, np.repeat(r[:1], n - len(r))]) for r in rows]), weights


def _weighted_sums(filled: np.ndarray, sources: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """``np.einsum("hc,...cd->...hd", w, filled)`` to the bit, from ``w``'s few nonzero weights per row
    (:func:`_sources`): numpy's einsum sums the products one after the other in c's order from +0.0 (pinned on
    random inputs in tests/robot/test_frame_cost_s23.py), and a term of weight 0 adds a zero, which leaves such a
    sum as it is (it is never -0.0: it starts at +0.0). So each row's nonzero terms, in order, from +0.0: the
    same sums, in a few whole-array operations instead of einsum's per-call cost (a frame's largest single call
    after the lifter's model)."""
    terms = filled[..., sources, :] * weights[..., None]        # (..., H, S, 2)
    out = terms[..., 0, :] + 0.0
    for j in range(1, sources.shape[1]):
        out += terms[..., j, :]
    return out


def _map(c: np.ndarray, w: np.ndarray, sources: tuple | None = None, prepared=None) -> np.ndarray:
    """H36M (..., 17, 3) = ``w`` applied to COCO (..., 17, 3); a joint's score is the lowest
    score among its sources, and it is NaN when any source coordinate or score is NaN.

    ``sources`` is ``_sources(w)`` (given for the module's fixed weights): a joint's badness is then
    gathered from its few sources instead of weighed over all 17 (an any: the same booleans). The score
    stays a min over all 17 (inf where unused): a min over only the sources could pick the other zero of
    a -0.0 / 0.0 tie. ``prepared`` is ``_prepared(c)``, when the caller maps ``c`` twice."""
    used, sources, weights = _sources(w) if sources is None else sources
    filled, fin = _prepared(c) if prepared is None else prepared
    out = np.empty(c.shape[:-2] + (len(w), 3))
    out[..., :2] = _weighted_sums(filled, sources, weights)
    out[..., 2] = np.minimum.reduce(np.where(used, c[..., None, :, 2], np.inf), axis=-1)  # np.min's; NaN propagates
    if fin is not None:  # a keypoint not finite (every one is, in most frames: then no joint is made NaN)
        out[~fin[..., sources].all(axis=-1)] = np.nan
    return out


def _prepared(c: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
    """(COCO x, y with non-finite coordinates 0, whether both coordinates are finite, or None when all are) for
    :func:`_map`; both x, y arrays C-contiguous copies (np.where's layout: einsum sums them the same way)."""
    finite = np.isfinite(c[..., :2])
    if finite.all():  # the usual frame: nothing to zero, and no joint to make NaN
        return np.ascontiguousarray(c[..., :2]), None
    return np.where(finite, c[..., :2], 0.0), finite[..., 0] & finite[..., 1]


def coco_to_h36m(kp) -> np.ndarray:
    """COCO-17 (..., 17, 2|3) -> H36M-17 (..., 17, 3), joint by joint as the module docstring says.

    One person's frame (17, 3) is remembered (:data:`_H36M_MEMO`): the person tracker and his lifter convert
    the same keypoints in each frame; the second gets a copy of the first's result."""
    c = as_keypoints(kp)
    key = c.tobytes() if c.shape == (N_JOINTS, 3) else None
    if key is not None and (hit := _H36M_MEMO.get(key)) is not None:
        return hit.copy()
    out = _coco_to_h36m(c)
    if key is not None:
        _H36M_MEMO.put(key, out.copy())
    return out


def _coco_to_h36m(c: np.ndarray) -> np.ndarray:
    """:func:`coco_to_h36m` of float64 (..., 17, 3) ``c``, nothing remembered."""
    prepared = _prepared(c)
    out = _map(c, W_EARS, _SOURCES_EARS, prepared)
    if (out[..., HEAD, 2] >= EYES_FOR_EARS * c[..., _EYES_HEAD_SOURCES, 2].min(axis=-1)).all():
        # everyone's ears score at least half his eyes' score (the eyes' head joint's score is the least of its
        # sources'; a NaN compares False): the ears' heads stand whatever the eyes give, so they are not mapped
        return out
    # the eyes stand in for the ears when they score higher, or when the ears are not there
    from_eyes = _map(c, W_EYES[HEAD:HEAD + 1], _SOURCES_EYES_HEAD, prepared)[..., 0, :]
    ears_score = out[..., HEAD, 2]
    use_eyes = np.isfinite(from_eyes[..., 0]) & ~(ears_score >= EYES_FOR_EARS * from_eyes[..., 2])  # NaN: eyes
    out[..., HEAD, :] = np.where(use_eyes[..., None], from_eyes, out[..., HEAD, :])
    return out


_SOURCES_EARS = _sources(W_EARS)
_SOURCES_EYES_HEAD = _sources(W_EYES[HEAD:HEAD + 1])
_EYES_HEAD_SOURCES = np.flatnonzero(W_EYES[HEAD])
"""The COCO keypoints the eyes' head joint is made from (the eyes and the shoulders)."""

_H36M_MEMO: Recent[np.ndarray] = Recent(16)
""":func:`coco_to_h36m` of the last few (17, 3) frames, by their float64 bytes."""


def to_h36m(kp, fmt: str) -> np.ndarray:
    """Keypoints of format ``fmt`` ("coco" | "h36m") as H36M-17 (..., 17, 3)."""
    if fmt == "coco":
        return coco_to_h36m(kp)
    if fmt == "h36m":
        return as_keypoints(kp)
    raise ValueError(f"unknown keypoint format {fmt!r} (one of {', '.join(FORMATS)})")


def to_h36m_each(kps: Sequence[np.ndarray], fmt: str) -> np.ndarray:
    """:func:`to_h36m` of several people's keypoints ((17, 2|3) each) in one pass: (D, 17, 3). Each person's
    conversion is remembered as :func:`coco_to_h36m` remembers it (his lifter asks for it next). The same
    numbers as one call per person (numpy's per-call cost, not its arithmetic, is most of a person's conversion;
    tests/robot/test_perception_batch_s18.py pins the two together)."""
    # np.array of equal-shape arrays stacks them, in a third of np.stack's time (no per-call checks)
    c = np.array([as_keypoints(kp) for kp in kps]) if len(kps) else np.empty((0, N_JOINTS, 3))
    if fmt == "h36m":
        return c
    if fmt != "coco":
        raise ValueError(f"unknown keypoint format {fmt!r} (one of {', '.join(FORMATS)})")
    out = _coco_to_h36m(c)
    for person_c, person_out in zip(c, out):
        _H36M_MEMO.put(person_c.tobytes(), person_out.copy())
    return out


def h36m_to_coco_3d(joints) -> np.ndarray:
    """COCO-17 points (..., 17, 3) of a 3D H36M-17 skeleton (..., 17, 3), metres, any frame.

    Limbs and nose are copied; ears sit on the line thorax -> head top, two thirds of the
    way up, 7.5 cm either side along the shoulder line; eyes 8 cm in front of the ear
    midpoint (toward the nose) and 3.2 cm either side. Project the result with
    ``cv2.projectPoints`` to get what a COCO detector would report."""
    p = np.asarray(joints, dtype=np.float64)
    out = np.empty(p.shape[:-2] + (17, 3))
    for h, j in COPIED_FROM_COCO.items():
        out[..., j, :] = p[..., h, :]
    thorax, head = p[..., THORAX, :], p[..., HEAD, :]
    centre = thorax + (head - thorax) / (1 + HEAD_UP)
    up = _unit(head - thorax)
    lateral = _unit(_reject(p[..., L_SHOULDER, :] - p[..., R_SHOULDER, :], up))
    forward = _unit(_reject(_reject(p[..., NECK, :] - centre, up), lateral))
    for j, side in ((C_L_EAR, 1), (C_R_EAR, -1)):
        out[..., j, :] = centre + side * _EAR_HALF_WIDTH_M * lateral
    for j, side in ((C_L_EYE, 1), (C_R_EYE, -1)):
        out[..., j, :] = centre + _EYE_FORWARD_M * forward + side * _EYE_HALF_WIDTH_M * lateral
    return out


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.maximum(np.linalg.norm(v, axis=-1, keepdims=True), 1e-12)


def _reject(v: np.ndarray, axis_unit: np.ndarray) -> np.ndarray:
    return v - np.sum(v * axis_unit, axis=-1, keepdims=True) * axis_unit


# ---------------------------------------------------------------------------- JSON lines


@dataclass
class Person:
    keypoints: np.ndarray
    """(J, 3) x, y (pixels), score; J is 17 unless the source sent fewer."""
    id: int | None = None
    """The exporter's track id, when it has one; after :class:`PersonTracker`, the tracker's id."""
    source_id: int | None = None
    """After :class:`PersonTracker`: the exporter's id (None when it sent none)."""


@dataclass
class KeypointFrame:
    t_s: float
    """Frame time (s)."""
    frame: int | None
    people: list[Person]
    format: str


def _fail(where: str, msg: str):
    raise KeypointInputError(f"{where}: {msg}")


def _parse_person(p, i: int, where: str) -> Person:
    if not isinstance(p, dict) or "keypoints" not in p:
        _fail(where, f"people[{i}]: expected an object with 'keypoints'")
    field = f"{where}: people[{i}].keypoints"
    raw = p["keypoints"]
    if not isinstance(raw, list):
        _fail(where, f"people[{i}].keypoints: expected a list")
    if raw and all(isinstance(v, list) for v in raw):
        rows = raw
        if any(len(r) not in (2, 3) for r in rows):
            _fail(where, f"people[{i}].keypoints: each keypoint must be [x, y] or [x, y, score]")
        if len({len(r) for r in rows}) > 1:
            _fail(where, f"people[{i}].keypoints: mixed [x, y] and [x, y, score] entries")
        width = len(rows[0])
    else:
        width = 3 if len(raw) % 3 == 0 and len(raw) != 34 else 2
        if len(raw) % width:
            _fail(where, f"people[{i}].keypoints: a flat list of {len(raw)} numbers is neither x,y,score "
                         "triples nor x,y pairs")
        rows = [raw[k:k + width] for k in range(0, len(raw), width)]
    if len(rows) > N_JOINTS:
        _fail(where, f"people[{i}].keypoints: {len(rows)} keypoints, expected 17")
    xy = strict_json.number_array([r[:2] for r in rows], (len(rows), 2), field, KeypointInputError,
                                  -MAX_COORDINATE_PX, MAX_COORDINATE_PX, nulls=True)
    scores = (strict_json.number_array([r[2] for r in rows], (len(rows),), f"{field} score", KeypointInputError,
                                       0.0, 1.0, nulls=True) if width == 3 else np.ones(len(rows)))
    pid = p.get("id")
    if pid is not None:
        pid = strict_json.integer(pid, f"{where}: people[{i}].id", KeypointInputError, -2**63, 2**63 - 1)
    return Person(np.column_stack([xy, scores]).reshape(len(rows), 3), pid)


def parse_keypoint_line(line: str | bytes, where: str, fmt: str, fps: float = 30.0) -> KeypointFrame | None:
    """One JSON line -> a frame (None for a blank line); ``where`` is "FILE:LINE".

    Every field is checked here, the input's one validation step: ``t`` finite within
    +-``MAX_TIMESTAMP_S``, ``frame`` a non-negative integer, coordinates finite within
    +-``MAX_COORDINATE_PX`` (or null: not seen), scores in [0, 1] (or null), ``id`` a
    64-bit integer; NaN/Infinity literals, non-UTF-8 bytes and deep nesting are refused."""
    if not line.strip():
        return None
    obj = strict_json.loads(line, where, KeypointInputError)
    if not isinstance(obj, dict):
        _fail(where, "expected a JSON object per line")
    line_fmt = obj.get("format", fmt)
    if line_fmt != fmt:
        _fail(where, f"format {line_fmt!r}, but the input was declared {fmt!r}")
    frame = obj.get("frame")
    if frame is not None:
        frame = strict_json.integer(frame, f"{where}: frame", KeypointInputError, 0, MAX_FRAME)
    t = obj.get("t")
    if t is None:
        if frame is None:
            _fail(where, "neither 't' (s) nor 'frame' given")
        t = frame / fps
    t = timestamp_s(t, f"{where}: t", KeypointInputError)
    people = obj.get("people", [])
    if not isinstance(people, list):
        _fail(where, "people: expected a list")
    return KeypointFrame(t, frame, [_parse_person(p, i, where) for i, p in enumerate(people)], fmt)


def timestamp_s(value, where: str, error: type[Exception]) -> float:
    """A frame timestamp (s) of an input file: finite and within +-MAX_TIMESTAMP_S."""
    return strict_json.number(value, where, error, -MAX_TIMESTAMP_S, MAX_TIMESTAMP_S)


def read_keypoints_jsonl(path: str | os.PathLike, fmt: str = "coco", fps: float = 30.0
                         ) -> Iterator[KeypointFrame]:
    """Frames of a JSON-lines keypoint file, lazily; errors name the file and line."""
    if fmt not in FORMATS:
        raise ValueError(f"unknown keypoint format {fmt!r} (one of {', '.join(FORMATS)})")
    try:
        f = open(path, "rb")
    except OSError as e:
        raise KeypointInputError(f"{path}: cannot open ({e.strerror or e})") from None
    with f:
        for n, raw in enumerate(f, 1):
            frame = parse_keypoint_line(raw, f"{path}:{n}", fmt, fps)
            if frame is not None:
                yield frame


# ---------------------------------------------------------------------------- person selection


SELECT_MODES = ("largest", "confident", "track")


def _extent_px2(kp: np.ndarray, min_score: float) -> float:
    """Area (px^2) of the bounding box of the keypoints seen with at least ``min_score``."""
    ok = np.isfinite(kp[:, :2]).all(axis=1) & (kp[:, 2] >= min_score)  # a NaN score compares False
    if ok.sum() < 2:
        return 0.0
    span = kp[ok, :2].max(axis=0) - kp[ok, :2].min(axis=0)
    return float(span[0] * span[1])


def _confidence(kp: np.ndarray) -> float:
    return float(np.nansum(kp[:, 2])) if np.isfinite(kp[:, :2]).any() else 0.0


@dataclass
class PersonSelector:
    """Which detected person the lifter follows, frame after frame.

    ``largest``: the largest bounding box of confidently seen keypoints; ``confident``:
    the highest summed score; ``track``: the exporter's id ``track_id`` (or, when it is
    None, the id of the first person picked by size), and nobody when that id is absent
    (the lifter then handles the person as lost; it never jumps to someone else)."""

    mode: str = "largest"
    track_id: int | None = None
    min_score: float = 0.3

    def __post_init__(self):
        if self.mode not in SELECT_MODES:
            raise ValueError(f"person selection {self.mode!r}: one of {', '.join(SELECT_MODES)}")

    def select(self, people: Sequence[Person]) -> Person | None:
        if not people:
            return None
        if self.mode == "confident":
            return max(people, key=lambda p: _confidence(p.keypoints))
        if self.mode == "track" and self.track_id is not None:
            return next((p for p in people if p.id == self.track_id), None)
        best = max(people, key=lambda p: _extent_px2(p.keypoints, self.min_score))
        if self.mode == "track":
            self.track_id = best.id
        return best


# ---------------------------------------------------------------------------- who is who


@config.section("people")
@dataclass(frozen=True)
class PeopleTrackParams:
    """Stable ids for every person seen ([people] in the box configuration)."""

    min_joints: int = config.setting(8, config.within(1, 17))
    """A detection needs this many keypoints seen (score >= ``min_score``) to be tracked: a
    sliver of a half-hidden person matches anyone nearby (fewer than 8 mixed people up in
    ``python -m firmware_sim crossings``)."""
    min_score: float = config.setting(0.3, config.within(0, 1))
    """A keypoint scoring below this does not count for tracking (the lifter's threshold)."""
    gate: float = config.setting(0.6, config.POSITIVE)
    """A detection may join a track whose predicted keypoints are at most this far (median over
    the joints), in units of the track's size in the image (his height, from his bones)."""
    gate_growth_per_s: float = config.setting(0.5, config.NON_NEGATIVE)
    """The gate of a track not seen for a while grows by this much per second unseen (where he
    reappears is less certain the longer he was hidden)."""
    max_lost_s: float = config.setting(3.0, config.POSITIVE)
    """A track unseen this long (s) is forgotten; a person back within it keeps his id."""
    max_predict_s: float = config.setting(1.5, config.POSITIVE)
    """Constant-velocity prediction runs at most this far (s) past the last sighting; a person
    hidden longer is looked for where he was last predicted."""
    velocity_smoothing: float = config.setting(0.15, config.within(0, 1))
    """Weight of the newest image velocity in the track's smoothed velocity."""


@dataclass
class _Track:
    id: int
    xy: np.ndarray
    """(J, 2) the last keypoints seen (NaN: not seen then)."""
    size_px: float
    t_s: float
    velocity_pxps: np.ndarray = field(default_factory=lambda: np.zeros(2))

    def predicted(self, t_s: float, max_predict_s: float) -> np.ndarray:
        return self.xy + self.velocity_pxps * min(t_s - self.t_s, max_predict_s)


def _seen(kp: np.ndarray, min_score: float) -> np.ndarray:
    """(..., 17) bool: the joints of keypoints (..., 17, 3) seen (finite, scored at least ``min_score``)."""
    return np.isfinite(kp[..., :2]).all(axis=-1) & (kp[..., 2] >= min_score)


class PersonTracker:
    """Stable ids for the people of successive frames (see "Who is who" in the module docstring).

        tracker = PersonTracker()
        people = tracker.update(frame.t_s, frame.people)   # the same Person objects' data, id = track id
    """

    def __init__(self, params: PeopleTrackParams = PeopleTrackParams(), keypoint_format: str = "coco"):
        if keypoint_format not in FORMATS:
            raise ValueError(f"keypoint format {keypoint_format!r}: one of {', '.join(FORMATS)}")
        self.params = params
        self.keypoint_format = keypoint_format
        self.tracks: dict[int, _Track] = {}
        self._ids = itertools.count()
        self.created = 0
        """Tracks started (ids handed out)."""
        self.rejected = 0
        """Detections with fewer than ``min_joints`` keypoints seen (not people)."""

    def update(self, t_s: float, people: Sequence[Person]) -> list[Person]:
        """The people of the frame at ``t_s`` with track ids (in the order given; detections
        that are not people are left out). Tracks unseen for ``max_lost_s`` are forgotten."""
        p = self.params
        for tid in [k for k, tr in self.tracks.items() if t_s - tr.t_s > p.max_lost_s or t_s < tr.t_s]:
            del self.tracks[tid]  # gone too long, or the clock went back: a new stream
        shaped, kps = [], []
        for person in people:
            kp = np.asarray(person.keypoints, float)
            if kp.shape not in ((N_JOINTS, 2), (N_JOINTS, 3)):
                self.rejected += 1
                continue
            shaped.append(person)
            kps.append(kp)
        # everyone's keypoints, seen joints and size in one pass (numpy's per-call cost, not its arithmetic, was
        # most of a frame's tracking when each detection had its own); tracked on the lifter's joints: one set
        # of bones
        kps = to_h36m_each(kps, self.keypoint_format)
        seen = _seen(kps, p.min_score)
        all_seen = bool(seen.all())  # every joint of everyone seen (the usual frame): all 17 >= min_joints of them
        if not (all_seen and p.min_joints <= N_JOINTS):
            enough = seen.sum(axis=1) >= p.min_joints
            if not enough.all():
                self.rejected += len(enough) - int(enough.sum())
                shaped = [person for person, ok in zip(shaped, enough.tolist()) if ok]
                kps, seen = kps[enough], seen[enough]
        sizes = _sizes_px(kps, seen, p.min_score, all_seen)
        assigned = _assign(self._costs(kps, seen, t_s, all_seen))
        out, followed = [], []
        for i, person in enumerate(shaped):
            tid = assigned.get(i)
            if tid is None:
                tid = next(self._ids)
                self.created += 1
                self.tracks[tid] = _Track(tid, np.where(seen[i][:, None], kps[i][:, :2], np.nan), sizes[i], t_s)
            else:
                followed.append((self.tracks[tid], i))
            # dataclasses.replace's result, built directly for a plain Person (replace costs ten times as much)
            out.append(Person(person.keypoints, tid, person.id) if type(person) is Person
                       else replace(person, id=tid, source_id=person.id))
        if followed:
            which = [i for _, i in followed]
            self._follow_all([tr for tr, _ in followed], kps[which], seen[which], [sizes[i] for i in which], t_s,
                             all_seen)
        return out

    def _costs(self, kps: np.ndarray, seen: np.ndarray, t_s: float, all_seen: bool = False
               ) -> dict[tuple[int, int], float]:
        """The match cost of every (track id, detection index) pair, tracks in their order, of detections ``kps``
        (D, 17, 3) whose joints ``seen`` (D, 17) are seen (:func:`_pair_costs`; ``all_seen``: all of them are)."""
        if not self.tracks or not len(kps):
            return {}
        return _pair_costs(list(self.tracks.items()), kps, seen, t_s, self.params, all_seen)

    def _follow_all(self, tracks: list[_Track], kps: np.ndarray, seen: np.ndarray, sizes_px: list[float],
                    t_s: float, all_seen: bool = False) -> None:
        """Move each of ``tracks`` to its detection at ``t_s`` (``kps`` (M, 17, 3), ``seen`` (M, 17), ``sizes_px``
        their :func:`_size_px`; ``all_seen``: the caller knows every joint is seen): its smoothed image velocity
        from the mean step of the joints seen now and before, the joints not seen now moved with it. Every track
        in one pass (the same numbers as one by one: tests/robot/test_perception_batch_s18.py)."""
        a = self.params.velocity_smoothing
        xy = np.array([tr.xy for tr in tracks])  # stacked (as np.stack, cheaper)
        velocity = np.array([tr.velocity_pxps for tr in tracks])
        dt = [t_s - tr.t_s for tr in tracks]
        # every joint seen now and before, and every track moving (the usual frame): every joint in every step, and
        # every track gets its new velocity (a finite sum has no NaN or infinite term: xy's test in one reduction)
        usual = all_seen and math.isfinite(xy.sum()) and min(dt) > 0
        if not usual:
            both = seen & np.isfinite(xy).all(axis=2)
            n_both = both.sum(axis=1)
            moving = np.array([d > 0 and n > 0 for d, n in zip(dt, n_both.tolist())])
        with np.errstate(all="ignore"):  # a track not moving (dt <= 0, no joint in common) gets no velocity
            # np.mean's own arithmetic: the steps summed joint after joint (numpy adds the rows of a (n, 2) array
            # in order), then / the count, then / dt; the joints left out add -0.0, the sum's exact identity
            step = kps[..., :2] - xy
            if usual:  # each count is all 17 joints (an integer count divides as the same float)
                v = step.sum(axis=1) / float(seen.shape[1]) / np.array(dt)[:, None]
            else:
                if not both.all():
                    step = np.where(both[..., None], step, -0.0)
                v = step.sum(axis=1) / n_both[:, None] / np.array(dt)[:, None]
        smoothed = a * v + (1 - a) * velocity
        velocity = smoothed if usual or moving.all() else np.where(moving[:, None], smoothed, velocity)
        if all_seen or seen.all():  # every joint seen now (the usual frame): each track at its detection
            new_xy = np.ascontiguousarray(kps[..., :2])
        else:  # joints not seen now keep their last position, moved with the person
            moved = xy + velocity[:, None, :] * np.array([max(d, 0.0) for d in dt])[:, None, None]
            new_xy = np.where(seen[..., None], kps[..., :2], moved)
        for tr, xy_k, velocity_k, size_px in zip(tracks, new_xy, velocity, sizes_px):
            tr.xy, tr.velocity_pxps, tr.size_px, tr.t_s = xy_k, velocity_k, size_px, t_s


def _pair_costs(tracks: list[tuple[int, _Track]], kps: np.ndarray, seen: np.ndarray, t_s: float,
                p: PeopleTrackParams, all_seen: bool = False) -> dict[tuple[int, int], float]:
    """The match cost of every (track id, detection index) pair of ``tracks`` ((id, track), in their order) and
    detections ``kps`` (D, 17, 3) whose joints ``seen`` (D, 17) are seen.

    A pair's cost is the median distance of the detection's keypoints from the track's prediction, in track
    sizes, as a fraction of the track's gate (which grows while it is unseen); inf beyond the gate or without
    common joints. Dividing by the gate weighs a miss by how sure the prediction is: a person seen a frame
    ago is predicted to a few pixels, one hidden for a second anywhere in a wide gate. So when a hidden walker
    reappears beside the one who hid him, the detection nearest the visible walker's sharp prediction keeps
    his id and the vague track takes the other (in ``firmware_sim crossings`` on development seed 5, 300
    crossings: right id kept 91.0 % -> 93.2 %). (Apparent size is no cue: at a real detector's noise it varies
    13 % from frame to frame, as much as between two people crossing; a smoothed size weighed in mixed more
    people up. Matching recently seen tracks first, DeepSORT's cascade, lost 22 points there: a half-hidden
    walker's sliver then takes the visible one's id.)

    Every pair's
    distances in one (T, D, 17) pass, and each pair's median the middle of its sorted distances (the joints
    not in common sorted last, as inf) with :func:`edge_runtime.core.numeric.median`'s arithmetic on Python
    floats (the same IEEE operations; tests/robot/test_perception_batch_s18.py). ``all_seen``: the caller knows
    every joint of every detection is seen."""
    ahead_s = np.array([min(t_s - tr.t_s, p.max_predict_s) for _, tr in tracks])
    # _Track.predicted of each: xy + velocity * ahead, element by element
    pred = (np.array([tr.xy for _, tr in tracks])  # stacked (as np.stack, cheaper)
            + np.array([tr.velocity_pxps for _, tr in tracks])[:, None, :] * ahead_s[:, None, None])
    # every joint seen and predicted (the usual frame): every pair has all its joints in common (a finite sum has no
    # NaN or infinite term: the predictions' test in one reduction)
    every = all_seen and math.isfinite(pred.sum())
    if not every:
        both = seen[None] & np.isfinite(pred).all(axis=2)[:, None]  # (T, D, 17)
    with np.errstate(over="ignore", invalid="ignore"):  # joints not in common may be anything: unused
        d = kps[None, :, :, :2] - pred[:, None]
        dist = np.sqrt(d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1])  # norms2's arithmetic
    rows = dist if every else np.where(both, dist, np.inf)
    rows.sort(axis=2)  # in place (a new array already): np.sort's order without its copy
    n_both = [[rows.shape[2]] * rows.shape[1]] * rows.shape[0] if every else both.sum(axis=2).tolist()
    rows = rows.tolist()
    costs = {}
    for (tid, tr), track_rows, counts in zip(tracks, rows, n_both):
        gate = p.gate + p.gate_growth_per_s * max(t_s - tr.t_s, 0.0)
        for i, (row, count) in enumerate(zip(track_rows, counts)):
            if count < 2:
                costs[tid, i] = math.inf
                continue
            # the median: a swinging limb or one gross keypoint error must not decide who is who
            h = count // 2
            mid = row[h] if count % 2 else (row[h - 1] + row[h]) / 2.0
            dist_sizes = mid / tr.size_px
            costs[tid, i] = dist_sizes / gate if dist_sizes <= gate else math.inf
    return costs


_BONES = ((L_SHOULDER, sk.L_HIP, 0.288), (R_SHOULDER, sk.R_HIP, 0.288), (sk.L_HIP, sk.L_KNEE, 0.245),
          (sk.R_HIP, sk.R_KNEE, 0.245), (sk.L_KNEE, sk.L_ANKLE, 0.246), (sk.R_KNEE, sk.R_ANKLE, 0.246),
          (L_SHOULDER, sk.L_ELBOW, 0.186), (R_SHOULDER, sk.R_ELBOW, 0.186), (sk.L_ELBOW, sk.L_WRIST, 0.146),
          (sk.R_ELBOW, sk.R_WRIST, 0.146))
"""(H36M joint, H36M joint, length as a fraction of body height; docs/design.md section 5)."""
_BONE_A = np.array([a for a, _, _ in _BONES])
_BONE_B = np.array([b for _, b, _ in _BONES])
_BONE_FRAC = [frac for _, _, frac in _BONES]
_BONE_FRACTIONS = np.array(_BONE_FRAC)


MAX_EXACT_ASSIGNMENT = 4
"""Up to this many detections in a frame the best assignment is searched exhaustively (at most
5^4 cases); beyond (a crowd), pairs are taken greedily, cheapest first."""


def _assign(costs: dict[tuple[int, int], float]) -> dict[int, int]:
    """Detection index -> track id over the finite-cost (gated) pairs: as many pairs as
    possible, and of those the least total cost."""
    pairs = {k: c for k, c in costs.items() if math.isfinite(c)}
    options: dict[int, list[int]] = {}  # each detection's tracks, in the pairs' order
    for t, d in pairs:
        options.setdefault(d, []).append(t)
    dets = sorted(options)
    if len(dets) > MAX_EXACT_ASSIGNMENT:
        assigned: dict[int, int] = {}
        for (tid, i), _ in sorted(pairs.items(), key=lambda kv: kv[1]):
            if i not in assigned and tid not in assigned.values():
                assigned[i] = tid
        return assigned
    if all(len(ts) == 1 for ts in options.values()) and len({ts[0] for ts in options.values()}) == len(dets):
        # each detection within one track's gate, no track within two detections' (people apart, the usual
        # frame): pairing them all is the only assignment with every detection paired, the search's answer (in
        # its order: the last detection first)
        return {d: options[d][0] for d in reversed(dets)}
    return _best_assignment(0, frozenset(), dets, options, pairs)[2]


def _best_assignment(k: int, taken: frozenset, dets: list[int], options: dict[int, list[int]],
                     pairs: dict[tuple[int, int], float]) -> tuple[int, float, dict[int, int]]:
    """:func:`_assign`'s exhaustive search from detection ``dets[k]`` on, tracks ``taken`` already used:
    (pairs made, their total cost, detection -> track). A module function, not a closure that calls
    itself: such a closure is a reference cycle (function -> cell -> function) that only the garbage
    collector frees, so one per frame made the collector run every few dozen frames, for milliseconds,
    inside whichever stage came next (reports/bench/s17_perf7/report.md)."""
    if k == len(dets):
        return 0, 0.0, {}
    d = dets[k]
    n, c, m = _best_assignment(k + 1, taken, dets, options, pairs)  # detection d starts a new track
    result = (n, c, m)
    for t in options[d]:
        if t not in taken:
            n, c, m = _best_assignment(k + 1, taken | {t}, dets, options, pairs)
            n, c = n + 1, c + pairs[(t, d)]
            if (n, -c) > (result[0], -result[1]):
                result = (n, c, {**m, d: t})
    return result


def _size_px(kp: np.ndarray, min_score: float, seen: np.ndarray | None = None) -> float:
    """A person's size in the image (px), whichever of his joints are seen: the largest body
    height his seen bones imply (bone length / its fraction of the height; the largest,
    because a bone seen end-on looks short, never long), else his keypoints' box diagonal.
    A partly hidden person so keeps his size (a box of his visible joints would shrink)."""
    if seen is None:
        seen = _seen(kp, min_score)
    both = np.flatnonzero(seen[_BONE_A] & seen[_BONE_B])
    if len(both) >= 2:
        bones = kp[_BONE_A[both], :2] - kp[_BONE_B[both], :2]
        # a vector's np.linalg.norm is sqrt(dot(v, v)): the same dot, and a correctly rounded sqrt
        heights = sorted([math.sqrt(v.dot(v)) / _BONE_FRAC[i] for v, i in zip(bones, both.tolist())])
        return max(heights[-2], 1.0)  # the second largest: one bad keypoint cannot inflate it
    xy = kp[seen, :2]
    return max(float(np.linalg.norm(xy.max(axis=0) - xy.min(axis=0))), 1.0)


def _sizes_px(kps: np.ndarray, seen: np.ndarray, min_score: float, all_seen: bool = False) -> list[float]:
    """:func:`_size_px` of each detection of ``kps`` (D, 17, 3), ``seen`` (D, 17) its seen joints: every bone of
    every detection in one pass (``np.vecdot`` of float64 calls the dot ``ndarray.dot`` calls, vector by vector),
    the same numbers; a detection with fewer than two bones seen gets :func:`_size_px` itself (its box).
    ``all_seen``: the caller knows ``seen`` is all True (then so is every bone)."""
    bone_seen = None if all_seen else seen[:, _BONE_A] & seen[:, _BONE_B]
    bones = kps[:, _BONE_A, :2] - kps[:, _BONE_B, :2]
    heights = np.sqrt(np.vecdot(bones, bones)) / _BONE_FRACTIONS
    every = all_seen or bone_seen.all()  # every bone of everyone seen (the usual frame): none to leave out
    if not every:
        heights = np.where(bone_seen, heights, -np.inf)
    heights.sort(axis=1)  # in place (a new array already): np.sort's order without its copy
    second = heights[:, -2].tolist()  # the second largest seen (the bones not seen sort first, -inf)
    counts = [len(_BONES)] * len(kps) if every else bone_seen.sum(axis=1).tolist()
    return [max(h, 1.0) if n >= 2 else _size_px(kps[i], min_score, seen[i])
            for i, (n, h) in enumerate(zip(counts, second))]


# ---------------------------------------------------------------------------- cameras


@dataclass(frozen=True)
class CameraModel:
    """A pinhole camera with OpenCV's distortion model; all lengths in pixels."""

    fx_px: float
    fy_px: float
    cx_px: float
    cy_px: float
    width_px: int
    height_px: int
    dist: tuple[float, ...] = ()
    """Distortion coefficients in OpenCV's order (k1, k2, p1, p2[, k3[, ...]]); () = none."""

    def __post_init__(self):
        # comparisons, not math.isfinite: a 400-digit integer from a file must not raise OverflowError
        for name in ("width_px", "height_px"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or not 1 <= v <= MAX_IMAGE_PX:
                raise ValueError(f"camera {name}: expected an integer in [1, {MAX_IMAGE_PX}], got {v!r}"[:200])
        for name in ("fx_px", "fy_px"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not 0 < v <= MAX_IMAGE_PX * 100:
                raise ValueError(f"camera {name}: expected a positive number, got {v!r}"[:200])
        if not all(isinstance(v, (int, float)) and -1e9 <= v <= 1e9 for v in (self.cx_px, self.cy_px, *self.dist)):
            raise ValueError("camera: principal point and distortion must be finite")
        if len(self.dist) not in (0, 4, 5, 8, 12, 14):
            raise ValueError(f"camera dist: {len(self.dist)} coefficients; OpenCV takes 4, 5, 8, 12 or 14")

    @property
    def K(self) -> np.ndarray:
        return np.array([[self.fx_px, 0, self.cx_px], [0, self.fy_px, self.cy_px], [0, 0, 1]], np.float64)

    @property
    def dist_array(self) -> np.ndarray:
        return np.asarray(self.dist, np.float64)

    @classmethod
    def from_fov(cls, width_px: int, height_px: int, hfov_deg: float = 100.0) -> "CameraModel":
        """A distortion-free camera with horizontal field of view ``hfov_deg`` and a centred
        principal point."""
        f = (width_px / 2) / math.tan(math.radians(hfov_deg) / 2)
        return cls(f, f, width_px / 2, height_px / 2, int(width_px), int(height_px))

    @classmethod
    def from_dict(cls, d: dict, where: str = "camera") -> "CameraModel":
        """From ``{"width_px", "height_px", "fx_px", "fy_px", "cx_px", "cy_px"[, "dist"]}``
        (the manifest's ``camera`` form) or ``{"K": 3x3, "dist", "width_px", "height_px"}``."""
        if not isinstance(d, dict):
            raise ValueError(f"{where}: expected an object")
        try:
            if "K" in d:
                K = np.asarray(d["K"], dtype=np.float64)
                if K.shape != (3, 3):
                    raise ValueError(f"{where}: field 'K': expected a 3x3 matrix")
                fx, fy, cx, cy = K[0, 0], K[1, 1], K[0, 2], K[1, 2]
            else:
                fx, fy, cx, cy = (float(d[k]) for k in ("fx_px", "fy_px", "cx_px", "cy_px"))
            w, h = d["width_px"], d["height_px"]
            dist = tuple(float(v) for v in d.get("dist", ()) or ())
        except KeyError as e:
            raise ValueError(f"{where}: field {e.args[0]!r}: missing") from None
        except (TypeError, ValueError, OverflowError) as e:  # OverflowError: float() of a 400-digit integer
            raise ValueError(f"{where}: {e}") from None
        if isinstance(w, bool) or isinstance(h, bool) or not isinstance(w, int) or not isinstance(h, int):
            raise ValueError(f"{where}: width_px and height_px must be integers")
        try:
            return cls(float(fx), float(fy), float(cx), float(cy), w, h, dist)
        except ValueError as e:
            raise ValueError(f"{where}: {e}") from None

    @classmethod
    def from_json(cls, path: str | os.PathLike) -> "CameraModel":
        """A camera file (JSON, :meth:`from_dict`'s fields); errors name the file."""
        try:
            raw = Path(path).read_bytes()
        except OSError as e:
            raise InputError(f"{path}: not a readable JSON camera file ({e.strerror or e})") from None
        d = strict_json.loads(raw, str(path), InputError)
        try:
            return cls.from_dict(d, str(path))
        except ValueError as e:
            raise InputError(str(e)) from None

    def to_dict(self) -> dict:
        return {"width_px": self.width_px, "height_px": self.height_px, "fx_px": self.fx_px,
                "fy_px": self.fy_px, "cx_px": self.cx_px, "cy_px": self.cy_px, "dist": list(self.dist)}

    def same_pixels_as(self, other: "CameraModel") -> bool:
        """Whether pixels of this camera are already pixels of ``other`` (no mapping needed)."""
        return (not any(self.dist) and not any(other.dist)
                and (self.fx_px, self.fy_px, self.cx_px, self.cy_px) ==
                (other.fx_px, other.fy_px, other.cx_px, other.cy_px))

    def to_camera(self, points_px, target: "CameraModel") -> np.ndarray:
        """Pixels (..., 2) of this camera -> undistorted pixels of the ``target`` camera.

        ``cv2.undistortPoints`` removes this camera's distortion and re-projects with
        ``target``'s K; the two cameras share their optical centre and axes. Non-finite
        points stay NaN."""
        import cv2

        p = np.asarray(points_px, dtype=np.float64)
        if self.same_pixels_as(target):
            return p.copy()
        flat = p.reshape(-1, 2)
        out = np.full(flat.shape, np.nan)
        ok = np.isfinite(flat).all(axis=1)
        if ok.any():
            und = cv2.undistortPoints(flat[ok].reshape(-1, 1, 2), self.K, self.dist_array, P=target.K,
                                      criteria=UNDISTORT_CRITERIA)
            out[ok] = und.reshape(-1, 2)
        return out.reshape(p.shape)


def normalize_screen(points_px, width_px: float, height_px: float) -> np.ndarray:
    """VideoPose3D's normalisation: ``u/w*2 - 1``, ``v/w*2 - h/w`` (x in [-1, 1])."""
    p = np.asarray(points_px, dtype=np.float64)
    return p / width_px * 2 - np.array([1.0, height_px / width_px])


def image_to_canonical(kp_h36m, camera: CameraModel | None, canonical: CameraModel) -> np.ndarray:
    """H36M keypoints (..., 17, 3) in ``camera`` pixels -> normalised canonical-camera
    coordinates (..., 17, 2) (scores dropped). ``camera`` None means the keypoints are
    already canonical pixels."""
    kp = np.asarray(kp_h36m, dtype=np.float64)
    px = kp[..., :2] if camera is None else camera.to_camera(kp[..., :2], canonical)
    return normalize_screen(px, canonical.width_px, canonical.height_px)
