"""``python -m firmware_sim <command>``: simulated devices.

Commands:
  drive   a simulated drive of the wrist IMU: DIR/imu.csv + DIR/truth.json (+ DIR/drive.png with --plot)
  cohort  the 20-subject cohort (baseline + 5 experimental trials each): one .npz per trial + cohort.json

Further commands register themselves through :func:`build_parser` (one subparser each).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from edge_runtime.cli import CliError, add_module_commands, make_parser, positive_float, positive_int, run


def _out_dir(path: str) -> Path:
    out = Path(path)
    try:
        out.mkdir(parents=True, exist_ok=True)
        probe = out / ".write_test"
        probe.write_text("")
        probe.unlink()
    except OSError as e:
        raise CliError(f"cannot write to output directory {str(out)!r}: {e.strerror or e}") from None
    return out


# ----------------------------------------------------------------------------------------------

def cmd_drive(args) -> int:
    from edge_runtime.wearable.detector import detect_triggers
    from firmware_sim.devices.wrist import make_subjects, simulate_drive
    from firmware_sim.devices.wrist_io import write_drive

    subject = None
    if args.subject is not None:
        cohort = make_subjects(max(20, args.subject), seed=args.cohort_seed)
        subject = cohort[args.subject - 1]
    out = _out_dir(args.out)
    rec = simulate_drive(args.minutes, args.seed, subject)
    try:
        csv, truth = write_drive(rec, out)
    except OSError as e:
        raise CliError(f"cannot write to {str(out)!r}: {e.strerror or e}") from None
    trig = detect_triggers(rec.acc_mps2)
    counts: dict[str, int] = {}
    for e in rec.events:
        counts[e.label] = counts.get(e.label, 0) + 1
    msg = (f"drive: {args.minutes:g} min, subject {rec.subject_id}, {len(rec.acc_mps2)} samples at 100 Hz, "
           f"{len(rec.events)} events ({', '.join(f'{k} {v}' for k, v in sorted(counts.items()))}), "
           f"{len(trig)} detector triggers -> {csv}, {truth}")
    if args.plot:
        from firmware_sim.devices.wrist_plots import plot_drive

        png = out / "drive.png"
        plot_drive(rec, trig, png)
        msg += f", {png}"
    print(msg)
    return 0


def cmd_cohort(args) -> int:
    from firmware_sim.scenarios.cohort import write_cohort

    out = _out_dir(args.out)
    try:
        index = write_cohort(out, args.subjects, args.seed, args.trial_minutes, progress=not args.quiet)
    except OSError as e:
        raise CliError(f"cannot write to {str(out)!r}: {e.strerror or e}") from None
    d = index["detector"]
    print(f"cohort: {args.subjects} subjects x {len(index['trials'])} trials -> {out}/cohort.json; "
          f"{d['distractions']} distractions + {d['other_events']} Other; detector recall {d['recall']:.3f}, "
          f"precision {d['precision']:.3f} ({d['captures']} captures, {d['false_alarms']} false alarms)")
    if args.json:
        Path(args.json).write_text(json.dumps(d, indent=1))
    return 0


def build_parser() -> argparse.ArgumentParser:
    ap, sub = make_parser("python -m firmware_sim", "Simulated devices and world.")

    d = sub.add_parser("drive", help="a simulated drive of the wrist IMU with its ground truth")
    d.add_argument("--minutes", type=positive_float, required=True, help="length of the drive (min)")
    d.add_argument("--seed", type=int, default=0)
    d.add_argument("--out", required=True, help="output directory (imu.csv, truth.json, drive.png)")
    d.add_argument("--subject", type=positive_int, default=None,
                   help="subject K (1-based) of the cohort of --cohort-seed; default: a subject outside it")
    d.add_argument("--cohort-seed", type=int, default=0, help="cohort that --subject picks from (default 0)")
    d.add_argument("--plot", action="store_true", help="also write DIR/drive.png")
    d.set_defaults(func=cmd_drive)

    c = sub.add_parser("cohort", help="the simulated cohort: baseline + exp1..exp5 per subject")
    c.add_argument("--subjects", type=positive_int, default=20)
    c.add_argument("--seed", type=int, default=0)
    c.add_argument("--out", required=True, help="output directory (one .npz per trial + cohort.json)")
    c.add_argument("--trial-minutes", type=positive_float, default=15.0)
    c.add_argument("--json", default=None, help="also write the detector figures to this JSON file")
    c.add_argument("--quiet", action="store_true", help="no progress bar")
    c.set_defaults(func=cmd_cohort)

    add_module_commands(sub, __package__, _MODULE_COMMANDS, {name: "sim" for name, _, _ in _MODULE_COMMANDS})
    return ap


# Commands that live in their own module: each module defines ``add_arguments(parser)`` and ``cmd(args)``.
_MODULE_COMMANDS = (
    ("imu", "devices.imu_firmware", "simulated wrist IMU firmware: MAVLink at 100 Hz over a pseudo-terminal"),
    ("can-hub", "devices.can_hub", "simulated CAN bus: a socketcand-protocol hub on 127.0.0.1"),
    ("sawyer", "robot.controller", "simulated Sawyer controller on a CAN or signed MAVLink link"),
    ("hrc", "scenarios.hrc", "closed-loop collision-avoidance scenarios: worker, camera, runtime, Sawyer"),
    ("gola", "scenarios.gola", "chapter 4's posture experiment: GOLA-HRC on a simulated cohort"),
    ("head-error", "scenarios.head_error", "head position error in the robot frame after calibration, through the lifter"),
    ("drive-eval", "scenarios.drive_eval", "held-out simulated driving through the wearable runtime: event recall, "
                                           "first-alert class, onset to alert, false alerts per hour"),
    ("early-tune", "scenarios.early_tuning", "early decisions on validation drives: where the time and the errors "
                                              "go, the decision policy's trade-off and its operating point"),
    ("record", "scenarios.recording", "a ready-to-use recording: several people's COCO keypoints, camera, calibration walk, truth"),
    ("score-lift", "scenarios.lift_score", "a lift's output against a recording's truth: reprojection, MPJPE per motion type"),
    ("crossings", "scenarios.crossings", "people crossing in front of the camera: how often the tracker keeps the right id"),
)


def main(argv: list[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    return run(lambda: args.func(args), bad_input=(ValueError, *getattr(args, "bad_input", ())),
               what=f"firmware_sim {args.command}", extra="sim")


if __name__ == "__main__":
    sys.exit(main())
