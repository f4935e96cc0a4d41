"""The robot command's ``--joints`` JSON lines -> the frames the robot loop is fed.

An input is a few lines of a joints file (camera- or robot-frame joints, ``people`` lists,
``valid``/``marker``), about half of them with a few fields made hostile and the bytes
maybe damaged (:func:`fuzz.targets.keypoints_jsonl.stream`). Each line is parsed on its own; a refused line is the documented
JointsInputError (the first is re-raised at the end). An accepted frame must carry a
timestamp within +-1e10 s and joints that are finite within +-100 m or NaN (not seen):
what the loop's distance checks and replay pacing are stated for.
"""
from __future__ import annotations

import numpy as np

from edge_runtime.robot.command import JointsInputError, parse_joints_line
from fuzz.harness import SilentAcceptance
from fuzz.targets.keypoints_jsonl import stream

NAME = "joints_jsonl"
DOCUMENTED = (JointsInputError,)

def plausible_frame(i: int, seed: int) -> dict:
    """Frame ``i`` (t = i / 30 s) of a joints file: camera- or robot-frame joints of one
    person, or a ``people`` list, some joints not seen (null)."""
    rng = np.random.default_rng(seed)
    kind = "joints_cam_m" if rng.random() < 0.5 else "joints_robot_m"

    def joints():
        j = rng.normal([0.0, 0.0, 3.0], 1.0, (17, 3))
        return [[None if rng.random() < 0.03 else float(v) for v in row] for row in j]

    if rng.random() < 0.3:
        return {"t": i / 30, "people": [{"id": k, kind: joints()} for k in range(int(rng.integers(0, 3)))],
                "marker": int(rng.integers(0, 4))}
    return {"t": i / 30, kind: joints(), "valid": True}


def strategy():
    return stream(plausible_frame)


def run(lines) -> None:
    refused = None
    for n, raw in enumerate(lines, 1):
        try:
            frame = parse_joints_line(raw, f"walk.jsonl:{n}")
        except JointsInputError as e:
            refused = refused or e
            continue
        if frame is None:
            continue
        if not abs(frame.t_s) <= 1e10:
            raise SilentAcceptance(f"a frame at t = {frame.t_s} s was accepted")
        j = frame.joints_m
        if j is not None and not (np.isnan(j) | (np.abs(j) <= 100.0)).all():
            raise SilentAcceptance(f"joints up to {np.nanmax(np.abs(j))} m were accepted")
    if refused is not None:
        raise refused
