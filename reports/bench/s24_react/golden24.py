"""The golden trace of tests/robot/test_golden_trace_s24.py: a window of the bench's robot scenario (two simulated
workers, the box's camera, the int8 lifter, the CAN link to the arm stand-in) recorded once as keypoints, and what the
runtime decided and sent for it. Made with main's code of session 24 (024e41e) and kept: a change that alters any
decision, command or command value makes that test fail.

    cd TREE && OMP_NUM_THREADS=1 /work/main/.venv/bin/python reports/bench/s24_react/golden24.py \\
        --npz /tmp/react24/workers60.npz --first 1500 --frames 300 [--write]

Without ``--write`` it prints how the trace of TREE compares with the stored one.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path.cwd()))

DATA = Path.cwd() / "tests" / "robot" / "data"
INPUT = DATA / "golden_s24_keypoints.npz"
"""(T, 2, 17, 2) float32 COCO pixels of the box's camera (every score 1) and the arm stand-in's working posture."""
GOLDEN = DATA / "golden_s24_trace.json"


def record(src_npz: str, first: int, frames: int) -> None:
    """The window's keypoints as the test's input (x, y in float32; every score is 1 in the bench's scenario)."""
    from bench.robot_cycle import _arm_posture

    kp = np.load(src_npz)["keypoints_px"][first:first + frames]
    assert (kp[..., 2] == 1).all()
    DATA.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(INPUT, xy=kp[..., :2].astype(np.float32), arm_posture_rad=np.array(_arm_posture()))


def main() -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--npz", default="/tmp/react24/workers60.npz")
    ap.add_argument("--first", type=int, default=1500)
    ap.add_argument("--frames", type=int, default=300)
    ap.add_argument("--write", action="store_true")
    a = ap.parse_args()
    sys.path.insert(0, str(Path.cwd() / "tests" / "robot"))
    from test_golden_trace_s24 import golden_trace

    if a.write:
        record(a.npz, a.first, a.frames)
        trace = golden_trace(INPUT)
        GOLDEN.write_text(json.dumps(trace, indent=0) + "\n")
        kinds = [f["kind"] for f in trace["frames"] if f["kind"]]
        print(f"wrote {INPUT} and {GOLDEN}: {len(trace['frames'])} frames, commands "
              f"{ {k: kinds.count(k) for k in sorted(set(kinds))} }, command frames on the bus {len(trace['commands'])}")
        return 0
    same = golden_trace(INPUT) == json.loads(GOLDEN.read_text())
    print("the same as the golden trace" if same else "DIFFERS from the golden trace")
    return 0 if same else 1


if __name__ == "__main__":
    sys.exit(main())
