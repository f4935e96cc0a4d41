"""The streaming pose lifter: 2D keypoints per camera frame -> 3D joints in the camera frame.

    lifter = StreamingLifter.from_manifest(ASSETS_DIR, LifterParams(precision="int8"),
                                           camera=CameraModel.from_json("cam.json"), keypoint_format="coco")
    pose = lifter.push(t_s, keypoints)      # (17, 3) x, y (px), score -- or None: nobody seen
    if pose.valid:
        use(pose.joints_cam_m)              # (17, 3) metres, OpenCV camera axes

The model (a VideoPose3D-style temporal network, shipped by ``python -m export``)
is loaded ONLY through ``assets/manifest.json`` (entry ``arch`` "lifter"; sha256
checked before the bytes reach onnxruntime). Its contract: input ``keypoints_2d``
float32 (N, 27, 17, 2), the last 27 frames oldest first, H36M-17 joints in the
canonical camera's pixels normalised as ``u/w*2 - 1``, ``v/w*2 - h/w``; outputs
``pose_3d`` (N, 1, 17, 3) root-relative joints and ``root_3d`` (N, 1, 3) the
pelvis, metres, camera frame, both for the LAST input frame. Absolute joints =
pose_3d + root_3d. Pixels of another camera are undistorted and re-projected into
the canonical camera (the manifest's ``camera``) before normalising
(:mod:`edge_runtime.robot.keypoints`).

3D that agrees with the 2D it came from
=======================================
The model's x and y come from a network that learnt from simulated bodies; the camera's
rays do not. So the runtime keeps only the model's per-joint DEPTH and puts every joint
on the ray of the keypoint it was lifted from (the undistorted, canonical-camera pixel,
or the held one): ``joints_cam_m[j] = z_j * ((u_j - cx) / fx, (v_j - cy) / fy, 1)`` with
``z_j`` the model's depth of joint ``j``. Projected back with the camera (its distortion
included) every joint lands on its input keypoint; only depth, the part 2D cannot give,
rests on the model (and on the floor anchoring of
:mod:`edge_runtime.robot.calibration`, which slides the skeleton along these rays). The
model's own joints stay in ``joints_model_cam_m``.

A real detector errs by several pixels per joint and frame, and a ray through a noisy
keypoint carries that error into 3D, while the model has seen 27 frames and averages much of
it out. So the pixel ``(u_j, v_j)`` is first moved toward the model joint's own projection
by at most ``ray_tolerance_px`` (1.5 px of the input camera): the output never strays from
what the camera saw by more than that, and within it the model's smoother estimate wins.
``ray_tolerance_px = 0`` puts every joint exactly on its keypoint's ray. A joint the model puts less than
``MIN_DEPTH_M`` in front of the camera makes the frame invalid (``model_output``).

Streaming
=========
A causal ring buffer holds the last ``receptive_field`` (27) frames; each camera
frame costs ONE onnxruntime call on a (1, 27, 17, 2) view of it (no copy: every
frame is written twice into a buffer of 2 x 27 slots, so the last 27 are always
contiguous; :class:`PeopleLifter` stacks every person's window of a frame into one
call). The output for frame t equals a batch run of the model over the
sequence padded at its start.

Start-up padding: after a start or a reset the first usable frame is replicated
into all 27 slots, as VideoPose3D pads a sequence with its edge values; the
output is computed at once and flagged ``warming_up`` until 27 real frames
have been buffered (outputs during warm-up are valid but rest on padding).

Missing data is never fed through as garbage:

* A joint is missing when its score is below ``min_score``, a coordinate is
  NaN/infinite, or it lies more than 4.5 image widths outside the image
  (``MAX_NORMALISED``). It is HELD at its last valid observation for up to
  ``hold_frames`` frames (``observed`` is False for it). Missing longer (or never
  seen since the last reset), the frame can still be lifted when the person shows
  enough of himself (:func:`edge_runtime.robot.hazard.enough_joints`: his trunk
  and head, pelvis, hips, spine, thorax, shoulders, observed or held, at least
  one ankle, and at most ``hazard.MAX_MISSING_JOINTS`` joints missing): that joint is flagged ``missing`` and
  the model is fed its last keypoint moved with the image motion of the joints
  he shows (one never seen: his nearest seen joint's keypoint). Its lifted
  position is a guess, no measurement: the hazard monitor bounds it by its
  bones from the joints he shows (:func:`edge_runtime.robot.hazard.body_spheres`).
  A real 2D detector drops single wrists, elbows, knees and ankles all the time
  (self-occlusion, a passing arm); declaring the whole person unseen for one of
  them costs more than it protects. Showing less, the frame is INVALID (reason
  ``missing_joints: ...``) and the model is not run. As shipped
  ``MAX_MISSING_JOINTS`` is 0: every joint missing beyond ``hold_frames`` makes
  the frame invalid (the hazard module says why).
* A frame with no person (``None``) or a keypoint array that is not 17 joints
  counts as every joint missing: held within ``hold_frames``, else invalid with
  reason ``no_person`` / ``joint_count`` (counted either way: ``stats.no_person``,
  ``stats.wrong_joint_count``).
* Dropped camera frames: a timestamp step above ``max_gap_periods`` frame periods
  means ``round(dt * frame_rate_hz) - 1`` frames were dropped; their joints age
  like missing ones.
* Holes in the buffer (dropped frames, invalid frames) are bridged when valid
  input returns by linear interpolation between the frames on either side, so
  the temporal context stays evenly spaced, provided the hole lasted at most
  ``lost_timeout_s``; after a longer one (the person was lost) the buffer is
  RESET and warm-up starts again from the next valid frame.
* A camera slower than ``frame_rate_hz`` looks like one that drops frames, so its
  frames are spaced out to the model's rate by the same interpolation (each pose
  is still computed, and reported, at the camera's own frames).
* A timestamp that is not finite or beyond +-1e10 s (``keypoints.MAX_TIMESTAMP_S``) is
  refused (reason ``bad_time``). A timestamp that does not increase is refused (reason ``time_not_increasing``)
  and changes nothing; one that goes back by more than ``lost_timeout_s`` starts
  a new stream (:meth:`StreamingLifter.restart`: buffer, joint memory and clock
  forgotten; ``stats.restarts``).

Every outcome is counted in :class:`LifterStats`. This module never imports
torch or onnx.

Several people
==============
:class:`PeopleLifter` lifts every tracked person of a frame (ids from
:class:`edge_runtime.robot.keypoints.PersonTracker`) with his own ring buffer, joint
memory and clock: one :class:`StreamingLifter` per id, all sharing one onnxruntime
session and one :class:`LifterStats`. A person's window only ever holds his own frames;
a person who is not in a frame is not pushed (he is absent, not "missing joints"), and
his lifter is dropped after ``lost_timeout_s`` without him. The windows of every person lifted in a
frame go to onnxruntime together, as one (N, 27, 17, 2) batch, when the model's batch dimension is
symbolic (the shipped lifters': each person's output is the same to the bit as his own batch-1 call,
tests/robot/test_lifter_batch.py; session 16 measured one call for two people at 0.31 ms of CPU against
2 x 0.22 ms for two, int8); a model whose batch is fixed gets one call per person.
"""
from __future__ import annotations

import math
import os
import time
from collections import Counter
from dataclasses import dataclass, field, fields

import numpy as np

from edge_runtime import config
from edge_runtime.core.manifest import ASSETS_DIR, PRECISIONS, ModelIntegrityError
from edge_runtime.core.numeric import median_columns, norms2
from edge_runtime.core.onnx import fast_run, session_from_manifest
from edge_runtime.core.skeleton import ALL_JOINTS, HIP, JOINTS, N_JOINTS, NO_JOINTS, PARENTS
from edge_runtime.robot.hazard import enough_joints
from edge_runtime.robot.keypoints import FORMATS, MAX_TIMESTAMP_S, CameraModel, image_to_canonical, to_h36m

LIFTER_ARCH = "lifter"
INPUT_NAME = "keypoints_2d"
POSE_OUTPUT = "pose_3d"
ROOT_OUTPUT = "root_3d"
JOINT_SET = "h36m-17"

# reason codes (LiftedPose.reason starts with one; LifterStats.invalid counts them)
NO_PERSON = "no_person"
JOINT_COUNT = "joint_count"
MISSING_JOINTS = "missing_joints"
TIME_NOT_INCREASING = "time_not_increasing"
BAD_TIME = "bad_time"

MAX_RAY_TOLERANCE_PX = 5.0
"""The largest ``ray_tolerance_px`` accepted: issue 14's p95 bound on the reprojection."""
MAX_RECEPTIVE_FIELD = 1024
"""The largest receptive field a manifest may declare (VideoPose3D's largest is 243 frames):
the ring buffer is allocated from it."""
MAX_NORMALISED = 10.0
"""A keypoint whose normalised coordinate (the image spans [-1, 1] in x) is beyond +-this
(4.5 image widths outside the image) counts as missing: the model's input stays finite and
within what a camera can show."""
MIN_DEPTH_M = 0.1
"""A lifted joint must lie at least this far in front of the camera (m): its ray is
scaled by its depth, and a depth at or behind the optical centre has no ray to be on."""


@config.section("lifter")
@dataclass(frozen=True)
class LifterParams:
    """Tunables of :class:`StreamingLifter` (a TOML section of the box configuration)."""

    precision: str = "int8"
    """Which shipped lifter to run: "int8" or "fp32" (manifest entry lifter-<precision>)."""
    threads: int = 1
    """onnxruntime intra-op threads (the box has 2 cores; 1 leaves one for the rest)."""
    manifest_public_key: str = ""
    """PEM file of the Ed25519 key the manifest must be signed with (manifest.json.sig); empty =
    the sha256 hashes only. Needs the signed-models extra."""
    min_score: float = 0.3
    """A keypoint whose detector score is below this is treated as missing."""
    hold_frames: int = 3
    """A missing joint is held at its last valid observation for up to this many frames
    (100 ms at 30 Hz); missing longer, the frame is reported invalid."""
    frame_rate_hz: float = 30.0
    """The camera rate the model was trained for; sets the frame period for gap detection
    and hole filling."""
    max_gap_periods: float = 1.5
    """A timestamp step above this many frame periods means frames were dropped."""
    lost_timeout_s: float = 0.5
    """A hole in the input (dropped or invalid frames) up to this long is bridged by linear
    interpolation; a longer one (the person was lost) resets the buffer."""
    ray_tolerance_px: float = 1.5
    """How far (input-camera pixels) a joint's projection may stay from its keypoint: each joint
    goes on the ray of the point within this distance of its keypoint that is nearest to the
    model's own projection (0 = exactly on the keypoint's ray). A detector errs by several pixels;
    the model's x and y, which average it out over 27 frames, are kept as far as this allows.
    1.5 px keeps the reprojection within issue 14's median 2 px with a margin."""

    def __post_init__(self):
        if self.precision not in PRECISIONS:
            raise ValueError(f"precision: {self.precision!r}, expected one of {', '.join(PRECISIONS)}")
        if isinstance(self.threads, bool) or not isinstance(self.threads, int) or self.threads < 1:
            raise ValueError(f"threads: expected an integer >= 1, got {self.threads!r}")
        if isinstance(self.hold_frames, bool) or not isinstance(self.hold_frames, int) or self.hold_frames < 0:
            raise ValueError(f"hold_frames: expected an integer >= 0, got {self.hold_frames!r}")
        if not 0.0 <= self.min_score <= 1.0:
            raise ValueError(f"min_score: expected a number in [0, 1], got {self.min_score!r}")
        if not (math.isfinite(self.ray_tolerance_px) and 0.0 <= self.ray_tolerance_px <= MAX_RAY_TOLERANCE_PX):
            raise ValueError(f"ray_tolerance_px: expected a number in [0, {MAX_RAY_TOLERANCE_PX:g}], "
                             f"got {self.ray_tolerance_px!r}")
        for name in ("frame_rate_hz", "lost_timeout_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name}: expected a positive number, got {v!r}")
        if not (math.isfinite(self.max_gap_periods) and self.max_gap_periods >= 1.0):
            raise ValueError(f"max_gap_periods: expected a number >= 1, got {self.max_gap_periods!r}")


@dataclass
class LiftedPose:
    """The lifter's answer for one camera frame."""

    t_s: float
    """The frame's timestamp (s), as pushed."""
    joints_cam_m: np.ndarray
    """(17, 3) absolute H36M joints in the camera frame (m; x right, y down, z forward);
    all NaN when the frame is invalid."""
    root_cam_m: np.ndarray
    """(3,) the pelvis in the camera frame (m; ``joints_cam_m[0]``, on its keypoint's ray); NaN when invalid."""
    valid: bool
    reason: str | None
    """None when valid; else a code (``no_person``, ``joint_count``, ``missing_joints``,
    ``time_not_increasing``, ``bad_time``), then ``: `` and details."""
    observed: np.ndarray
    """(17,) bool: the joint was seen in this frame (False: held or missing)."""
    warming_up: bool = False
    """The buffer still holds start-up padding (fewer than 27 real frames since a reset)."""
    infer_s: float = 0.0
    """Time of this frame's onnxruntime call (s), which :class:`PeopleLifter` shares among everyone lifted
    in the frame; 0 when the model was not run."""
    held: np.ndarray | None = None
    """(17,) bool: the joint was not seen in this frame and stands at its last observation
    (its ray); False for observed joints and for every joint of an invalid frame."""
    joints_model_cam_m: np.ndarray | None = None
    """(17, 3) the model's own absolute joints (before they were put on the keypoints' rays);
    None when the model did not run."""
    missing: np.ndarray | None = None
    """(17,) bool: the joint has not been seen for longer than ``hold_frames`` (module docstring):
    its position in ``joints_cam_m`` is the model's guess from an imputed keypoint, not a
    measurement (the robot loop passes it on as NaN). None or all False: every joint observed or held."""

    @property
    def code(self) -> str | None:
        return None if self.reason is None else self.reason.split(":", 1)[0]

    def to_json(self) -> dict:
        """A JSON-ready dict (joints as lists, None when invalid)."""
        def fin(a):
            return np.round(a, 5).tolist() if self.valid else None

        held = self.held if self.held is not None else np.zeros(N_JOINTS, bool)
        missing = self.missing if self.missing is not None else np.zeros(N_JOINTS, bool)
        return {"t": self.t_s, "valid": self.valid, "reason": self.reason, "warming_up": self.warming_up,
                "joints_cam_m": fin(self.joints_cam_m), "root_cam_m": fin(self.root_cam_m),
                "observed": [bool(v) for v in self.observed], "held": [bool(v) for v in held],
                "missing": [bool(v) for v in missing]}


@dataclass
class LifterStats:
    """Counters since the lifter was made."""

    frames: int = 0
    valid: int = 0
    warming_up: int = 0
    """Valid frames whose buffer still held start-up padding."""
    invalid: Counter = field(default_factory=Counter)
    """Invalid frames by reason code."""
    no_person: int = 0
    """Frames pushed with nobody in them (None)."""
    wrong_joint_count: int = 0
    """Frames whose keypoints were not 17 joints (all their joints count as missing)."""
    joints_held: int = 0
    """Joint-frames filled from an earlier observation."""
    joints_missing: int = 0
    """Joint-frames lifted from an imputed keypoint (missing beyond ``hold_frames``, the person
    lifted anyway: :func:`edge_runtime.robot.hazard.enough_joints`)."""
    frames_dropped: int = 0
    """Camera frames missing according to the timestamps."""
    frames_interpolated: int = 0
    """Buffer slots filled by interpolation across a hole."""
    resets: int = 0
    """Buffer resets after the person was lost for longer than lost_timeout_s."""
    restarts: int = 0
    """Full restarts: the timestamps went back by more than lost_timeout_s (a new stream)."""
    inferences: int = 0
    """Windows lifted (one a person and frame, however many went in one call)."""
    infer_s: float = 0.0
    """Total onnxruntime time (s)."""

    @property
    def mean_infer_ms(self) -> float:
        return 1000 * self.infer_s / self.inferences if self.inferences else float("nan")

    def to_json(self) -> dict:
        d = {f.name: getattr(self, f.name) for f in fields(self)}
        d["invalid"] = dict(self.invalid)
        d["valid_share"] = self.valid / self.frames if self.frames else 0.0
        d["mean_infer_ms"] = None if not self.inferences else round(self.mean_infer_ms, 4)
        return d


class StreamingLifter:
    """A causal ring buffer of 2D frames in front of one lifter ONNX session."""

    def __init__(self, session, entry: dict, *, params: LifterParams = LifterParams(),
                 camera: CameraModel | None = None, keypoint_format: str = "h36m", source: str = ""):
        if keypoint_format not in FORMATS:
            raise ValueError(f"keypoint format {keypoint_format!r}: one of {', '.join(FORMATS)}")
        self.session = session
        self.entry = entry
        self.params = params
        self.source = source or entry.get("file", "<lifter>")
        self.name = entry.get("name", LIFTER_ARCH)
        self.precision = entry.get("precision", "")
        self.keypoint_format = keypoint_format
        self.receptive_field, self.canonical_camera = _check_entry(entry, self.source)
        self.camera = camera
        _check_session(session, self.receptive_field, self.source)
        self._outputs = [POSE_OUTPUT, ROOT_OUTPUT]
        # the compiled session's own run where it gives exactly session.run's results (core.onnx.fast_run):
        # 2.6-6 % of the int8 call, the wrapper's per-call checks of the feed (reports/bench/s18_ortperf)
        self._run = fast_run(session, self._outputs,
                             {INPUT_NAME: np.zeros((1, self.receptive_field, N_JOINTS, 2), np.float32)}, None)
        self._batches = _symbolic_batch(session)
        self._bindings: dict[int, tuple | None] = {}  # _bound_call's, by batch size (shared by the siblings)
        self.stats = LifterStats()
        self._period_s = 1.0 / params.frame_rate_hz
        r = self.receptive_field
        self._ring = np.zeros((2 * r, N_JOINTS, 2), np.float32)
        self._last_seen = np.zeros((N_JOINTS, 2), np.float64)
        self._moved = np.zeros((N_JOINTS, 2), np.float64)
        """Image motion (normalised) of the person's seen joints since each joint's last sighting."""
        self._age = np.full(N_JOINTS, np.inf)
        self._last_t: float | None = None
        self.reset()

    # ------------------------------------------------------------------ construction

    @classmethod
    def from_manifest(cls, assets_dir: str | os.PathLike = ASSETS_DIR, params: LifterParams = LifterParams(), *,
                      camera: CameraModel | None = None, keypoint_format: str = "h36m") -> "StreamingLifter":
        """The shipped lifter of ``params.precision`` (manifest entry of arch "lifter"),
        hash-checked, with ``params.threads`` intra-op threads."""
        session, entry, path = session_from_manifest(assets_dir, params.precision, arch=LIFTER_ARCH,
                                                     threads=params.threads,
                                                     public_key_file=params.manifest_public_key or None)
        return cls(session, entry, params=params, camera=camera, keypoint_format=keypoint_format, source=path)

    # ------------------------------------------------------------------ state

    def reset(self) -> None:
        """Empty the buffer: the next usable frame starts a new warm-up. Joint memory is kept
        (its age decides whether a held value may still be used)."""
        self._pos = 0
        self._filled = 0
        self._buffered_t: float | None = None
        self._frames_since_buffered = 0

    def restart(self) -> None:
        """Forget everything but the counters: buffer, joint memory and the clock (a new
        stream, e.g. a source whose timestamps started again)."""
        self.stats.restarts += 1
        self.reset()
        self._age[:] = np.inf
        self._last_t = None

    @property
    def warming_up(self) -> bool:
        return self._filled < self.receptive_field

    def window(self) -> np.ndarray:
        """The model input the last call saw: (receptive_field, 17, 2) normalised, oldest first."""
        return self._ring[self._pos:self._pos + self.receptive_field]

    def _write(self, frame: np.ndarray) -> None:
        r = self.receptive_field
        self._ring[self._pos] = frame
        self._ring[self._pos + r] = frame
        self._pos = (self._pos + 1) % r
        self._filled += 1

    # ------------------------------------------------------------------ per frame

    def push(self, t_s: float, keypoints) -> LiftedPose:
        """One camera frame: ``keypoints`` (17, 3) x, y (pixels of ``camera``), score in the
        lifter's ``keypoint_format``, (17, 2) for all scores 1, or None when nobody was
        seen. Returns the 3D pose for this frame, or an invalid result saying why."""
        ready = self._prepare(t_s, keypoints)
        if isinstance(ready, LiftedPose):
            return ready
        return _finish([self], [ready], *_lift(self, [self]))[0]

    def _prepare(self, t_s: float, keypoints, usable: tuple | None = None) -> LiftedPose | tuple:
        """Everything of :meth:`push` before the model: the frame's verdict when it is invalid, else what
        :func:`_finish` needs once the model has run on :meth:`window` (``(t_s, observed, held, missing)``).
        ``usable``: :meth:`_usable` of the keypoints, made beforehand (:func:`_usable_all`)."""
        st = self.stats
        st.frames += 1
        t_s = float(t_s)
        if not (math.isfinite(t_s) and abs(t_s) <= MAX_TIMESTAMP_S):  # gap arithmetic would overflow
            return self._invalid(t_s, f"{BAD_TIME}: timestamp {t_s}", None)
        if self._last_t is not None and t_s < self._last_t - self.params.lost_timeout_s:
            self.restart()  # the clock went back by more than a lost person's timeout: a new stream
        if self._last_t is not None and t_s <= self._last_t:
            return self._invalid(t_s, f"{TIME_NOT_INCREASING}: {t_s:.4f} s after {self._last_t:.4f} s", None)
        steps = self._steps_since_last(t_s)
        self._last_t = t_s
        self._frames_since_buffered += steps
        observed, why = self._observe(keypoints, usable)
        if self._buffered_t is not None and t_s - self._buffered_t > self.params.lost_timeout_s + 1e-9:
            st.resets += 1  # lost for too long: the buffer no longer describes this person's recent motion
            self.reset()
        frame = self._last_seen.astype(np.float32)
        if why is None and (observed is ALL_JOINTS or observed.all()):
            held = stale = NO_JOINTS  # every joint seen (the usual frame): nothing held, aged or imputed
        else:
            self._age[~observed] += steps
            held = ~observed & (self._age <= self.params.hold_frames)
            stale = ~observed & ~held
            if stale.any():
                if why is not None or not enough_joints(~stale):
                    if why is None:
                        why = f"{MISSING_JOINTS}: " + ", ".join(JOINTS[j] for j in np.flatnonzero(stale))
                    return self._invalid(t_s, why, observed)
                st.joints_missing += int(stale.sum())
                self._impute(frame, stale)
            st.joints_held += int(held.sum())
        self._buffer(frame)
        return t_s, observed, held, stale

    def _impute(self, frame: np.ndarray, stale: np.ndarray) -> None:
        """The model's input for joints missing beyond ``hold_frames`` (in place): the last keypoint
        moved with the image motion the person's other joints made since (``_moved``); a joint never
        seen since the last restart stands at its nearest seen ancestor's keypoint."""
        for j in np.flatnonzero(stale):
            if math.isinf(self._age[j]):
                k = PARENTS[j]
                while stale[k] and PARENTS[k] >= 0:
                    k = PARENTS[k]
                frame[j] = frame[k]
            else:
                frame[j] += self._moved[j].astype(np.float32)

    def _steps_since_last(self, t_s: float) -> int:
        """Frame periods since the previous frame (1, or more when frames were dropped)."""
        if self._last_t is None:
            return 1
        dt = t_s - self._last_t
        if dt <= self.params.max_gap_periods * self._period_s:
            return 1
        steps = max(1, round(dt / self._period_s))
        self.stats.frames_dropped += steps - 1
        return steps

    def _observe(self, keypoints, usable: tuple | None = None) -> tuple[np.ndarray, str | None]:
        """Update the joint memory from this frame; (observed mask, invalid reason or None). ``usable``:
        :meth:`_usable` of the keypoints, when :func:`_usable_all` made it for everyone at once."""
        if keypoints is None:
            self.stats.no_person += 1
            return np.zeros(N_JOINTS, bool), f"{NO_PERSON}: nobody in this frame"
        kp = np.asarray(keypoints, dtype=np.float64)
        if kp.ndim != 2 or kp.shape[0] != N_JOINTS or kp.shape[1] not in (2, 3):
            self.stats.wrong_joint_count += 1
            return np.zeros(N_JOINTS, bool), f"{JOINT_COUNT}: keypoints of shape {kp.shape}, expected (17, 3)"
        ok, norm = self._usable(kp) if usable is None else usable
        if norm is None:
            return ok, None
        if ok is ALL_JOINTS or ok.all():
            self._moved[:] = 0.0
            self._last_seen[:] = norm
            self._age[:] = 0
            return ok, None
        # the image motion of the joints seen now and at their previous sighting moves the joints not seen
        # (each from its own last keypoint): the person walks on while a hand is hidden
        again = ok & (self._age == 0)  # seen in the previous frame too
        if again.any():
            self._moved[~ok] += median_columns(norm[again] - self._last_seen[again])
        self._moved[ok] = 0.0
        self._last_seen[ok] = norm[ok]
        self._age[ok] = 0
        return ok, None

    def _usable(self, kp: np.ndarray) -> tuple[np.ndarray, np.ndarray | None]:
        """(which joints of keypoints ``kp`` (17, 2|3) are usable, their normalised coordinates (17, 2), NaN where
        left out; None when no joint passed the score and finiteness checks)."""
        kp = to_h36m(kp, self.keypoint_format)
        ok = np.isfinite(kp[:, :2]).all(axis=1) & (kp[:, 2] >= self.params.min_score)  # NaN score: False
        if ok.all():  # the usual frame: no row to leave out
            norm = self._pixel_maps().normalised(kp)
        else:
            if not ok.any():
                return ok, None
            # the rows left out stay NaN: each keypoint is mapped on its own, so mapping only the
            # rows kept gives them the same values
            norm = np.full((N_JOINTS, 2), np.nan)
            norm[ok] = self._pixel_maps().normalised(kp[ok])
        # undistortion may fail far outside the image; a point beyond MAX_NORMALISED is no joint
        # this camera saw, and float32 would make a huge one inf in the model's input
        ok &= (np.abs(norm) <= MAX_NORMALISED).all(axis=1)  # NaN: False
        return ok, norm

    def _buffer(self, frame: np.ndarray) -> None:
        """Append a usable frame; bridge a hole since the last one by interpolation, or
        replicate the frame into every slot after a reset (start-up padding)."""
        if self._buffered_t is None:
            self._ring[:] = frame
            self._pos, self._filled = 0, 0
        else:
            gap = self._frames_since_buffered - 1
            if gap > 0:
                last = self._ring[(self._pos - 1) % self.receptive_field].copy()
                for k in range(1, gap + 1):
                    self._write(last + (frame - last) * (k / (gap + 1)))
                self.stats.frames_interpolated += gap
        self._write(frame)
        self._buffered_t = self._last_t
        self._frames_since_buffered = 0

    def _bound_call(self, lifters: list["StreamingLifter"]) -> tuple | None:
        """(run, input, pose, root) for a call on the windows of ``lifters`` (this frame's, ready): the session's
        input and outputs bound once per batch size to arrays of their own (onnxruntime's IOBinding), so a call
        neither converts its feed nor makes its outputs (about 1 % of the bench's frame: reports/bench/s24_react).
        Made, for each batch size, on the first call's windows only if it gives exactly ``session.run``'s results
        on them; None when it does not, or the session has no IOBinding (a stand-in): the plain call then."""
        n = len(lifters)
        bound = self._bindings.get(n, False)
        if bound is False:
            bound = self._bindings[n] = _bind(self.session, [lf.window() for lf in lifters])
        return bound

    def _pixel_maps(self) -> "_PixelMaps":
        """The constants of this lifter's pixel conversions (made again if its cameras or parameters changed)."""
        m = self.__dict__.get("_maps")
        if m is None or not m.made_for(self.camera, self.canonical_camera, self.params):
            m = self._maps = _PixelMaps(self.camera, self.canonical_camera, self.params)
        return m

    def _rays(self, model_joints: np.ndarray | None = None) -> np.ndarray:
        """(17, 3) canonical-camera rays (x/z, y/z, 1) of this frame's keypoints (observed or held):
        the model's input for the last frame, un-normalised (``normalize_screen`` inverted). With
        ``model_joints`` each ray is turned toward the model joint's own projection by at most
        ``ray_tolerance_px`` (input-camera pixels, converted with the focal lengths' ratio)."""
        return _rays_of(StreamingLifter._pixel_maps(self), self._last_seen, model_joints)

    def _invalid(self, t_s: float, reason: str, observed: np.ndarray | None) -> LiftedPose:
        self.stats.invalid[reason.split(":", 1)[0]] += 1
        obs = np.zeros(N_JOINTS, bool) if observed is None else observed
        return LiftedPose(t_s, np.full((N_JOINTS, 3), np.nan), np.full(3, np.nan), False, reason, obs,
                          self.warming_up, 0.0, np.zeros(N_JOINTS, bool))

    # ------------------------------------------------------------------ batch (reference, tools)

    def lift_windows(self, windows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The model on (N, receptive_field, 17, 2) normalised windows: (pose_3d (N, 17, 3),
        root_3d (N, 3)). No buffering, no checks of missing data: a reference and a tool."""
        x = np.ascontiguousarray(windows, dtype=np.float32)
        pose, root = self._run(self._outputs, {INPUT_NAME: x}, None)
        return pose[:, 0], root[:, 0]

    def sibling(self) -> "StreamingLifter":
        """A new lifter for another person: the same session, model checks and parameters,
        its own buffer and clock, counting into the same :class:`LifterStats`."""
        other = object.__new__(StreamingLifter)
        other.__dict__.update({k: v for k, v in self.__dict__.items()
                               if k in ("session", "entry", "params", "source", "name", "precision",
                                        "keypoint_format", "receptive_field", "canonical_camera", "camera",
                                        "_outputs", "_run", "stats", "_period_s", "_batches", "_maps",
                                        "_bindings")})
        r = self.receptive_field
        other._ring = np.zeros((2 * r, N_JOINTS, 2), np.float32)
        other._last_seen = np.zeros((N_JOINTS, 2), np.float64)
        other._moved = np.zeros((N_JOINTS, 2), np.float64)
        other._age = np.full(N_JOINTS, np.inf)
        other._last_t = None
        other.reset()
        return other

    def describe(self) -> dict:
        return {"name": self.name, "precision": self.precision, "source": self.source,
                "receptive_field": self.receptive_field, "threads": self.params.threads,
                "keypoint_format": self.keypoint_format, "canonical_camera": self.canonical_camera.to_dict(),
                "camera": None if self.camera is None else self.camera.to_dict()}

    def __repr__(self) -> str:
        return f"StreamingLifter({self.name!r}, precision={self.precision!r}, rf={self.receptive_field})"


class PeopleLifter:
    """One temporal window per tracked person (module docstring, "Several people").

        people_lifter = PeopleLifter(StreamingLifter.from_manifest(...))
        for pid, pose in people_lifter.push(t_s, tracked_people):   # [(id, LiftedPose)]
            ...
    """

    def __init__(self, lifter: StreamingLifter):
        self.template = lifter
        """Never pushed itself: each person gets a sibling of it."""
        self.lifters: dict[int, StreamingLifter] = {}

    @property
    def stats(self) -> LifterStats:
        return self.template.stats

    def push(self, t_s: float, people) -> list[tuple[int, LiftedPose]]:
        """Lift each person (objects with ``id`` and ``keypoints``) with his own window. A
        person absent for longer than ``lost_timeout_s`` loses his lifter (his window would
        be reset anyway); a shorter absence is bridged like any hole."""
        out, ready = [], []
        usable = _usable_all(self.template, [person.keypoints for person in people])
        for person, usable_i in zip(people, usable):
            lifter = self.lifters.get(person.id)
            if lifter is None:
                lifter = self.lifters[person.id] = self.template.sibling()
            r = lifter._prepare(t_s, person.keypoints, usable_i)
            out.append((person.id, r))
            if not isinstance(r, LiftedPose):
                ready.append((len(out) - 1, lifter, r))
        if ready:
            lifters = [lf for _, lf, _ in ready]
            if self.template._batches:
                finished = _finish(lifters, [r for _, _, r in ready], *_lift(self.template, lifters))
            else:  # a model of a fixed batch size: one call per person
                finished = [_finish([lf], [r], *_lift(lf, [lf]))[0] for _, lf, r in ready]
            for (k, _, _), pose_k in zip(ready, finished):
                out[k] = (out[k][0], pose_k)
        timeout = self.template.params.lost_timeout_s
        for pid in [k for k, lf in self.lifters.items() if lf._last_t is None or not
                    (t_s - timeout <= lf._last_t <= t_s)]:
            del self.lifters[pid]
        return out


def _usable_all(lifter: StreamingLifter, keypoints: list) -> list[tuple | None]:
    """:meth:`StreamingLifter._usable` of several people's keypoints for ``lifter``'s siblings, everyone's in one
    pass when there are several and their normalisation goes element by element (canonical-camera pixels:
    undistortion maps each person apart); None for a person left to his own lifter (keypoints that are not
    (17, 2|3): his lifter says why). Each person's numbers are his own (tests/robot/test_perception_batch_s18.py)."""
    out: list = [None] * len(keypoints)
    maps = lifter._pixel_maps()
    if len(keypoints) < 2 or not maps.canonical_pixels:
        return out
    arrays = [None if k is None else np.asarray(k, dtype=np.float64) for k in keypoints]
    which = [i for i, a in enumerate(arrays) if a is not None and a.ndim == 2 and a.shape[0] == N_JOINTS
             and a.shape[1] in (2, 3)]
    if len(which) < 2:
        return out
    # stacked (as np.stack, cheaper); each person's H36M keypoints come from the tracker's conversion (memo)
    kp = np.array([to_h36m(arrays[i], lifter.keypoint_format) for i in which])
    scored = np.isfinite(kp[..., :2]).all(axis=-1) & (kp[..., 2] >= lifter.params.min_score)  # NaN score: False
    norm = maps.normalised(kp)
    # a row left out below is NaN, which no range check passes: the range is checked on the rows as they are
    ok = scored & (np.abs(norm) <= MAX_NORMALISED).all(axis=-1)
    if ok.all():  # every keypoint of everyone usable (the usual frame): no row to leave out, the shared mask
        for i, norm_i in zip(which, norm):
            out[i] = (ALL_JOINTS, norm_i)
        return out
    if scored.all():
        any_ok = [True] * len(which)
    else:
        any_ok = scored.any(axis=1).tolist()
        norm[~scored] = np.nan  # the rows left out stay NaN, as _usable leaves them
    for i, ok_i, norm_i, kept in zip(which, ok, norm, any_ok):
        out[i] = (ok_i, norm_i if kept else None)
    return out


def _lift(lifter: StreamingLifter, lifters: list[StreamingLifter]) -> tuple[np.ndarray, np.ndarray, float]:
    """One onnxruntime call of ``lifter``'s session on the windows of ``lifters`` (each prepared for this
    frame), in order: (pose_3d (N, 1, 17, 3), root_3d (N, 1, 3), the call's time in s), counted in the
    shared :class:`LifterStats` (``inferences`` per window, ``infer_s`` per call)."""
    bound = lifter._bound_call(lifters)
    if bound is not None:
        binding, x, pose, root = bound
        for k, lf in enumerate(lifters):
            x[k] = lf.window()
        t0 = time.perf_counter()
        binding()
        dt = time.perf_counter() - t0
        pose, root = pose.copy(), root.copy()  # the bound arrays are the next call's too
    else:
        # np.array of the equal-shape windows stacks them, in a third of np.stack's time (no per-call checks)
        x = lifters[0].window()[None] if len(lifters) == 1 else np.array([lf.window() for lf in lifters])
        t0 = time.perf_counter()
        pose, root = lifter._run(lifter._outputs, {INPUT_NAME: x}, None)
        dt = time.perf_counter() - t0
    st = lifter.stats
    st.inferences += len(lifters)
    st.infer_s += dt
    return pose, root, dt


def _bind(session, windows: list[np.ndarray]) -> tuple | None:
    """:meth:`StreamingLifter._bound_call`'s (run, input, pose, root) for a batch of ``len(windows)``, checked on
    ``windows`` against ``session.run``; None when the session has no IOBinding or the two differ."""
    from edge_runtime.core.onnx import same_arrays

    try:
        io = session.io_binding()
        x = np.array(windows, np.float32)
        pose = np.zeros((len(windows), 1, N_JOINTS, 3), np.float32)
        root = np.zeros((len(windows), 1, 3), np.float32)
        # by the arrays' own memory (raw pointers: nothing copied at binding, every call reads and writes them)
        io.bind_input(INPUT_NAME, "cpu", 0, np.float32, x.shape, x.ctypes.data)
        io.bind_output(POSE_OUTPUT, "cpu", 0, np.float32, pose.shape, pose.ctypes.data)
        io.bind_output(ROOT_OUTPUT, "cpu", 0, np.float32, root.shape, root.ctypes.data)
        run = session.run_with_iobinding
        run(io)
        if not same_arrays([pose, root], session.run([POSE_OUTPUT, ROOT_OUTPUT], {INPUT_NAME: x})):
            return None
    except Exception:  # noqa: BLE001 - no (or another) IOBinding: the plain call is the contract
        return None
    return (lambda: run(io)), x, pose, root


def _finish(lifters: list[StreamingLifter], ready: list[tuple], pose: np.ndarray, root: np.ndarray,
            dt: float) -> list[LiftedPose]:
    """Each lifter's pose of this frame from one onnxruntime call on their windows (``pose`` (N, 1, 17, 3),
    ``root`` (N, 1, 3), ``dt`` the call's time) and what each one's :meth:`StreamingLifter._prepare`
    returned. Everyone's arithmetic in one go (element by element, so each person's numbers are those of his
    own); lifters of other cameras or parameters than the first's (never siblings) each on their own."""
    n = len(lifters)
    maps = lifters[0]._pixel_maps()
    if any(not lf._pixel_maps().made_for(*maps.cameras, maps.params) for lf in lifters[1:]):
        return [_finish([lf], [r], pose[i:i + 1], root[i:i + 1], dt)[0]
                for i, (lf, r) in enumerate(zip(lifters, ready))]
    # float32 + float32 added in float64 (each value converted exactly, as astype(float64) then + converts them)
    model_joints = np.add(pose.reshape(n, N_JOINTS, 3), root.reshape(n, 1, 3), dtype=np.float64)
    finite = np.isfinite(model_joints)
    finite = [True] * n if finite.all() else finite.reshape(n, -1).all(axis=1).tolist()
    nearest_m = model_joints[:, :, 2].min(axis=1).tolist()
    out: list = [None] * n
    good = []
    for i, (lf, (t_s, observed, _, _)) in enumerate(zip(lifters, ready)):
        if not finite[i]:
            out[i] = lf._invalid(t_s, "model_output: non-finite joints", observed)
        elif nearest_m[i] < MIN_DEPTH_M:
            out[i] = lf._invalid(t_s, f"model_output: a joint {nearest_m[i]:.2f} m in front of the camera",
                                 observed)
        else:
            good.append(i)
    if not good:
        return out
    model_joints = model_joints if len(good) == n else model_joints[good]
    seen = np.array([lifters[i]._last_seen for i in good])  # stacked (as np.stack, cheaper)
    joints = _rays_of(maps, seen, model_joints) * model_joints[..., 2:3]
    for k, i in enumerate(good):
        lf, (t_s, observed, held, missing) = lifters[i], ready[i]
        if missing is not NO_JOINTS and missing.any():
            # a missing joint's ray is its imputed keypoint's: the model's own joint is as good a guess
            joints[k][missing] = model_joints[k][missing]
        st = lf.stats
        warming = lf.warming_up
        st.valid += 1
        st.warming_up += warming
        out[i] = LiftedPose(t_s, joints[k], joints[k, HIP].copy(), True, None, observed, warming, dt, held,
                            model_joints[k], missing)
    return out


def _rays_of(maps: "_PixelMaps", last_seen: np.ndarray, model_joints: np.ndarray | None) -> np.ndarray:
    """:meth:`StreamingLifter._rays` of keypoints ``last_seen`` (..., 17, 2) (normalised) and ``model_joints``
    (..., 17, 3) or None: one person's or several people's at once, element by element the same."""
    px = (last_seen + maps.screen_offset) * maps.half_width_px
    if model_joints is not None and maps.tolerance_px > 0:
        toward = model_joints[..., :2] / model_joints[..., 2:3] * maps.focal_px + maps.centre_px - px
        # np.linalg.norm(toward, axis=-1, keepdims=True) to the bit
        dist = norms2(toward.reshape(-1, 2)).reshape(toward.shape[:-1] + (1,))
        px = px + toward * np.minimum(1.0, maps.tolerance_px / np.maximum(dist, 1e-9))
    rays = np.empty(px.shape[:-1] + (3,))
    rays[..., :2] = (px - maps.centre_px) / maps.focal_px
    rays[..., 2] = 1.0
    return rays


class _PixelMaps:
    """A lifter's pixel conversions: the keypoints' normalisation (:func:`edge_runtime.robot.keypoints.
    image_to_canonical`) and the constants of its inverse, made once instead of in every frame (the offset
    of :func:`edge_runtime.robot.keypoints.normalize_screen`, the canonical camera's focal lengths and centre,
    and the ray tolerance in canonical pixels)."""

    def __init__(self, camera: CameraModel | None, canonical: CameraModel, params: LifterParams):
        self.cameras, self.params = (camera, canonical), params
        self.screen_offset = np.array([1.0, canonical.height_px / canonical.width_px])
        self.width_px = canonical.width_px
        self.canonical_pixels = camera is None or camera.same_pixels_as(canonical)
        """The keypoints are canonical-camera pixels already (:meth:`CameraModel.to_camera` would copy them)."""
        self.half_width_px = canonical.width_px / 2
        self.focal_px = np.array([canonical.fx_px, canonical.fy_px], np.float64)
        self.centre_px = np.array([canonical.cx_px, canonical.cy_px], np.float64)
        self.tolerance_px = params.ray_tolerance_px * canonical.fx_px / (camera.fx_px if camera is not None
                                                                         else canonical.fx_px)

    def made_for(self, camera, canonical, params) -> bool:
        return self.cameras[0] is camera and self.cameras[1] is canonical and self.params is params

    def normalised(self, kp: np.ndarray) -> np.ndarray:
        """(n, 3) keypoints in the input camera's pixels -> normalised canonical coordinates (n, 2)."""
        if self.canonical_pixels:  # normalize_screen's arithmetic, its constants made once
            return kp[..., :2] / self.width_px * 2 - self.screen_offset
        return image_to_canonical(kp, *self.cameras)


def _symbolic_batch(session) -> bool:
    """Whether the lifter input's batch dimension is symbolic (a name or None), so that the windows of
    several people can go in one call; a fixed one (an int) takes one window at a time."""
    shape = next((i.shape for i in session.get_inputs() if i.name == INPUT_NAME), None)
    return bool(shape) and not isinstance(shape[0], int)


def padded_windows(frames: np.ndarray, receptive_field: int) -> np.ndarray:
    """(T, 17, 2) -> (T, receptive_field, 17, 2): frame t's causal window, the sequence
    padded at its start by replicating frame 0 (the streaming lifter's start-up padding)."""
    f = np.asarray(frames)
    pad = np.repeat(f[:1], receptive_field - 1, axis=0)
    full = np.concatenate([pad, f], axis=0)
    idx = np.arange(len(f))[:, None] + np.arange(receptive_field)[None, :]
    return full[idx]


def _check_entry(entry: dict, source: str) -> tuple[int, CameraModel]:
    """(receptive field, canonical camera) from a lifter manifest entry."""
    rf = entry.get("receptive_field", 27)
    if isinstance(rf, bool) or not isinstance(rf, int) or not 1 <= rf <= MAX_RECEPTIVE_FIELD:
        raise ModelIntegrityError(f"{source}: manifest field 'receptive_field': expected an integer in "
                                  f"[1, {MAX_RECEPTIVE_FIELD}], got {rf!r}"[:300])
    if entry.get("joints", JOINT_SET) != JOINT_SET:
        raise ModelIntegrityError(f"{source}: manifest field 'joints': {entry.get('joints')!r}, this runtime "
                                  f"feeds {JOINT_SET}")
    if "camera" not in entry:
        raise ModelIntegrityError(f"{source}: manifest field 'camera': missing (the canonical camera the "
                                  "lifter was trained for)")
    try:
        cam = CameraModel.from_dict(entry["camera"], "manifest field 'camera'")
    except ValueError as e:
        raise ModelIntegrityError(f"{source}: {e}") from None
    return rf, cam


def _check_session(session, rf: int, source: str) -> None:
    """The session has the lifter's input and outputs, with the right shapes on a probe."""
    inputs = {i.name: i.shape for i in session.get_inputs()}
    outputs = {o.name for o in session.get_outputs()}
    if INPUT_NAME not in inputs or not {POSE_OUTPUT, ROOT_OUTPUT} <= outputs:
        raise ModelIntegrityError(f"{source}: expected input {INPUT_NAME!r} and outputs {POSE_OUTPUT!r}, "
                                  f"{ROOT_OUTPUT!r}; the model has {sorted(inputs)} -> {sorted(outputs)}")
    try:
        pose, root = session.run([POSE_OUTPUT, ROOT_OUTPUT], {INPUT_NAME: np.zeros((1, rf, N_JOINTS, 2), np.float32)})
    except Exception as e:  # onnxruntime's own exception types
        msg = " ".join(str(e).split())[:200]
        raise ModelIntegrityError(f"{source}: the model does not take (1, {rf}, 17, 2) keypoints ({msg})") from None
    if pose.shape != (1, 1, N_JOINTS, 3) or root.shape != (1, 1, 3):
        raise ModelIntegrityError(f"{source}: outputs of shape {pose.shape} and {root.shape}, expected "
                                  f"(1, 1, 17, 3) and (1, 1, 3)")


__all__ = ["LifterParams", "LiftedPose", "LifterStats", "StreamingLifter", "PeopleLifter", "padded_windows", "LIFTER_ARCH", "MIN_DEPTH_M"]
