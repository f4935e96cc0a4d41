"""A lift's output scored against a recording's truth (``python -m firmware_sim record``).

    python -m firmware_sim record --out DIR --seconds 60 --people 3 --seed 1
    python -m edge_runtime lift --keypoints DIR/keypoints.jsonl --camera DIR/camera.json --person all \\
        --out DIR/lifted.jsonl
    python -m firmware_sim score-lift --recording DIR --lifted DIR/lifted.jsonl [--json OUT.json]

Each valid lifted person is matched to the simulated person by the exporter id the tracker
kept (``source_id``; the tracker itself never uses it). Figures, over frames past the lifter's
warm-up, overall and per motion type (``truth.jsonl``'s ``motion``):

* **reprojection** (px): the lifted camera-frame joints projected with the recording's own
  camera (``cv2.projectPoints``, its distortion included) against the keypoints they were
  lifted from (COCO -> H36M as the runtime maps them), over the joints observed in that frame;
* **MPJPE** (mm): root-relative joints (pelvis subtracted) against the truth's;
* **P-MPJPE** (mm): after the best similarity alignment (Procrustes: rotation, scale, translation);
* **root error** (mm): the pelvis in the camera frame, depth included (before any floor anchoring);
* ``model_own_joints``: MPJPE and P-MPJPE of the network's own joints (``joints_model_cam_m``,
  before the runtime puts them on the keypoints' rays), to show what the rays cost or gain;
* ``true_depth_on_rays``: P-MPJPE of joints on the lifted joints' rays at the TRUE depth of
  each joint: what the rays alone cost, the floor of the output's P-MPJPE whatever the
  network's depth (with ``ray_tolerance_px = 0`` the rays are the keypoints').
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from edge_runtime.cli import CliError
from edge_runtime.robot.keypoints import CameraModel, read_keypoints_jsonl, to_h36m

BAD_INPUT = (OSError,)


def add_arguments(parser) -> None:
    parser.add_argument("--recording", required=True, nargs="+", metavar="DIR",
                        help="firmware_sim record directories (their figures are pooled)")
    parser.add_argument("--lifted", required=True, nargs="+", metavar="LIFTED.jsonl",
                        help="python -m edge_runtime lift --person all output for each DIR/keypoints.jsonl")
    parser.add_argument("--json", metavar="OUT.json", help="write the figures here")


def procrustes_aligned(pred: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """``pred`` (17, 3) after the similarity transform that best fits it to ``truth``."""
    mp, mt = pred.mean(axis=0), truth.mean(axis=0)
    p, t = pred - mp, truth - mt
    U, s, Vt = np.linalg.svd(p.T @ t)
    d = np.sign(np.linalg.det(U @ Vt))
    D = np.diag([1.0, 1.0, d])
    R = U @ D @ Vt
    scale = float((s * np.diag(D)).sum() / (p * p).sum())
    return scale * p @ R + mt


def _errors_mm(j: np.ndarray, tj: np.ndarray) -> tuple[float, float, float]:
    """(MPJPE root-relative, P-MPJPE, root error), mm, of joints ``j`` against ``tj``."""
    mpjpe = 1000 * float(np.linalg.norm((j - j[0]) - (tj - tj[0]), axis=1).mean())
    pa = 1000 * float(np.linalg.norm(procrustes_aligned(j, tj) - tj, axis=1).mean())
    return mpjpe, pa, 1000 * float(np.linalg.norm(j[0] - tj[0]))


def _read_jsonl(path: Path) -> list[dict]:
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except OSError as e:
        raise CliError(f"{path}: cannot read ({e.strerror or e})") from None
    out = []
    for n, line in enumerate(lines, 1):
        if line.strip():
            try:
                out.append(json.loads(line))
            except json.JSONDecodeError as e:
                raise CliError(f"{path}:{n}: not JSON ({e.msg})") from None
    return out


def score(recordings: list[Path], lifted: list[Path]) -> dict:
    """The figures of the module docstring, as a dict, pooled over the recordings."""
    rows, frames, persons = [], 0, 0
    for rec, lift in zip(recordings, lifted):
        r, f, p = _rows(rec, lift)
        rows += r
        frames += f
        persons += p
    if not rows:
        raise CliError(f"{', '.join(map(str, lifted))}: no valid lifted person past warm-up matched the truth")
    out = {"lifted": list(map(str, lifted)), "recordings": list(map(str, recordings)), "frames": frames,
           "person_frames": persons, "scored_person_frames": len(rows), "all": _figures(rows), "by_motion": {}}
    for motion in sorted({r[0] for r in rows}):
        out["by_motion"][motion] = _figures([r for r in rows if r[0] == motion])
    return out


def _rows(recording: Path, lifted: Path) -> tuple[list, int, int]:
    """Per scored person-frame (motion, reprojection errors px, errors mm...); frames; person-frames."""
    import cv2

    cam_d = json.loads((recording / "camera.json").read_text())
    camera = CameraModel.from_dict(cam_d, str(recording / "camera.json"))
    truth = {row["frame"]: {p["id"]: p for p in row["people"]} for row in _read_jsonl(recording / "truth.jsonl")}
    kp_path = recording / "keypoints.jsonl"
    observed_2d = {f.frame: {p.id: to_h36m(p.keypoints, "coco") for p in f.people}
                   for f in read_keypoints_jsonl(kp_path, "coco")}
    rows = []  # (motion, reprojection errors px (observed joints), mpjpe mm, p-mpjpe mm, root mm)
    frames = persons = 0
    for line in _read_jsonl(lifted):
        if "summary" in line:
            continue
        if "people" not in line:
            raise CliError(f"{lifted}: expected the output of lift --person all (a 'people' list per frame)")
        frames += 1
        for p in line["people"]:
            persons += 1
            if p["warming_up"] or p.get("source_id") is None:
                continue
            true = truth.get(line["frame"], {}).get(p["source_id"])
            seen_2d = observed_2d.get(line["frame"], {}).get(p["source_id"])
            if true is None or seen_2d is None:
                continue
            j = np.asarray(p["joints_cam_m"], float)
            tj = np.asarray(true["camera_joints_m"], float)
            obs = np.asarray(p["observed"], bool)
            img, _ = cv2.projectPoints(j, np.zeros(3), np.zeros(3), camera.K, camera.dist_array)
            reproj = np.linalg.norm(img.reshape(17, 2)[obs] - seen_2d[obs, :2], axis=1)
            model = np.asarray(p.get("joints_model_cam_m", j), float)
            on_rays = j / j[:, 2:3] * tj[:, 2:3]
            rows.append((true["motion"], reproj, *_errors_mm(j, tj), *_errors_mm(model, tj)[:2],
                         _errors_mm(on_rays, tj)[1]))
    return rows, frames, persons


def _figures(rows) -> dict:
    reproj = np.concatenate([r[1] for r in rows]) if rows else np.zeros(0)
    q = lambda x, p: round(float(np.percentile(x, p)), 2) if len(x) else None  # noqa: E731
    mp, pa, root, model_mp, model_pa, rays_pa = (np.array([r[k] for r in rows]) for k in (2, 3, 4, 5, 6, 7))
    return {"n": len(rows), "reprojection_px": {"median": q(reproj, 50), "p95": q(reproj, 95), "joints": int(len(reproj))},
            "mpjpe_mm": round(float(mp.mean()), 1), "p_mpjpe_mm": round(float(pa.mean()), 1),
            "root_error_mm": {"median": q(root, 50), "p95": q(root, 95)},
            "model_own_joints": {"mpjpe_mm": round(float(model_mp.mean()), 1),
                                 "p_mpjpe_mm": round(float(model_pa.mean()), 1)},
            "true_depth_on_rays": {"p_mpjpe_mm": round(float(rays_pa.mean()), 1)}}


def cmd(args) -> int:
    if len(args.recording) != len(args.lifted):
        raise CliError(f"{len(args.recording)} --recording directories but {len(args.lifted)} --lifted files")
    recs = [Path(r) for r in args.recording]
    for rec in recs:
        for name in ("camera.json", "truth.jsonl", "keypoints.jsonl"):
            if not (rec / name).is_file():
                raise CliError(f"--recording {rec}: no {name} (make one with python -m firmware_sim record)")
    res = score(recs, [Path(x) for x in args.lifted])
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=1) + "\n")
    print(f"{'motion':<12} {'n':>6} {'reproj px med/p95':>18} {'MPJPE mm':>9} {'P-MPJPE mm':>11} "
          f"{'root mm med/p95':>16}  {'model MPJPE / P-MPJPE':>22}  {'rays at true depth P-MPJPE':>27}")
    for name, f in [("all", res["all"]), *res["by_motion"].items()]:
        r, root, m = f["reprojection_px"], f["root_error_mm"], f["model_own_joints"]
        print(f"{name:<12} {f['n']:>6} {r['median']:>8} / {r['p95']:<7} {f['mpjpe_mm']:>9} {f['p_mpjpe_mm']:>11} "
              f"{root['median']:>7} / {root['p95']:<7}  {m['mpjpe_mm']:>10} / {m['p_mpjpe_mm']:<9}  "
              f"{f['true_depth_on_rays']['p_mpjpe_mm']:>27}")
    return 0
