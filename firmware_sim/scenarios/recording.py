"""A ready-to-use recording for a newcomer, and the varied motion that tests the lifter.

    python -m firmware_sim record --out DIR [--seconds 60] [--people 3] [--seed S] [--noise real|default]

writes, from one simulated camera (3-8 m from the cell, 1-3 m high, a wide-angle lens with
barrel distortion, 30 Hz):

* ``DIR/keypoints.jsonl`` -- COCO-17 keypoints of several people, as a 2D detector exports
  them (:func:`edge_runtime.robot.keypoints.read_keypoints_jsonl`'s form; each person's
  ``id`` is the exporter's, which the runtime's tracker does not rely on, and the people of a
  frame come in random order); the detector errs at a real detector's scale
  (:data:`firmware_sim.devices.camera.REAL_DETECTOR`) and people hide each other
  (:func:`firmware_sim.devices.camera.occlude`);
* ``DIR/camera.json`` -- its intrinsics and distortion (``--intrinsics`` / ``--camera`` of the
  runtime's commands), plus the true extrinsics (``R``, ``t_m``; the runtime ignores them);
* ``DIR/calibration.jsonl`` -- one worker walking onto the three floor markers and standing 3 s
  on each (``python -m edge_runtime robot --keypoints ... --calibrate CAL.json``);
* ``DIR/truth.jsonl`` -- per frame and person: ``id``, ``motion`` (the motion type),
  ``joints_robot_m`` and ``camera_joints_m`` (H36M-17, metres): the form ``python -m
  edge_runtime robot --joints`` reads, so the decision chain can also be replayed on the truth
  (``robot --link none --fast --joints DIR/truth.jsonl``);
* ``DIR/recording.json`` -- what was simulated, and the commands to try next.

Motion types (:data:`MOTIONS`), each an episode of a few seconds: ``walk``, ``run`` (2 m/s with
a long stride and forward lean), ``turn`` (a curving walk, then a turn on the spot),
``stop_and_go`` (walk, stand, walk on), ``carry`` (walking with both forearms held forward),
``reach`` (hands far forward and high), ``bend``, ``crouch`` (a squat) and ``work``. Bodies are
1.45-2.0 m tall. The shipped lifter learnt from straight walks, standing, work, look-down,
bends, squats and turns (``models.pose_data``); ``run``, ``stop_and_go``, ``carry`` and
``reach`` are motion types it never saw.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from edge_runtime.cli import CliError, positive_float, positive_int
from edge_runtime.core.skeleton import HIP
from edge_runtime.robot.keypoints import CameraModel
from firmware_sim.devices.camera import (
    CANONICAL,
    REAL_DETECTOR,
    TYPICAL_WEBCAM_DIST,
    Camera,
    DetectorNoise,
    detect,
    occlude,
    random_placement,
)
from firmware_sim.people import motions
from firmware_sim.people.human import Body, angle_column
from firmware_sim.scenarios.head_error import calibration_motion, stop_points

RATE_HZ = 30.0
HEIGHTS_M = (1.45, 2.0)
MOTIONS = ("walk", "run", "turn", "stop_and_go", "carry", "reach", "bend", "crouch", "work")
UNSEEN_BY_LIFTER = ("run", "stop_and_go", "carry", "reach")
"""Motion types the shipped lifter's training data (``models.pose_data``) never held."""
NOISES = {"real": REAL_DETECTOR, "default": DetectorNoise()}

BAD_INPUT = (OSError,)


def random_body(rng: np.random.Generator) -> Body:
    return Body.from_height(float(rng.uniform(*HEIGHTS_M)), str(rng.choice(["F", "M"])))


def random_camera(rng: np.random.Generator) -> Camera:
    """A placement as in the dissertation, with a wide-angle lens: the canonical 1280 x 720 image,
    a focal length for 85-105 deg and 50-130 % of a typical webcam's barrel distortion."""
    hfov = math.radians(rng.uniform(85.0, 105.0))
    f = 640 / math.tan(hfov / 2)
    dist = tuple(float(v) * rng.uniform(0.5, 1.3) for v in TYPICAL_WEBCAM_DIST)
    lens = CameraModel(f, f, 640 + rng.normal(0, 8), 360 + rng.normal(0, 8), CANONICAL.width_px,
                       CANONICAL.height_px, dist)
    return random_placement(rng, intrinsics=lens, rate_hz=RATE_HZ)


def _labelled(m: motions.Motion, label: str) -> motions.Motion:
    return motions.make_motion(m.body, m.rate_hz, m.angles_deg, m.pelvis_xz_m, m.heading_rad, label)


def _carrying(m: motions.Motion) -> motions.Motion:
    """A walk with both forearms held forward at waist height (a box in the hands): the arm
    swing replaced by a fixed hold."""
    a = m.angles_deg.copy()
    for side in ("left", "right"):
        a[:, angle_column(f"shoulder_flexion_deg.{side}")] = 25.0
        a[:, angle_column(f"elbow_flexion_deg.{side}")] = 95.0
    return motions.make_motion(m.body, m.rate_hz, a, m.pelvis_xz_m, m.heading_rad, "carry")


IN_PLACE = {  # motion type -> (body, at, heading, rng) -> Motion, at one spot
    "reach": lambda b, at, h, rng: motions.work_at(b, at, h, rng.uniform(3, 6), rng.uniform(1.3, 1.75),
                                                   rng.uniform(0.55, 0.8), RATE_HZ, rng),
    "bend": lambda b, at, h, rng: motions.bend(b, at, h, rng.uniform(40, 85), rng.uniform(3, 5),
                                               rng.uniform(0.3, 1.5), RATE_HZ, rng),
    "crouch": lambda b, at, h, rng: motions.squat(b, at, h, rng.uniform(0.6, 1.0), rng.uniform(3.5, 5.5),
                                                  rng.uniform(0.5, 2.0), RATE_HZ, rng),
    "work": lambda b, at, h, rng: motions.work_at(b, at, h, rng.uniform(3, 6), rng.uniform(0.8, 1.3),
                                                  rng.uniform(0.25, 0.5), RATE_HZ, rng),
}


def episode(kind: str, body: Body, start_xz, heading: float, goal_xz, rng: np.random.Generator) -> motions.Motion:
    """One episode of motion type ``kind`` from ``start_xz`` (facing ``heading``); moving kinds
    end at ``goal_xz``."""
    start, goal = np.asarray(start_xz, float), np.asarray(goal_xz, float)
    style = {"arm_swing": rng.uniform(0.6, 1.3), "stride": rng.uniform(0.9, 1.1), "lean_deg": rng.uniform(0, 5)}
    if kind in ("walk", "carry"):
        m = motions.walk(body, [start, goal], rng.uniform(0.7, 1.6), RATE_HZ, rng=rng, style=style)
        return _carrying(m) if kind == "carry" else _labelled(m, kind)
    if kind == "run":
        m = motions.walk(body, [start, goal], 2.0, RATE_HZ, accel_mps2=2.5, rng=rng,
                         style={"arm_swing": 1.6, "stride": 1.25, "lean_deg": rng.uniform(6, 12)})
        return _labelled(m, kind)
    if kind == "turn":
        mid = (start + goal) / 2 + rng.normal(0, 0.8, 2)
        m = motions.walk(body, [start, mid, goal], rng.uniform(0.8, 1.4), RATE_HZ, corner_radius_m=1.0, rng=rng)
        end, h = m.end
        spin = motions.turn(body, end, h, h + rng.choice([-1, 1]) * rng.uniform(1.5, 3.0), rng.uniform(1.0, 2.0),
                            RATE_HZ)
        return _labelled(motions.concat([m, spin], blend_s=0.2), kind)
    if kind == "stop_and_go":
        mid = start + (goal - start) * rng.uniform(0.35, 0.65)
        a = motions.walk(body, [start, mid], rng.uniform(0.9, 1.6), RATE_HZ, rng=rng, style=style)
        pause = motions.stand(body, mid, a.end[1], rng.uniform(0.5, 1.5), RATE_HZ, rng)
        b = motions.walk(body, [mid, goal], rng.uniform(0.9, 1.6), RATE_HZ, rng=rng, style=style)
        return _labelled(motions.concat([a, pause, b], blend_s=0.2), kind)
    in_place = IN_PLACE.get(kind)
    if in_place is not None:
        return _labelled(in_place(body, start, heading, rng), kind)
    raise ValueError(f"motion type {kind!r}: one of {', '.join(MOTIONS)}")


def session(body: Body, camera: Camera, rng: np.random.Generator, seconds: float, kinds=MOTIONS) -> motions.Motion:
    """Episodes of random ``kinds`` for about ``seconds``, between floor points 3-8 m from the
    camera and in its view; every frame labelled with its episode's motion type."""
    points = stop_points(camera, rng, 12)
    xz = points[0]
    heading = float(rng.uniform(-math.pi, math.pi))
    parts: list[motions.Motion] = []
    while sum(len(p) for p in parts) < seconds * RATE_HZ:
        kind = str(rng.choice(kinds))
        goal = points[rng.integers(len(points))]
        if np.linalg.norm(goal - xz) < 1.0:
            goal = points[(np.argmax(np.linalg.norm(points - xz, axis=1)))]
        m = episode(kind, body, xz, heading, goal, rng)
        parts.append(m)
        xz, heading = m.end
    return motions.concat(parts, blend_s=0.3)


def scene(camera: Camera, rng: np.random.Generator, seconds: float, people: int,
          noise: DetectorNoise = REAL_DETECTOR, kinds=MOTIONS, body_fn=random_body, motion_fn=None) -> dict:
    """Several people's sessions seen by ``camera``: truth and COCO detector output with occlusion.
    Returns ``motions`` (one per person, T frames each), ``keypoints`` (per person (T, 17, 3)).
    ``body_fn(rng) -> Body`` makes each person (the lifter's training varies proportions too);
    ``motion_fn(Motion) -> Motion``, when given, changes each person's session before the camera
    sees it (the lifter's pose-space augmentation; it must draw from its own generator, not ``rng``)."""
    sessions = [session(body_fn(rng), camera, rng, seconds, kinds) for _ in range(people)]
    if motion_fn is not None:
        sessions = [motion_fn(s) for s in sessions]
    n = min(len(s) for s in sessions)
    sessions = [motions.Motion(s.body, s.rate_hz, s.angles_deg[:n], s.pelvis_xz_m[:n], s.heading_rad[:n],
                               s.labels[:n], s.joints_m[:n]) for s in sessions]
    kps = [detect(camera, s.joints_m, rng, noise, fmt="coco") for s in sessions]
    depth = [camera.to_camera(s.joints_m[:, HIP])[:, 2] for s in sessions]
    return {"motions": sessions, "keypoints": occlude(kps, depth, rng)}


def _person_json(pid: int, kp: np.ndarray) -> dict | None:
    seen = np.isfinite(kp[:, :2]).all(axis=1)
    if not seen.any():
        return None
    return {"id": pid, "keypoints": [[round(float(x), 2), round(float(y), 2), round(float(s), 3)] if ok
                                     else [None, None, 0.0] for (x, y, s), ok in zip(kp, seen)]}


def write_keypoints(path: Path, keypoints: list[np.ndarray], rng: np.random.Generator, t0_s: float = 0.0) -> None:
    """COCO keypoints of several people (per person (T, 17, 3)) as JSON lines, people in random order."""
    with open(path, "w", encoding="utf-8") as f:
        for k in range(len(keypoints[0])):
            people = [p for p in (_person_json(i, kp[k]) for i, kp in enumerate(keypoints)) if p is not None]
            order = rng.permutation(len(people))
            f.write(json.dumps({"t": round(t0_s + k / RATE_HZ, 4), "frame": k, "format": "coco",
                                "people": [people[i] for i in order]}) + "\n")


def write_truth(path: Path, camera: Camera, sessions: list[motions.Motion], t0_s: float = 0.0) -> None:
    with open(path, "w", encoding="utf-8") as f:
        for k in range(len(sessions[0])):
            f.write(json.dumps({"t": round(t0_s + k / RATE_HZ, 4), "frame": k, "people": [
                {"id": i, "motion": str(s.labels[k]), "joints_robot_m": np.round(s.joints_m[k], 4).tolist(),
                 "camera_joints_m": np.round(camera.to_camera(s.joints_m[k]), 4).tolist()}
                for i, s in enumerate(sessions)]}) + "\n")


def add_arguments(parser) -> None:
    parser.add_argument("--out", required=True, metavar="DIR", help="where the recording goes")
    parser.add_argument("--seconds", type=positive_float, default=60.0, help="length of the scene (s, default 60)")
    parser.add_argument("--people", type=positive_int, default=3, help="people in the scene (default 3)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--noise", choices=sorted(NOISES), default="real",
                        help="the detector's errors: real (COCO sigmas at the person's size, default) or default")


def cmd(args) -> int:
    out = Path(args.out)
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise CliError(f"--out {out}: cannot create ({e.strerror or e})") from None
    rng = np.random.default_rng(args.seed)
    camera = random_camera(rng)
    noise = NOISES[args.noise]
    cal, labels = calibration_motion(random_body(rng), rng)
    cal_kp = detect(camera, cal.joints_m, rng, noise, fmt="coco")
    write_keypoints(out / "calibration.jsonl", [cal_kp], rng)
    sc = scene(camera, rng, args.seconds, args.people, noise)
    write_keypoints(out / "keypoints.jsonl", sc["keypoints"], rng)
    write_truth(out / "truth.jsonl", camera, sc["motions"])
    (out / "camera.json").write_text(json.dumps(camera.to_dict(), indent=1) + "\n")
    d = out
    meta = {"command": f"python -m firmware_sim record --out {args.out} --seconds {args.seconds:g} "
                       f"--people {args.people} --seed {args.seed} --noise {args.noise}",
            "frames": len(sc["motions"][0]), "rate_hz": RATE_HZ, "people": args.people,
            "heights_m": [round(m.body.height_m, 3) for m in sc["motions"]],
            "camera_position_m": np.round(camera.position_m, 3).tolist(), "noise": args.noise,
            "calibration_markers": {"frames": len(cal), "marker_per_frame": labels.tolist()},
            "next": [f"python -m edge_runtime robot --keypoints {d}/calibration.jsonl --intrinsics {d}/camera.json "
                     f"--calibrate {d}/cal.json",
                     f"python -m edge_runtime lift --keypoints {d}/keypoints.jsonl --camera {d}/camera.json "
                     f"--person all --out {d}/lifted.jsonl",
                     f"python -m edge_runtime robot --link none --fast --keypoints {d}/keypoints.jsonl "
                     f"--intrinsics {d}/camera.json --calibration {d}/cal.json --log {d}/replay.jsonl",
                     f"python -m firmware_sim score-lift --recording {d} --lifted {d}/lifted.jsonl"]}
    (out / "recording.json").write_text(json.dumps(meta, indent=1) + "\n")
    print(f"record: {meta['frames']} frames of {args.people} people ({args.seconds:g} s) and a calibration walk "
          f"of {len(cal)} frames -> {out}/keypoints.jsonl, calibration.jsonl, camera.json, truth.jsonl, "
          "recording.json\nnext:\n  " + "\n  ".join(meta["next"]))
    return 0
