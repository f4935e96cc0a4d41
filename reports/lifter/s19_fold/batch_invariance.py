"""Does a lifter give each window the same output in a batch of 2-3 as alone? (session 18 perf8's open question)

The product lifts everyone of a frame in one onnxruntime call (edge_runtime.robot.lifter.PeopleLifter, ``_lift``).
This script captures the windows the product really builds, by wrapping ``_lift`` while ``python -m edge_runtime
lift --person all`` runs in-process on a ``firmware_sim record`` recording:

* ``steady``: the recording's own clock (30 Hz);
* ``random_normal``: 3000 windows of N(0, 0.3) noise (off the data, as ort_ab.py's output check);
* ``jumpy``: the same keypoints with a clock that now and then skips frames (2/30, 5/30 s: the lifter bridges the
  hole by interpolation), jumps 0.7 s ahead (a reset) or goes back (-1 s: a restart), as perf8's jumpy-clock test.

Every captured window is then run alone (batch 1) and inside batches of 2 and 3: with the people it was really
lifted with in that frame, and with windows drawn at random from the whole capture (also from the jumpy one).
Reported per model and case: how many windows, how many differ at all, and the max |difference| of pose_3d and
root_3d in metres.

    PYTHONPATH=. python reports/lifter/s19_fold/batch_invariance.py --recording /tmp/fold/rec4 \
        --model shipped_int8=edge_runtime/assets:int8 --model fp32=edge_runtime/assets:fp32 \
        --model folded_int8=/tmp/fold/folded:int8 --out reports/lifter/s19_fold/results/batch_invariance.json
"""
from __future__ import annotations

import argparse
import contextlib
import io
import json
import sys
import time
from pathlib import Path

import numpy as np

import edge_runtime.robot.lifter as lifter_mod
from edge_runtime.core.onnx import session_from_manifest

OUTPUTS = ["pose_3d", "root_3d"]
INPUT = "keypoints_2d"


def jumpy_copy(src: Path, dst: Path, seed: int) -> Path:
    """``src`` keypoints.jsonl with its clock perturbed: ~8 % of frames move the clock by something else than
    1/30 s (2/30, 5/30, 0.7 s ahead, or 1 s back)."""
    rng = np.random.default_rng(seed)
    t = 0.0
    with open(src) as f, open(dst, "w") as g:
        for line in f:
            d = json.loads(line)
            r = rng.random()
            t += 1 / 30 if r > 0.08 else float(rng.choice([2 / 30, 5 / 30, 0.7, -1.0]))
            d["t"] = round(t, 6)
            d.pop("frame", None)
            g.write(json.dumps(d) + "\n")
    return dst


def capture(keypoints: Path, camera: Path) -> list[np.ndarray]:
    """Every (N, 27, 17, 2) batch the product's PeopleLifter hands to onnxruntime while lifting ``keypoints``."""
    from edge_runtime.__main__ import main

    batches: list[np.ndarray] = []
    orig = lifter_mod._lift

    def recording(lifter, lifters):
        batches.append(np.array([lf.window() for lf in lifters]))
        return orig(lifter, lifters)

    lifter_mod._lift = recording
    try:
        with contextlib.redirect_stdout(io.StringIO()):
            rc = main(["lift", "--keypoints", str(keypoints), "--camera", str(camera), "--person", "all", "--quiet",
                       "--out", str(keypoints.with_suffix(".lifted.jsonl"))])
    finally:
        lifter_mod._lift = orig
    if rc:
        raise SystemExit(f"lift failed ({rc})")
    return batches


def compare(sess, batches: list[np.ndarray], pool: np.ndarray, rng: np.random.Generator) -> dict:
    """Each window's batch-1 output against its output inside (a) its own frame's batch, (b) random batches of
    2 and 3 drawn from ``pool``."""
    run = lambda x: sess.run(OUTPUTS, {INPUT: np.ascontiguousarray(x, np.float32)})
    alone = {}

    def single(w: np.ndarray):
        key = w.tobytes()
        if key not in alone:
            alone[key] = run(w[None])
        return alone[key]

    worst = {"own_frame": [0.0, 0.0], "random_2": [0.0, 0.0], "random_3": [0.0, 0.0]}
    differ = {k: 0 for k in worst}
    count = {k: 0 for k in worst}

    def check(kind: str, batch: np.ndarray):
        pose, root = run(batch)
        for i, w in enumerate(batch):
            p1, r1 = single(w)
            dp, dr = float(np.abs(pose[i] - p1[0]).max()), float(np.abs(root[i] - r1[0]).max())
            worst[kind] = [max(worst[kind][0], dp), max(worst[kind][1], dr)]
            differ[kind] += (dp > 0 or dr > 0)
            count[kind] += 1

    for b in batches:
        if len(b) > 1:
            check("own_frame", b)
    for n in (2, 3):
        for _ in range(len(pool) // n):
            check(f"random_{n}", pool[rng.choice(len(pool), n, replace=False)])
    return {k: {"windows": count[k], "differ": differ[k], "max_abs_pose_m": worst[k][0],
                "max_abs_root_m": worst[k][1]} for k in worst}


def main(argv=None) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--recording", required=True, nargs="+", help="firmware_sim record directories")
    p.add_argument("--model", action="append", required=True, help="name=ASSETS_DIR:precision")
    p.add_argument("--out", required=True)
    p.add_argument("--seed", type=int, default=0)
    a = p.parse_args(argv)
    t0 = time.strftime("%H:%M:%S", time.gmtime())
    captured = {}
    for rec in map(Path, a.recording):
        jumpy = jumpy_copy(rec / "keypoints.jsonl", Path("/tmp") / f"{rec.name}_jumpy.jsonl", a.seed)
        for clock, kp in (("steady", rec / "keypoints.jsonl"), ("jumpy", jumpy)):
            captured[f"{rec.name}/{clock}"] = capture(kp, rec / "camera.json")
    # off the data: N(0, 0.3) windows, where ort_ab.py's check found 8-bit u8 x s8 kernels saturating (ortperf)
    noise = np.random.default_rng(a.seed).normal(0, 0.3, (3000, 27, 17, 2)).astype(np.float32)
    captured["random_normal"] = [w[None] for w in noise]
    result = {"utc_start": t0, "argv": sys.argv[1:], "captures": {
        k: {"calls": len(b), "windows": int(sum(len(x) for x in b)), "multi_person_calls": sum(len(x) > 1 for x in b)}
        for k, b in captured.items()}, "models": {}}
    for spec in a.model:
        name, _, rest = spec.partition("=")
        assets, _, precision = rest.rpartition(":")
        sess, entry, path = session_from_manifest(assets, precision, arch="lifter", threads=1)
        result["models"][name] = {"file": str(path), "sha256": entry["sha256"], "cases": {}}
        for case, batches in captured.items():
            pool = np.concatenate(batches)
            r = compare(sess, batches, pool, np.random.default_rng(a.seed))
            result["models"][name]["cases"][case] = r
            print(f"{name:12s} {case:14s} " + "; ".join(
                f"{k}: {v['differ']}/{v['windows']} differ, max pose {v['max_abs_pose_m']:.2e} root "
                f"{v['max_abs_root_m']:.2e} m" for k, v in r.items()), flush=True)
    result["utc_end"] = time.strftime("%H:%M:%S", time.gmtime())
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(result, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
