"""Keypoints from a camera: OpenCV capture -> a user-supplied 2D pose ONNX model -> people.

    model = PoseModel("pose.onnx", keypoint_format="coco")
    with CameraKeypointSource("0", model) as src:      # a device index, a video file or a URL
        for item in src.frames():
            if isinstance(item, CameraStatus):          # "stalled", "ok" again, "ended"
                ...
            else:                                       # CameraFrame: t_s, index, people
                pose = lifter.push(item.t_s, selector.select(item.people)...)

The 2D pose model contract
==========================
The box does not ship a 2D detector: the integrator brings one (an export of
Detectron2 keypoint R-CNN, MMPose/RTMPose, YOLO-pose, ...) as ONNX with this
interface:

* **input**: one float32 tensor (1, 3, H, W), its first input (any name): the
  camera image as RGB in [0, 1], **letterboxed** to W x H: scaled by
  ``s = min(W / w, H / h)`` keeping the aspect ratio (bilinear), centred, the
  border filled with 0.5 grey. H and W are read from the model; a model with
  dynamic H, W gets ``CameraSourceParams.input_hw``.
* **output**, either (chosen by the output's name, else by its shape):

  - ``keypoints`` float32 (1, P, 17, 3): P >= 0 people, each 17 keypoints
    (x, y in the model's input pixels, score in [0, 1]). A person whose best
    score is below ``min_person_score`` is padding and dropped;
  - ``heatmaps`` float32 (1, 17, h, w): one person. Each joint is the peak of its
    map (cell centres map to input pixels as ``(i + 0.5) * W / w``); the peak
    value is its score.

* **keypoint order**: COCO-17 by default (``keypoint_format="coco"``) or H36M-17.

Keypoints come back in the camera image's own pixels (the letterbox undone),
ready for :mod:`edge_runtime.robot.keypoints` (undistortion) and the lifter.

Faults (docs/design.md section 8: degrade loudly)
=========================================
* A source that cannot be opened, or a pose model that is missing or that
  onnxruntime refuses: :class:`CameraError` / ``ModelIntegrityError`` naming it.
* A zero-size or unreadable image (None, empty, wrong dtype or shape) is SKIPPED
  and counted (``stats.bad_images``); the lifter then sees a dropped frame.
* A stalled camera (no frame for ``stall_timeout_s``) is reported once as a
  :class:`CameraStatus` "stalled" (counted), "ok" when frames return; after
  ``give_up_s`` without a frame the source reports "disconnected" and ends.
  The capture is read on its own thread, so a read() that blocks inside the
  driver cannot block the loop that reports the stall.
* A live camera that delivers faster than the model runs: the oldest waiting
  frame is dropped (``stats.frames_dropped``); a video file is read in full.
"""
from __future__ import annotations

import logging
import math
import os
import queue
import threading
import time
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Iterator

import numpy as np

from edge_runtime import config
from edge_runtime.core.manifest import ModelIntegrityError
from edge_runtime.errors import InputError
from edge_runtime.robot.keypoints import FORMATS, Person

log = logging.getLogger(__name__)

PAD_VALUE = 0.5
"""Letterbox border (RGB in [0, 1])."""


class CameraError(InputError):
    """A camera source that cannot be opened or used; the message names it."""


class BadImageError(InputError):
    """An image the pose model cannot take (zero-size, wrong shape or type)."""


@config.section("camera")
@dataclass(frozen=True)
class CameraParams:
    """The camera and keypoint input of the robot loop."""

    device: str = ""
    """The robot loop's camera when no input flag is given: an OpenCV device index ("0"), a
    video file or a stream URL; empty = none configured."""
    rate_hz: float = config.setting(30.0, ("a number in (0, 240]", lambda v: 0 < v <= 240))
    """Frames per second the camera delivers and the loop expects."""
    keypoint_format: str = config.setting("coco", config.one_of("coco", "h36m"))
    """2D keypoint layout of the input: "coco" (COCO-17) or "h36m"."""
    intrinsics: str = ""
    """JSON file with the camera model (K, distortion, size); empty = the lifter's own camera."""
    pose_model: str = ""
    """ONNX 2D pose model for --camera; empty = none configured."""


@config.section("camera_source")
@dataclass(frozen=True)
class CameraSourceParams:
    """Tunables of the camera path."""

    stall_timeout_s: float = 1.0
    """No frame for this long: the camera is reported stalled."""
    give_up_s: float = 10.0
    """No frame for this long: the camera is reported disconnected and the source ends."""
    min_person_score: float = 0.05
    """A detected person whose best keypoint score is below this is padding, not a person."""
    input_hw: tuple[int, int] = (0, 0)
    """(H, W) for a pose model with dynamic input size; (0, 0) = read them from the model."""
    default_fps: float = 30.0
    """Frame rate for a video file that does not state one (timestamps = index / fps)."""

    def __post_init__(self):
        if not (0 < self.stall_timeout_s <= self.give_up_s):
            raise ValueError("stall_timeout_s must be > 0 and <= give_up_s")
        if not (self.default_fps > 0 and math.isfinite(self.default_fps)):
            raise ValueError("default_fps must be a positive number")


# ---------------------------------------------------------------------------- images


def check_image(image) -> np.ndarray:
    """``image`` as an (h, w, 3) uint8 BGR array, or :class:`BadImageError` saying why."""
    if image is None:
        raise BadImageError("no image")
    a = np.asarray(image)
    if a.ndim == 2:
        a = np.repeat(a[:, :, None], 3, axis=2)
    if a.ndim != 3 or a.shape[2] not in (3, 4):
        raise BadImageError(f"image of shape {a.shape}, expected (h, w, 3)")
    if a.shape[0] == 0 or a.shape[1] == 0:
        raise BadImageError(f"zero-size image {a.shape}")
    if a.dtype != np.uint8:
        raise BadImageError(f"image of dtype {a.dtype}, expected uint8")
    return a[:, :, :3]


def letterbox(image_bgr: np.ndarray, height: int, width: int) -> tuple[np.ndarray, float, np.ndarray]:
    """(model input (1, 3, H, W) float32 RGB in [0, 1], scale s, offset (ox, oy) px).

    Input pixel = image pixel * s + offset."""
    import cv2

    img = check_image(image_bgr)
    h, w = img.shape[:2]
    s = min(width / w, height / h)
    nw, nh = max(1, round(w * s)), max(1, round(h * s))
    resized = cv2.resize(img, (nw, nh), interpolation=cv2.INTER_LINEAR)
    ox, oy = (width - nw) // 2, (height - nh) // 2
    canvas = np.full((height, width, 3), PAD_VALUE, np.float32)
    canvas[oy:oy + nh, ox:ox + nw] = resized[:, :, ::-1] / np.float32(255)
    return np.ascontiguousarray(canvas.transpose(2, 0, 1)[None]), s, np.array([ox, oy], np.float64)


# ---------------------------------------------------------------------------- the pose model


class PoseModel:
    """A user-supplied 2D pose ONNX model (see the module docstring for its contract)."""

    def __init__(self, path: str | os.PathLike, *, keypoint_format: str = "coco", threads: int = 1,
                 params: CameraSourceParams = CameraSourceParams()):
        if keypoint_format not in FORMATS:
            raise ValueError(f"keypoint format {keypoint_format!r}: one of {', '.join(FORMATS)}")
        p = Path(path)
        if not p.is_file():
            raise ModelIntegrityError(f"{p}: pose model file not found")
        self.path = p
        self.keypoint_format = keypoint_format
        self.params = params
        from edge_runtime.core.onnx import open_session  # onnxruntime loads only when a model is opened

        self.session = open_session(p, threads, str(p))
        inp = self.session.get_inputs()[0]
        self.input_name = inp.name
        shape = list(inp.shape)
        if len(shape) != 4 or (isinstance(shape[1], int) and shape[1] != 3):
            raise ModelIntegrityError(f"{p}: input {inp.name!r} of shape {shape}, expected (1, 3, H, W)")
        hw = tuple(d if isinstance(d, int) and d > 0 else None for d in shape[2:])
        if None in hw:
            if 0 in params.input_hw:
                raise ModelIntegrityError(f"{p}: input {inp.name!r} has dynamic size {shape}; set input_hw")
            hw = params.input_hw
        self.input_hw: tuple[int, int] = (int(hw[0]), int(hw[1]))
        self.output_name, self.output_kind = self._pick_output()

    def _pick_output(self) -> tuple[str, str]:
        outs = self.session.get_outputs()
        by_name = {o.name: o for o in outs}
        for kind in ("keypoints", "heatmaps"):
            if kind in by_name:
                return kind, kind
        for o in outs:
            s = o.shape
            if len(s) == 4 and s[2] == 17 and s[3] == 3:
                return o.name, "keypoints"
            if len(s) == 4 and s[1] == 17:
                return o.name, "heatmaps"
        raise ModelIntegrityError(f"{self.path}: no output 'keypoints' (1, P, 17, 3) or 'heatmaps' (1, 17, h, w); "
                                  f"the model has {[(o.name, o.shape) for o in outs]}")

    def detect(self, image_bgr) -> list[Person]:
        """People in one BGR image, keypoints (17, 3) in the image's pixels. Raises
        :class:`BadImageError` for an image the model cannot take."""
        height, width = self.input_hw
        x, s, offset = letterbox(image_bgr, height, width)
        out = self.session.run([self.output_name], {self.input_name: x})[0]
        if self.output_kind == "keypoints":
            kp = np.asarray(out, np.float64).reshape(-1, 17, 3)
        else:
            kp = _heatmap_peaks(np.asarray(out, np.float64), height, width)[None]
        kp = kp[np.nan_to_num(kp[:, :, 2], nan=0).max(axis=1) >= self.params.min_person_score].copy()
        kp[:, :, :2] = (kp[:, :, :2] - offset) / s
        return [Person(k) for k in kp]


def _heatmap_peaks(hm: np.ndarray, height: int, width: int) -> np.ndarray:
    """(1, 17, h, w) heatmaps -> (17, 3) peaks in input pixels, peak value as score."""
    maps = hm.reshape(hm.shape[-3], -1)
    h, w = hm.shape[-2:]
    idx = maps.argmax(axis=1)
    iy, ix = np.divmod(idx, w)
    return np.stack([(ix + 0.5) * width / w, (iy + 0.5) * height / h, maps.max(axis=1)], axis=1)


# ---------------------------------------------------------------------------- the source


@dataclass
class CameraFrame:
    t_s: float
    """Stream time (s): index / fps for a file, monotonic time since opening for a live source."""
    index: int
    people: list[Person]


@dataclass
class CameraStatus:
    state: str
    """"stalled" (no frame for stall_timeout_s), "ok" (frames again), "ended" (end of a
    file), "disconnected" (no frame for give_up_s)."""
    since_s: float
    """Seconds since the last frame."""

    def log(self) -> None:
        """One log line (event ``camera_state``): a warning unless the frames are back. Logged with
        ``--quiet`` too: a service's journal must show a camera that stalled."""
        log.log(logging.INFO if self.state == "ok" else logging.WARNING, "camera %s (%.2f s since the last frame)",
                self.state, self.since_s, extra={"event": "camera_state"})


@dataclass
class CameraStats:
    frames: int = 0
    """Images read and passed to the pose model."""
    bad_images: int = 0
    """Zero-size or unreadable images, skipped."""
    read_failures: int = 0
    """read() calls of a live source that returned no image."""
    frames_dropped: int = 0
    """Live frames dropped because the model was still busy with an older one."""
    stalls: int = 0

    def to_json(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}


def open_capture(spec: str):
    """``cv2.VideoCapture`` for a device index ("0"), a URL ("rtsp://...") or a video file;
    (capture, is_live). Refuses what cannot be opened, naming it."""
    import cv2

    live = spec.isdigit() or "://" in spec
    if not live and not Path(spec).is_file():
        raise CameraError(f"{spec}: video file not found")
    cap = cv2.VideoCapture(int(spec) if spec.isdigit() else spec)
    if not cap.isOpened():
        raise CameraError(f"{spec}: OpenCV cannot open this {'camera' if live else 'video file'}")
    return cap, live


class CameraKeypointSource:
    """Frames from a capture (anything with ``read() -> (ok, image)``), through a pose model.

    ``capture`` may be a spec string for :func:`open_capture` or an opened capture
    object (then ``live`` says whether it is a live source)."""

    def __init__(self, capture, pose_model: PoseModel, params: CameraSourceParams = CameraSourceParams(), *,
                 live: bool | None = None, fps: float | None = None):
        if isinstance(capture, str):
            self.name = capture
            capture, is_live = open_capture(capture)
            live = is_live if live is None else live
        else:
            self.name = type(capture).__name__
        self.cap = capture
        self.live = bool(live)
        self.model = pose_model
        self.params = params
        self.stats = CameraStats()
        self.fps = fps or self._capture_fps() or params.default_fps
        self._queue: queue.Queue = queue.Queue(maxsize=2)
        self._stop = threading.Event()
        self._t0 = time.monotonic()
        self._thread = threading.Thread(target=self._reader, name="camera-reader", daemon=True)
        self._thread.start()

    def frame_size(self) -> tuple[int, int] | None:
        """(width, height) in pixels as the capture reports it, or None when it does not."""
        try:
            import cv2

            w, h = int(self.cap.get(cv2.CAP_PROP_FRAME_WIDTH)), int(self.cap.get(cv2.CAP_PROP_FRAME_HEIGHT))
        except Exception:  # a capture object without get()
            return None
        return (w, h) if w > 0 and h > 0 else None

    def _capture_fps(self) -> float:
        try:
            import cv2

            v = float(self.cap.get(cv2.CAP_PROP_FPS))
        except Exception:  # a capture object without get()
            return 0.0
        return v if math.isfinite(v) and 0 < v < 1000 else 0.0

    # the reader thread: (t_s, image) items, None at the end of a file
    def _reader(self) -> None:
        index = 0
        while not self._stop.is_set():
            try:
                ok, image = self.cap.read()
            except Exception:  # a driver error is a failed read
                ok, image = False, None
            t = index / self.fps if not self.live else time.monotonic() - self._t0
            if not ok:
                if not self.live:
                    self._put(None)
                    return
                self.stats.read_failures += 1
                time.sleep(min(0.01, self.params.stall_timeout_s / 4))
                continue
            index += 1
            self._put((t, index - 1, image))

    def _put(self, item) -> None:
        while not self._stop.is_set():
            try:
                self._queue.put(item, timeout=0.05)
                return
            except queue.Full:
                if self.live and item is not None:
                    try:
                        self._queue.get_nowait()
                        self.stats.frames_dropped += 1
                    except queue.Empty:
                        pass

    def frames(self) -> Iterator[CameraFrame | CameraStatus]:
        """Frames with the people the pose model saw, and status changes, until the end of
        a file, a disconnection, or :meth:`close`."""
        last = time.monotonic()
        stalled = False
        p = self.params
        while not self._stop.is_set():
            try:
                item = self._queue.get(timeout=p.stall_timeout_s if not stalled else 0.1)
            except queue.Empty:
                since = time.monotonic() - last
                if since >= p.give_up_s:
                    yield CameraStatus("disconnected", since)
                    return
                if not stalled and since >= p.stall_timeout_s:
                    stalled = True
                    self.stats.stalls += 1
                    yield CameraStatus("stalled", since)
                continue
            if item is None:
                yield CameraStatus("ended", time.monotonic() - last)
                return
            now = time.monotonic()
            if stalled:
                stalled = False
                yield CameraStatus("ok", now - last)
            last = now
            t_s, index, image = item
            try:
                people = self.model.detect(image)
            except BadImageError:
                self.stats.bad_images += 1
                continue
            self.stats.frames += 1
            yield CameraFrame(t_s, index, people)

    def close(self) -> None:
        """Stop the reader thread, then release the capture (OpenCV must not release a
        capture while another thread reads it; a read blocked in the driver gets 1 s)."""
        self._stop.set()
        self._thread.join(timeout=1.0)
        try:
            self.cap.release()
        except Exception:  # a capture without release(), or a driver error on the way out
            pass

    def __enter__(self) -> "CameraKeypointSource":
        return self

    def __exit__(self, *exc) -> None:
        self.close()
