"""Cache the head-error tool's per-frame inputs, one pickle per (seed, calibration method).

    PYTHONPATH=. python reports/robot/s17_headtail/cache.py --seed 4 --calibration-method truth --out /tmp/headtail

Runs ``firmware_sim head-error``'s own ``cmd`` (so its JSON is written too, the reference figures) with
the module's ``work_motion``, ``lift`` and calibration calls wrapped to keep, per placement, the worker's
motion (true joints, activity labels), the lifted frames the robot loop got (joints, observed, warm-up)
and the calibration. ``analyse.py`` replays the anchoring variants on them.
"""
from __future__ import annotations

import argparse
import dataclasses
import pickle
from pathlib import Path

from firmware_sim.devices.camera import REAL_DETECTOR
from firmware_sim.scenarios import head_error as he

# diagnosis only: the real detector without its fixed per-person joint offsets, or with its drifting half white
NOISE_VARIANTS = {"real": REAL_DETECTOR, "no-offset": dataclasses.replace(REAL_DETECTOR, offset_sd_m=0.0),
                  "white": dataclasses.replace(REAL_DETECTOR, drift_tau_s=1e-6),
                  "white-no-offset": dataclasses.replace(REAL_DETECTOR, drift_tau_s=1e-6, offset_sd_m=0.0)}


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seed", type=int, required=True)
    ap.add_argument("--calibration-method", required=True)
    ap.add_argument("--placements", type=int, default=40)
    ap.add_argument("--out", required=True)
    ap.add_argument("--noise-variant", choices=sorted(NOISE_VARIANTS), default="real")
    a = ap.parse_args()
    kept: list[dict] = []
    orig_work, orig_lift, orig_true, orig_fit = he.work_motion, he.lift, he.true_calibration, he.from_recording

    def work_motion(body, camera, rng):
        m = orig_work(body, camera, rng)
        kept[-1].update(truth_m=m.joints_m, labels=m.labels, camera_m=camera.position_m.copy())
        return m

    def lift(lifter, keypoints, t0_s, warm=False):
        out = orig_lift(lifter, keypoints, t0_s, warm)
        if warm and "truth_m" in kept[-1]:  # the worker's frames (labelled calibration lifts without warm)
            kept[-1].update(joints=out[0], observed=out[1], warming=out[2])
        return out

    def keep_cal(fit):
        def wrapped(*args, **kw):
            kept.append({})
            cal = fit(*args, **kw)
            kept[-1]["cal"] = cal
            return cal
        return wrapped

    he.work_motion, he.lift = work_motion, lift
    he.NOISES["real"] = NOISE_VARIANTS[a.noise_variant]
    tag = f"seed{a.seed}_{a.calibration_method}" + ("" if a.noise_variant == "real" else f"_{a.noise_variant}")
    he.true_calibration, he.from_recording = keep_cal(orig_true), keep_cal(orig_fit)
    out = Path(a.out)
    args = argparse.Namespace(placements=a.placements, seed=a.seed, anchor="on", precision="int8",
                              noise="real", calibration_method=a.calibration_method, assets=None,
                              ray_tolerance_px=None, anchor_window_frames=None, unlabelled=False,
                              json=str(out / f"head_error_{tag}.json"), plot=None)
    he.cmd(args)
    done = [k for k in kept if "joints" in k]
    for k in done:
        k["cal"]._anchor = None  # the replay starts each placement's anchoring afresh
    (out / f"cache_{tag}.pkl").write_bytes(pickle.dumps(done))
    print(f"{len(done)} placements cached")


if __name__ == "__main__":
    main()
