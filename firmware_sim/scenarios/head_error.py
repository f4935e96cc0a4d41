"""Head position error in the robot frame after the 3-marker calibration, with the shipped lifter.

    python -m firmware_sim head-error --placements 40 --seed 0 --json reports/robot/head_error.json \\
        --plot reports/robot/head_error.png

For each of N random camera placements (:func:`firmware_sim.devices.camera.random_placement`: 3-8 m
from the cell, 1-3 m high, canonical intrinsics, 30 Hz):

1. a calibrating worker (height drawn from 1.60-1.90 m) stands ``STAND_S`` on each of the three
   floor markers (0, floor, 1), (1, floor, 1), (0, floor, 2), walking between them; his
   keypoints (:func:`firmware_sim.devices.camera.detect`, default detector noise) go through the
   shipped :class:`edge_runtime.robot.lifter.StreamingLifter` and
   :func:`edge_runtime.robot.calibration.from_recording` fits camera -> robot (frames labelled
   by marker; warm-up frames unused);
2. another worker (another height) walks between random points 3-8 m from the camera and
   works ``WORK_S`` at each; the lifter runs on, and each valid frame's head is mapped to the
   robot frame twice: ``off`` -- ``Calibration.apply`` of the lifted head; ``on`` --
   ``Calibration.to_robot`` as the robot loop calls it (every valid frame in order, warm-up
   frames too, with the observed-joint mask): the skeleton scaled about the camera centre so
   its ankles rest on the floor (fused with the lifter's depth where that is nearer the arm;
   ``calibration.anchor_factor``), each person's factor filtered over his recent frames
   (``FloorAnchor``, causal), guards as in ``CalibrationParams``. Warm-up frames are not scored.

Errors (m) against the true head: 3-D, ground-projected (x-z: what the hazard zones use)
and height (y), median and p95, overall and binned by the true ground distance from the
camera to the worker's pelvis (3-4, 4-5, ..., 7-8 m); and ``farther_from_arm``: how often and by
how much the head is placed farther from the arm's base axis than it is (the hazard monitor's side). Placements whose calibration is
refused are counted and skipped.

Where the error comes from: ``calibration_pose_error`` (the fitted camera pose against the
simulated camera's: rotation angle, camera-centre distance) and ``true_depth`` (the head error
when each lifted skeleton is put at its true distance: the lifter's shape and the calibration's
pose alone). With ``--calibration-method truth`` the gap between ``true_depth`` and ``on`` is the
floor anchoring's depth error.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from edge_runtime.cli import CliError, positive_int
from edge_runtime.core.skeleton import BASE_HEIGHT_M, HEAD, HIP
from edge_runtime.robot import calibration
from edge_runtime.robot.calibration import METHODS as METHODS_FIT
from edge_runtime.robot.calibration import (
    Calibration,
    CalibrationError,
    CalibrationParams,
    anchor_factor,
    from_recording,
    rotation_between_deg,
)
from firmware_sim.devices.camera import REAL_DETECTOR, Camera, DetectorNoise, detect, random_placement
from firmware_sim.people import motions
from firmware_sim.people.human import Body

METHODS = ("off", "on")
BINS_M = tuple(range(3, 9))               # distance bin edges (m): 3-4, ..., 7-8
STAND_S = 3.0                             # calibration: time on each marker (s)
WORK_S = 3.0                              # test: time working at each stop (s)
STOPS = 5                                 # test: stops per placement
WORKER_HEIGHTS_M = (1.60, 1.90)           # workers' heights are drawn uniformly from this range
RATE_HZ = 30.0
NOISES = {"default": DetectorNoise(), "real": REAL_DETECTOR}
TRUTH = "truth"                           # --calibration-method: the true extrinsics, no fit

BAD_INPUT = (OSError,)


def add_arguments(parser) -> None:
    parser.add_argument("--placements", type=positive_int, default=40, help="random camera placements (default 40)")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument("--anchor", choices=("on", "off", "both"), default="both",
                        help="floor re-anchoring of the lifted skeleton: measure with it, without, or both")
    parser.add_argument("--precision", choices=("int8", "fp32"), default="int8", help="which shipped lifter")
    parser.add_argument("--noise", choices=sorted(NOISES), default="default",
                        help="the 2D detector's errors: default (DetectorNoise()) or real (REAL_DETECTOR: COCO "
                             "sigmas at the person's size, offsets, more misses)")
    parser.add_argument("--calibration-method", choices=(*METHODS_FIT, TRUTH), default=CalibrationParams().method,
                        help="the calibration fit (edge_runtime.robot.calibration; default: its default), or "
                             f"'{TRUTH}': the simulated camera's true extrinsics (the reference)")
    parser.add_argument("--assets", metavar="DIR", help="lifter models (manifest.json) to measure; default: the shipped")
    parser.add_argument("--ray-tolerance-px", type=float, default=None,
                        help="the lifter's [lifter] ray_tolerance_px (default: its default)")
    parser.add_argument("--anchor-window-frames", type=positive_int, default=None,
                        help="the floor anchoring's window (default: calibration.ANCHOR_WINDOW_FRAMES; 1 = each frame alone)")
    parser.add_argument("--unlabelled", action="store_true",
                        help="calibrate as the runtime's --calibrate does: find the stands in the walk itself "
                             "(no marker labels; the lifter's warm-up frames included)")
    parser.add_argument("--json", required=True, metavar="OUT.json", help="write the figures here")
    parser.add_argument("--plot", metavar="OUT.png", help="error vs distance, both methods")


# ------------------------------------------------------------------------------ simulation
def _body(rng: np.random.Generator) -> Body:
    return Body.from_height(float(rng.uniform(*WORKER_HEIGHTS_M)), str(rng.choice(["F", "M"])))


def calibration_motion(body: Body, rng: np.random.Generator, params: CalibrationParams = CalibrationParams()):
    """The calibration walk: (motion, marker label per frame: 1-3 standing, 0 walking)."""
    markers = params.markers_xz_m
    parts, labels = [], []
    for i, m in enumerate(markers):
        if i:
            parts.append(motions.walk(body, [markers[i - 1], m], 0.8, RATE_HZ))
            labels.append(np.zeros(len(parts[-1]), int))
        parts.append(motions.stand(body, m, math.pi, STAND_S, RATE_HZ, rng=rng))
        labels.append(np.full(len(parts[-1]), i + 1))
    return motions.concat(parts, blend_s=0.2), np.concatenate(labels)


def stop_points(camera: Camera, rng: np.random.Generator, n: int) -> np.ndarray:
    """(n, 2) floor points (x, z) 3.2-7.8 m (ground distance) from the camera whose whole
    standing body (floor to 2 m) is in the image."""
    cam = camera.position_m
    out = []
    for _ in range(10_000):
        p = np.array([rng.uniform(-3.0, 3.0), rng.uniform(-1.5, 3.5)])
        d = math.hypot(p[0] - cam[0], p[1] - cam[2])
        ends = np.array([[p[0], y, p[1]] for y in (-BASE_HEIGHT_M, 2.0 - BASE_HEIGHT_M)])
        if 3.2 <= d <= 7.8 and camera.in_image(camera.project(ends)).all():
            out.append(p)
            if len(out) == n:
                return np.array(out)
    raise RuntimeError("no floor points 3-8 m from this camera in view")


def work_motion(body: Body, camera: Camera, rng: np.random.Generator):
    """The test: walk to ``STOPS`` random points in view 3-8 m from the camera, work at each."""
    pts = stop_points(camera, rng, STOPS)
    parts = []
    for i, p in enumerate(pts):
        if i:
            parts.append(motions.walk(body, [pts[i - 1], p], float(rng.uniform(0.8, 1.6)), RATE_HZ, rng=rng))
        heading = parts[-1].end[1] if parts else float(rng.uniform(-math.pi, math.pi))
        parts.append(motions.work_at(body, p, heading, WORK_S, rate_hz=RATE_HZ, rng=rng))
    return motions.concat(parts, blend_s=0.3)


def lift(lifter, keypoints: np.ndarray, t0_s: float, warm: bool = False):
    """(T, 17, 3) camera-frame joints of detector output (T, 17, 3) at RATE_HZ from ``t0_s``;
    NaN where the lifter is invalid or (unless ``warm``) still warming up. With ``warm``:
    (joints, observed (T, 17) bool, warming_up (T,) bool), every valid frame kept, as the robot
    loop gets them."""
    out = np.full((len(keypoints), 17, 3), np.nan)
    observed, warming = np.zeros((len(keypoints), 17), bool), np.zeros(len(keypoints), bool)
    for k, kp in enumerate(keypoints):
        pose = lifter.push(t0_s + k / RATE_HZ, kp if np.isfinite(kp[:, :2]).any() else None)
        if pose.valid and (warm or not pose.warming_up):
            out[k], observed[k], warming[k] = pose.joints_cam_m, pose.observed, pose.warming_up
    return (out, observed, warming) if warm else out


def true_calibration(camera: Camera, params: CalibrationParams = CalibrationParams()) -> Calibration:
    """The exact camera -> robot map of a simulated camera (the reference for the fits)."""
    zero = np.zeros((3, 3))
    return Calibration(camera.R.T, camera.position_m, TRUTH, 0.0, zero, zero, params)


def calibration_error(cal: Calibration, camera: Camera) -> dict:
    """How far a fitted calibration's camera pose is from the simulated camera's: the angle (deg) of
    the rotation between the two camera -> robot rotations, the camera centre's distance (m) and its
    height error (m, signed), and the fit's scale."""
    return {"rotation_deg": rotation_between_deg(cal.A, camera.R.T),
            "camera_position_m": float(np.linalg.norm(cal.b - camera.position_m)),
            "camera_height_m": float(cal.b[1] - camera.position_m[1]), "scale": cal.scale}


def _error_rows(d_m: np.ndarray) -> np.ndarray:
    """(N, 3) rows of 3-D, ground-projected (x-z) and signed height errors of (N, 3) head offsets (m)."""
    return np.stack([np.linalg.norm(d_m, axis=1), np.hypot(d_m[:, 0], d_m[:, 2]), d_m[:, 1]], axis=1)


def run_placement(lifter, rng: np.random.Generator, methods=METHODS,
                  params: CalibrationParams = CalibrationParams(), truth: bool = False,
                  noise: DetectorNoise = DetectorNoise(), anchor_window_frames: int | None = None,
                  labelled: bool = True) -> dict:
    """One camera placement: calibrate (``truth``: take the true extrinsics instead; the
    calibration walk is still simulated, so the random streams match), then the worker's
    frames. Returns per-frame arrays (``distance_m``, per method ``err`` (T, 3) rows of 3-D,
    ground, height errors) or ``{"refused": reason}``. ``labelled``: the calibration frames carry
    the simulator's marker labels (warm-up frames left out); else the runtime finds the stands
    itself in every valid frame, as ``edge_runtime robot --calibrate --keypoints`` does."""
    camera = random_placement(rng)
    cal_mot, labels = calibration_motion(_body(rng), rng)
    cal_joints = lift(lifter, detect(camera, cal_mot.joints_m, rng, noise), 0.0, warm=not labelled)
    cal_joints = cal_joints if labelled else cal_joints[0]
    try:
        cal = true_calibration(camera, params) if truth else from_recording(cal_mot.t_s, cal_joints, params,
                                                                             marker=labels if labelled else None)
    except CalibrationError as e:
        return {"camera": camera.to_dict(), "refused": str(e)}
    if anchor_window_frames is not None:
        cal.anchor_window_frames = anchor_window_frames
    work = work_motion(_body(rng), camera, rng)
    t0 = len(cal_mot) / RATE_HZ + 2.0                     # a gap: the lifter restarts its buffer
    joints, observed, warming = lift(lifter, detect(camera, work.joints_m, rng, noise), t0, warm=True)
    valid = np.isfinite(joints).all(axis=(1, 2))
    # the robot loop's path: every valid frame, in order, through the (stateful) to_robot
    anchored = np.full_like(joints, np.nan)
    if "on" in methods:
        for k in np.flatnonzero(valid):
            anchored[k] = cal.to_robot(joints[k][None], observed[k][None])[0]
    ok = valid & ~warming                                  # warm-up frames are fed, not scored
    joints, anchored, truth = joints[ok], anchored[ok], work.joints_m[ok, HEAD]
    cam = camera.position_m
    dist = np.hypot(*(work.joints_m[ok, HIP][:, [0, 2]] - cam[[0, 2]]).T)
    res = {"camera": camera.to_dict(), "calibration_scale": cal.scale, "distance_m": dist,
           "calibration_error": calibration_error(cal, camera)}
    # the lifter's skeleton alone: each frame scaled about the camera centre so that its pelvis lies at
    # the true pelvis's distance (a perfect depth); what is left is the lifter's shape and the fit's pose
    raw = cal.apply(joints)
    k_depth = (np.linalg.norm(work.joints_m[ok, HIP] - cal.b, axis=1)
               / np.linalg.norm(raw[:, HIP] - cal.b, axis=1))
    res["true_depth"] = _error_rows(cal.b + k_depth[:, None] * (raw[:, HEAD] - cal.b) - truth)
    for m in methods:
        if m == "on":
            head = anchored[:, HEAD]
            # the factor the anchoring applied: it scales about the camera centre
            k = np.linalg.norm(head - cal.b, axis=1) / np.linalg.norm(cal.apply(joints[:, HEAD]) - cal.b, axis=1)
            res["applied"] = np.array([anchor_factor(j, cal.A, cal.b, cal.params, o)[1] is None
                                       for j, o in zip(joints, observed[ok])], bool)
            res["factor"] = k
        else:
            head = cal.apply(joints[:, HEAD])
        res[m] = _error_rows(head - truth)
        # signed: how much farther from the arm's base axis (the robot frame's y axis) the head is placed
        # than it is, on the ground (> 0: farther, what the hazard monitor must not get)
        res[f"{m}_farther"] = np.hypot(head[:, 0], head[:, 2]) - np.hypot(truth[:, 0], truth[:, 2])
    return res


# ------------------------------------------------------------------------------ figures
def _pct(x, p: float) -> float:
    """The ``p``-th percentile of ``x``, rounded for the JSON."""
    return round(float(np.percentile(x, p)), 4)


def _stats(err: np.ndarray) -> dict:
    """Median and p95 (m) of (N, 3) rows of 3-D, ground and signed height errors."""
    if not len(err):
        return {"n": 0}
    e3, eg, eh = err.T
    return {"n": int(len(err)),
            "error_3d_m": {"median": _pct(e3, 50), "p95": _pct(e3, 95)},
            "error_ground_m": {"median": _pct(eg, 50), "p95": _pct(eg, 95)},
            "error_height_m": {"median_abs": _pct(np.abs(eh), 50), "p95_abs": _pct(np.abs(eh), 95),
                               "median_signed": _pct(eh, 50)}}


def summarise(results: list[dict], methods, args) -> dict:
    done = [r for r in results if "refused" not in r]
    dist = np.concatenate([r["distance_m"] for r in done]) if done else np.zeros(0)
    out = {"command": (f"python -m firmware_sim head-error --placements {args.placements} --seed {args.seed} "
                       f"--anchor {args.anchor} --precision {args.precision} "
                       f"--calibration-method {args.calibration_method} --noise {args.noise} --json {args.json}"
                       + (f" --plot {args.plot}" if args.plot else "")
                       + (f" --assets {args.assets}" if getattr(args, "assets", None) else "")
                       + (f" --ray-tolerance-px {args.ray_tolerance_px:g}"
                          if getattr(args, "ray_tolerance_px", None) is not None else "")
                       + (" --unlabelled" if getattr(args, "unlabelled", False) else "")
                       + (f" --anchor-window-frames {args.anchor_window_frames}"
                          if getattr(args, "anchor_window_frames", None) is not None else "")),
           "lifter_precision": args.precision, "calibration_method": args.calibration_method, "placements": args.placements,
           "labelled_calibration": not getattr(args, "unlabelled", False),
           "calibrations_refused": [r["refused"] for r in results if "refused" in r],
           "frames": int(len(dist)), "methods": {}}
    for m in methods:
        err = np.concatenate([r[m] for r in done]) if done else np.zeros((0, 3))
        bins = {f"{lo}-{lo + 1}m": _stats(err[(dist >= lo) & (dist < lo + 1)]) for lo in BINS_M[:-1]}
        out["methods"][m] = {"all": _stats(err), "by_distance": bins}
        if done:
            far = np.concatenate([r[f"{m}_farther"] for r in done])
            out["methods"][m]["farther_from_arm"] = {
                "what": "the head's ground distance from the arm's base axis, placed minus true (m; > 0: placed "
                        "farther than it is)",
                **{f"share_over_{t:g}_m": round(float(np.mean(far > t)), 4) for t in (0.0, 0.1, 0.3)},
                "p95_m": _pct(far, 95), "p99_m": _pct(far, 99)}
    if done:
        err = np.concatenate([r["true_depth"] for r in done])
        pose = {k: np.array([r["calibration_error"][k] for r in done]) for k in ("rotation_deg", "camera_position_m")}
        out["true_depth"] = {"what": "the lifted skeleton scaled about the camera centre so that its pelvis lies at "
                                     "the true distance: the error left by the lifter's shape and the calibration's "
                                     "pose when the depth is perfect", "all": _stats(err)}
        out["calibration_pose_error"] = {k: {"median": _pct(v, 50), "p90": _pct(v, 90), "max": _pct(v, 100)}
                                         for k, v in pose.items()}
        # a fit turned this far is not a noisy calibration but a wrong one (the markers mistaken)
        out["calibration_pose_error"]["over_10_deg"] = int(np.sum(pose["rotation_deg"] > 10.0))
    if "on" in methods and done:
        applied = np.concatenate([r["applied"] for r in done])
        k = np.concatenate([r["factor"] for r in done])
        p = CalibrationParams()
        out["anchoring"] = {"applied_fraction": round(float(applied.mean()), 4) if len(applied) else None,
                            "factor_median": round(float(np.median(k)), 4) if len(k) else None,
                            "clamped_fraction": round(float(np.mean((k <= p.anchor_min_scale)
                                                                    | (k >= p.anchor_max_scale))), 4) if len(k) else None,
                            # which anchoring ran: the floor rays alone (inf, shipped) or fused with the lifter's depth
                            "lifter_depth_sd": str(calibration.ANCHOR_LIFTER_DEPTH_SD)}
    out["per_placement"] = [
        {"camera_position_m": np.round(r["camera"]["position_m"], 3).tolist(),
         **({"refused": r["refused"]} if "refused" in r else
            {"calibration_scale": round(r["calibration_scale"], 4), "frames": int(len(r["distance_m"])),
             **{k: round(v, 4) for k, v in r["calibration_error"].items() if k != "scale"},
             **{f"median_error_3d_m_{m}": round(float(np.median(r[m][:, 0])), 4) if len(r[m]) else None
                for m in methods}})}
        for r in results]
    return out


def plot(summary: dict, path: str | Path) -> None:
    import matplotlib  # lazily: only --plot needs it

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    centres = [lo + 0.5 for lo in BINS_M[:-1]]
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2), sharex=True)
    colours = {"off": "tab:red", "on": "tab:blue"}
    names = {"off": "lifter root (no anchoring)", "on": "floor-anchored"}
    for ax, key, title in zip(axes, ("error_3d_m", "error_ground_m", "error_height_m"),
                              ("3-D head error", "ground-projected (x-z) head error", "|height| error")):
        for m, s in summary["methods"].items():
            b = s["by_distance"].values()
            med = [v[key]["median" if key != "error_height_m" else "median_abs"] if v["n"] else np.nan for v in b]
            p95 = [v[key]["p95" if key != "error_height_m" else "p95_abs"] if v["n"] else np.nan for v in b]
            ax.plot(centres, med, "o-", color=colours[m], label=f"{names[m]}: median")
            ax.plot(centres, p95, "s--", color=colours[m], alpha=0.6, label=f"{names[m]}: p95")
        ax.set_title(title)
        ax.set_xlabel("ground distance camera -> worker (m)")
        ax.set_ylabel("error (m)")
        ax.grid(alpha=0.3)
        ax.set_ylim(bottom=0)
    axes[0].legend(fontsize=8)
    fig.suptitle(f"head position in the robot frame after the 3-marker calibration, {summary['lifter_precision']} "
                 f"lifter, {summary['placements']} placements, {summary['frames']} frames")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)


def cmd(args) -> int:
    from edge_runtime.core.manifest import ASSETS_DIR, ManifestError
    from edge_runtime.robot.lifter import LifterParams, StreamingLifter

    methods = METHODS if args.anchor == "both" else (args.anchor,)
    for p in filter(None, (args.json, args.plot)):
        if not Path(p).parent.is_dir():
            raise CliError(f"{p}: directory {Path(p).parent} does not exist")
    try:
        lifter = StreamingLifter.from_manifest(args.assets or ASSETS_DIR, LifterParams(
            precision=args.precision, **({} if args.ray_tolerance_px is None else {"ray_tolerance_px": args.ray_tolerance_px})))
    except (ManifestError, OSError, ValueError) as e:
        raise CliError(f"lifter {args.precision}: {e}") from None
    rng = np.random.default_rng(args.seed)
    results = []
    try:
        from tqdm import tqdm
    except ImportError:  # pragma: no cover - tqdm is a dependency
        tqdm = None
    seeds = rng.integers(0, 2**31, args.placements)
    truth = args.calibration_method == TRUTH
    params = CalibrationParams(method="rigid" if truth else args.calibration_method)
    it = tqdm(seeds, desc="placements", unit="cam") if tqdm else seeds
    for s in it:
        lifter.restart()
        results.append(run_placement(lifter, np.random.default_rng(int(s)), methods, params, truth,
                                     NOISES[args.noise], args.anchor_window_frames, not args.unlabelled))
    summary = summarise(results, methods, args)
    Path(args.json).write_text(json.dumps(summary, indent=2) + "\n")
    if args.plot:
        plot(summary, args.plot)
    for m, s in summary["methods"].items():
        a = s["all"]
        if a["n"]:
            print(f"{m:>3}: 3-D median {a['error_3d_m']['median']:.3f} p95 {a['error_3d_m']['p95']:.3f} m; "
                  f"ground median {a['error_ground_m']['median']:.3f} p95 {a['error_ground_m']['p95']:.3f} m "
                  f"({a['n']} frames)")
            f = s["farther_from_arm"]
            print(f"     placed farther from the arm than it is: {f['share_over_0_m']:.3f} of frames, by > 0.1 m "
                  f"{f['share_over_0.1_m']:.3f}, by > 0.3 m {f['share_over_0.3_m']:.4f}; p95 {f['p95_m']:.3f} "
                  f"p99 {f['p99_m']:.3f} m")
    if "calibration_pose_error" in summary:
        pe, td = summary["calibration_pose_error"], summary["true_depth"]["all"]
        print(f"calibrations: {len(summary['per_placement']) - len(summary['calibrations_refused'])} made, "
              f"{len(summary['calibrations_refused'])} refused, {pe['over_10_deg']} turned by more than 10 deg")
        print(f"calibration pose: rotation median {pe['rotation_deg']['median']:.2f} deg (p90 "
              f"{pe['rotation_deg']['p90']:.2f}), camera centre median {pe['camera_position_m']['median']:.3f} m; "
              f"with the true depth: ground median {td['error_ground_m']['median']:.3f} p95 "
              f"{td['error_ground_m']['p95']:.3f} m")
    return 0
