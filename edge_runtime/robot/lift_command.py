"""``python -m edge_runtime lift``: 2D keypoints -> the streaming lifter -> 3D joints per frame.

    python -m edge_runtime lift --keypoints KP.jsonl --format coco --width 1920 --height 1080 \\
        [--camera CAM.json] [--assets DIR] [--precision int8|fp32] [--threads N] --out OUT.jsonl
    python -m edge_runtime lift --video PATH|DEVICE|URL --pose-model POSE.onnx [--camera CAM.json] --out OUT.jsonl

Input: a JSON-lines keypoint file (:func:`edge_runtime.robot.keypoints.read_keypoints_jsonl`),
read and checked in full before the model loads, or a camera / video through OpenCV and a
2D pose ONNX model (:mod:`edge_runtime.robot.camera_source`, its contract in the docstring).

The camera: ``--camera CAM.json`` (fx_px, fy_px, cx_px, cy_px, width_px, height_px and
OpenCV ``dist``); without it, a distortion-free camera with the lifter's 100 degree
horizontal field of view at ``--width`` x ``--height`` (a video's own size by default).

Output (``--out``): one JSON object per frame -- ``t``, ``frame``, ``person`` (the
exporter's id), ``valid``, ``reason``, ``warming_up``, ``observed`` and ``held`` (17
booleans each: seen in this frame / standing at its last observation), ``joints_cam_m``
(17 x [x, y, z], metres, camera frame, each joint on its keypoint's ray; null when invalid)
and ``root_cam_m`` -- then one ``{"summary": {...}}`` line: frames, valid share, mean
per-frame lifter time (ms) and every counter. The summary is also printed.

``--person all`` lifts every person: they are tracked with stable ids
(:class:`edge_runtime.robot.keypoints.PersonTracker`, ``[people]`` of ``--config``) and each is
lifted with his own window (:class:`edge_runtime.robot.lifter.PeopleLifter`). A frame's line is
then ``{"t", "frame", "valid", "reason", "people": [{"id", "source_id", "warming_up",
"joints_cam_m", "root_cam_m", "observed", "held", "joints_model_cam_m"}, ...], "invalid": [{"id", "reason"}, ...]}``:
``people`` holds the valid lifts, ``invalid`` the others, and the frame is valid when nobody is
invalid -- the form ``python -m edge_runtime robot --joints`` reads (``joints_model_cam_m``: the
network's own joints before they were put on the keypoints' rays, for evaluation).
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np

from edge_runtime.cli import CliError, positive_float, positive_int, probability
from edge_runtime.core.manifest import PRECISIONS, ModelIntegrityError
from edge_runtime.robot.camera_source import CameraError
from edge_runtime.robot.keypoints import FORMATS, SELECT_MODES, CameraModel, KeypointInputError, PersonSelector

BAD_INPUT = (KeypointInputError, CameraError, ModelIntegrityError)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    src = parser.add_mutually_exclusive_group(required=True)
    src.add_argument("--keypoints", metavar="FILE.jsonl", help="2D keypoints, one JSON object per frame")
    src.add_argument("--video", metavar="PATH|DEVICE|URL", help="a video file, a camera index or a stream URL")
    parser.add_argument("--pose-model", metavar="POSE.onnx", help="2D pose ONNX model for --video (contract: "
                        "edge_runtime/camera_source.py)")
    parser.add_argument("--format", choices=FORMATS, default="coco", help="keypoint layout [coco]")
    parser.add_argument("--width", type=positive_int, metavar="PX", help="image width of the keypoints' camera")
    parser.add_argument("--height", type=positive_int, metavar="PX", help="image height of the keypoints' camera")
    parser.add_argument("--camera", metavar="CAM.json", help="camera intrinsics and OpenCV distortion")
    parser.add_argument("--assets", metavar="DIR", help="model directory with manifest.json [edge_runtime/assets]")
    parser.add_argument("--config", metavar="BOX.toml", help="the box configuration; its [lifter] section "
                        "(edge_runtime/box.example.toml)")
    parser.add_argument("--precision", choices=PRECISIONS, help="which lifter [lifter] precision (int8)")
    parser.add_argument("--threads", type=positive_int, help="onnxruntime intra-op threads [lifter] threads (1)")
    parser.add_argument("--person", default="largest", metavar="all|" + "|".join(SELECT_MODES) + "|id:N",
                        help="whom to lift when several people are seen: all of them (tracked), or one [largest]")
    parser.add_argument("--min-score", type=probability, help="keypoints scoring lower are missing "
                        "[lifter] min_score (0.3)")
    parser.add_argument("--hold-frames", type=int, help="frames a missing joint is held [lifter] hold_frames (3)")
    parser.add_argument("--fps", type=positive_float, default=30.0,
                        help="frame rate for lines with 'frame' but no 't' [30]")
    parser.add_argument("--out", metavar="OUT.jsonl", help="per-frame results and a summary line")
    parser.add_argument("--quiet", action="store_true", help="no status lines on stderr")


ALL = "all"


def _selector(spec: str, min_score: float) -> PersonSelector | None:
    """The one person to follow (None: ``--person all``)."""
    if spec == ALL:
        return None
    if spec.startswith("id:"):
        try:
            return PersonSelector("track", track_id=int(spec[3:]), min_score=min_score)
        except ValueError:
            raise CliError(f"--person {spec}: expected id:<integer>") from None
    if spec not in SELECT_MODES:
        raise CliError(f"--person {spec}: {ALL}, one of {', '.join(SELECT_MODES)} or id:N")
    return PersonSelector(spec, min_score=min_score)


def _camera(args, size: tuple[int, int] | None) -> CameraModel:
    """--camera, else the canonical field of view at --width x --height (or the video's size)."""
    if args.camera:
        cam = CameraModel.from_json(args.camera)
        for flag, given, have in (("--width", args.width, cam.width_px), ("--height", args.height, cam.height_px)):
            if given is not None and given != have:
                raise CliError(f"{flag} {given} disagrees with {args.camera} ({have} px)")
        return cam
    w, h = args.width, args.height
    if (w is None or h is None) and size:
        w, h = w or size[0], h or size[1]
    if w is None or h is None:
        raise CliError("give the image size (--width and --height) or a camera file (--camera CAM.json)")
    return CameraModel.from_fov(w, h)


def _params(args):
    """The [lifter] and [people] sections of --config (defaults without one), the flags on top."""
    from edge_runtime import config
    from edge_runtime.robot import lifter  # noqa: F401 - [lifter], [people]

    cfg = config.override(config.load(args.config), "lifter", precision=args.precision, threads=args.threads,
                          min_score=args.min_score, hold_frames=args.hold_frames)
    return cfg.lifter, cfg.people


def _frames_from_file(args):
    """[(t_s, frame, people)], read and checked in full before any model loads."""
    from edge_runtime.robot.keypoints import read_keypoints_jsonl

    frames = [(f.t_s, f.frame, f.people) for f in read_keypoints_jsonl(args.keypoints, args.format, args.fps)]
    if not frames:
        raise KeypointInputError(f"{args.keypoints}: no frames")
    return frames, None


def _frames_from_video(args, stats: dict, threads: int):
    from edge_runtime.robot.camera_source import CameraFrame, CameraKeypointSource, PoseModel

    if not args.pose_model:
        raise CliError("--video needs --pose-model POSE.onnx (the 2D keypoint detector)")
    model = PoseModel(args.pose_model, keypoint_format=args.format, threads=threads)
    source = CameraKeypointSource(args.video, model)

    def frames():
        try:
            for item in source.frames():
                if isinstance(item, CameraFrame):
                    yield item.t_s, item.index, item.people
                    continue
                stats[item.state] = stats.get(item.state, 0) + 1
                item.log()
        finally:
            source.close()
            stats.update(source.stats.to_json())

    return frames(), source.frame_size()


def cmd(args) -> int:
    from edge_runtime.core.manifest import ASSETS_DIR
    from edge_runtime.robot.lifter import StreamingLifter

    params, tracking = _params(args)
    selector = _selector(args.person, params.min_score)
    camera_stats: dict = {}
    frames, size = _frames(args, camera_stats, params.threads)
    camera = _camera(args, size)
    lifter = StreamingLifter.from_manifest(args.assets or ASSETS_DIR, params, camera=camera,
                                           keypoint_format=args.format)
    try:
        out = open(args.out, "w", encoding="utf-8") if args.out else None
    except OSError as e:
        raise CliError(f"--out {args.out}: cannot write ({e.strerror or e})") from None
    t_wall = time.perf_counter()
    try:
        if selector is None:
            _lift_everyone(frames, tracking, lifter, out)
        else:
            _lift_all(frames, selector, lifter, out)
    except KeyboardInterrupt:
        pass
    finally:
        summary = {"model": lifter.name, "precision": lifter.precision, "threads": params.threads,
                   "camera": camera.to_dict(), "wall_s": round(time.perf_counter() - t_wall, 3),
                   **lifter.stats.to_json()}
        if camera_stats:
            summary["camera_source"] = camera_stats
        if out:
            out.write(json.dumps({"summary": summary}) + "\n")
            out.close()
    print(_summary_text(lifter, summary, args.out))
    return 0


def _frames(args, camera_stats: dict, threads: int):
    """(frames, the video's size or None) from --keypoints or --video."""
    if args.keypoints:
        if args.pose_model:
            raise CliError("--pose-model goes with --video, not --keypoints")
        return _frames_from_file(args)
    return _frames_from_video(args, camera_stats, threads)


def _lift_all(frames, selector: PersonSelector, lifter, out) -> None:
    """Every frame's followed person through the lifter; one JSON line each to ``out``."""
    for t_s, index, people in frames:
        person = selector.select(people)
        pose = lifter.push(t_s, None if person is None else person.keypoints)
        if out:
            rec = {"t": t_s, "frame": index, "person": None if person is None else person.id}
            rec.update(pose.to_json())
            out.write(json.dumps(rec) + "\n")


def _lift_everyone(frames, tracking, lifter, out) -> None:
    """Every person of every frame, tracked and lifted with his own window; one JSON line per frame."""
    from edge_runtime.robot.keypoints import PersonTracker
    from edge_runtime.robot.lifter import PeopleLifter

    tracker, people_lifter = PersonTracker(tracking), PeopleLifter(lifter)
    for t_s, index, people in frames:
        tracked = tracker.update(t_s, people)
        source = {p.id: p.source_id for p in tracked}
        poses = people_lifter.push(t_s, tracked)
        valid = [{"id": pid, "source_id": source[pid], **_person_json(pose)} for pid, pose in poses if pose.valid]
        invalid = [{"id": pid, "reason": pose.reason} for pid, pose in poses if not pose.valid]
        if out:
            out.write(json.dumps({"t": t_s, "frame": index, "valid": not invalid,
                                  "reason": None if not invalid else f"person {invalid[0]['id']}: {invalid[0]['reason']}",
                                  "people": valid, "invalid": invalid}) + "\n")


def _person_json(pose) -> dict:
    d = pose.to_json()
    model = np.round(pose.joints_model_cam_m, 5).tolist()  # the network's own joints, for evaluation
    return {**{k: d[k] for k in ("warming_up", "joints_cam_m", "root_cam_m", "observed", "held")},
            "joints_model_cam_m": model}


def _summary_text(lifter, summary: dict, out_path: str | None) -> str:
    s = lifter.stats
    invalid = ", ".join(f"{k} {v}" for k, v in sorted(s.invalid.items())) or "none"
    mean = f"{s.mean_infer_ms:.3f} ms" if s.inferences else "n/a"
    camera_stats = summary.get("camera_source")
    return (f"summary: {s.frames} frames, valid {s.valid} ({summary['valid_share']:.1%}; warming up "
            f"{s.warming_up}), mean lifter time {mean} per frame ({lifter.name}, {summary['threads']} thread(s))\n"
            f"  invalid: {invalid}; joints held {s.joints_held}, frames dropped {s.frames_dropped}, "
            f"interpolated {s.frames_interpolated}, resets {s.resets}"
            + ("\n  camera: " + ", ".join(f"{k} {v}" for k, v in camera_stats.items()) if camera_stats else "")
            + (f"\n  written to {out_path}" if out_path else ""))
