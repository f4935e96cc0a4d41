"""The robot command's ``--joints`` JSON lines -> the frames the robot loop is fed.

An input is a few lines of a joints file (camera- or robot-frame joints, ``people`` lists,
``valid``/``reason``/``marker``) built from plausible values mixed, about one value in a
hundred, with hostile ones (see :mod:`fuzz.targets.keypoints_jsonl`), some lines damaged
at the byte level. Each line is parsed on its own; a refused line is the documented
JointsInputError (the first is re-raised at the end). An accepted frame must carry a
timestamp within +-1e10 s and joints that are finite within +-100 m or NaN (not seen):
what the loop's distance checks and replay pacing are stated for.
"""
from __future__ import annotations

import json

import numpy as np
from hypothesis import strategies as st

from edge_runtime.robot.command import JointsInputError, parse_joints_line
from fuzz.harness import SilentAcceptance
from fuzz.targets.keypoints_jsonl import damaged, rarely_hostile

NAME = "joints_jsonl"
DOCUMENTED = (JointsInputError,)

COORD = rarely_hostile(st.one_of(st.floats(-5, 10), st.floats(-100, 100), st.none()))
JOINTS = rarely_hostile(st.lists(rarely_hostile(st.tuples(COORD, COORD, COORD).map(list)), min_size=17, max_size=17))
KIND = st.sampled_from(["joints_cam_m", "joints_robot_m"])
PERSON = st.builds(lambda k, j, pid: {k: j, "id": pid}, KIND, JOINTS, rarely_hostile(st.integers(0, 9)))
FRAME = st.one_of(
    st.builds(lambda k, j, t, v: {"t": t, k: j, "valid": v}, KIND, JOINTS, rarely_hostile(st.floats(0, 100)),
              rarely_hostile(st.just(True))),
    st.builds(lambda people, t, m: {"t": t, "people": people, "marker": m}, rarely_hostile(st.lists(PERSON, max_size=3)),
              rarely_hostile(st.floats(0, 100)), rarely_hostile(st.sampled_from([0, 1, 2, 3]))))


def strategy():
    return st.lists(damaged(FRAME.map(lambda f: json.dumps(f).encode())), min_size=1, max_size=6)


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
