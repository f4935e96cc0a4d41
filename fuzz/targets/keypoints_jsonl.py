"""Keypoint JSON lines -> person selection -> the streaming lifter's model input.

An input is a few lines of a keypoint file: frames built from plausible values mixed with
hostile ones (NaN/Infinity literals, 1e308, 400-digit integers, strings and booleans where
numbers belong, scores outside [0, 1], wrong list shapes), each line then possibly damaged
at the byte level (non-UTF-8 bytes, deep nesting, cut short). Every line is parsed; a
refused line is a counted invalid frame (the first refusal is re-raised at the end, the
parser's documented one-line error), the others go through :class:`PersonSelector` into a
:class:`StreamingLifter` with a distorted camera. The model is a probe: a window that is
not finite or lies outside the lifter's stated input range (``MAX_NORMALISED``) reaching it
is a silent acceptance.
"""
from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
from hypothesis import strategies as st

from edge_runtime.robot.keypoints import CameraModel, KeypointInputError, PersonSelector, parse_keypoint_line
from edge_runtime.robot.lifter import INPUT_NAME, MAX_NORMALISED, POSE_OUTPUT, ROOT_OUTPUT, StreamingLifter
from fuzz.harness import SilentAcceptance

NAME = "keypoints_jsonl"
DOCUMENTED = (KeypointInputError,)

RF = 27
CANONICAL = CameraModel.from_fov(1280, 720)
CAMERA = CameraModel(900.0, 900.0, 640.0, 360.0, 1280, 720, (-0.28, 0.07, 0.001, -0.001, 0.0))

HOSTILE = st.one_of(st.floats(), st.sampled_from([1e308, -1e308, 3.5e38, 1e-320, 10**400, -(10**30)]),
                    st.text(max_size=3), st.booleans(), st.none(), st.just([]), st.just({}))


def rarely_hostile(plausible: st.SearchStrategy) -> st.SearchStrategy:
    """``plausible`` 99 times in 100, else a hostile value: a line of 51 numbers is then
    refused about half the time, and the lifter still sees streams of accepted frames."""
    return st.integers(0, 99).flatmap(lambda r: HOSTILE if r == 37 else plausible)  # hypothesis favours 0 and 99


COORD = rarely_hostile(st.one_of(st.floats(-200, 1500), st.floats(-1e6, 1e6), st.none()))
SCORE = rarely_hostile(st.floats(0, 1))
ROW = rarely_hostile(st.tuples(COORD, COORD, SCORE).map(list))
KEYPOINTS = rarely_hostile(st.one_of(st.lists(ROW, min_size=17, max_size=17),
                                     st.lists(ROW, min_size=17, max_size=17).map(lambda r: r[:-1]),
                                     st.lists(COORD, min_size=34, max_size=34)))
PERSON = st.fixed_dictionaries({"keypoints": KEYPOINTS}, optional={"id": rarely_hostile(st.integers(0, 9))})
FRAME = st.fixed_dictionaries(
    {"people": rarely_hostile(st.lists(PERSON, max_size=3)), "t": rarely_hostile(st.floats(0, 100))},
    optional={"frame": rarely_hostile(st.integers(0, 3000)), "format": rarely_hostile(st.just("coco"))})


@st.composite
def damaged(draw, lines: st.SearchStrategy[bytes]) -> bytes:
    """A line of ``lines``, one time in ten damaged at the byte level: a non-UTF-8 byte,
    deep nesting, cut short, or a NaN/Infinity literal, 1e400 or a 400-digit number put in."""
    data = bytearray(draw(lines))
    damage = draw(st.integers(0, 99)) - 90  # hypothesis favours 0: mostly undamaged lines
    if damage == 0 and data:
        data[draw(st.integers(0, len(data) - 1))] = draw(st.integers(0x80, 0xFF))
    elif damage == 1:
        depth = draw(st.integers(50, 20000))
        data = bytearray(b'{"t": 0.1, "people": ' + b"[" * depth + b"]" * depth + b"}")
    elif damage == 2:
        data = data[:draw(st.integers(0, len(data)))]
    elif damage == 3:
        i = draw(st.integers(0, len(data)))
        data[i:i] = draw(st.sampled_from([b"9" * 400, b"NaN", b"-Infinity", b"1e400", b",", b"\x00"]))
    return bytes(data)


def line() -> st.SearchStrategy[bytes]:
    return damaged(FRAME.map(lambda f: json.dumps(f).encode()))


class ModelProbe:
    """The lifter's ONNX session stand-in: checks every window the lifter hands the model."""

    def get_inputs(self):
        return [SimpleNamespace(name=INPUT_NAME, shape=[1, RF, 17, 2])]

    def get_outputs(self):
        return [SimpleNamespace(name=POSE_OUTPUT), SimpleNamespace(name=ROOT_OUTPUT)]

    def run(self, outputs, feeds):
        x = feeds[INPUT_NAME]
        if not np.isfinite(x).all() or np.abs(x).max() > MAX_NORMALISED:
            raise SilentAcceptance(f"the lifter's model got a window with max |x| = {np.abs(x).max()}")
        n = x.shape[0]
        return np.zeros((n, 1, 17, 3), np.float32), np.full((n, 1, 3), 3.0, np.float32)


ENTRY = {"name": "lifter-probe", "receptive_field": RF, "joints": "h36m-17", "camera": CANONICAL.to_dict()}


def strategy():
    return st.tuples(st.lists(line(), min_size=1, max_size=8), st.just("coco"))


def run(data) -> None:
    lines, fmt = data
    lifter = StreamingLifter(ModelProbe(), ENTRY, camera=CAMERA, keypoint_format=fmt)
    selector = PersonSelector()
    refused = None
    for n, raw in enumerate(lines, 1):
        try:
            frame = parse_keypoint_line(raw, f"kp.jsonl:{n}", fmt)
        except KeypointInputError as e:
            refused = refused or e  # a counted invalid frame; the stream goes on
            continue
        if frame is not None:
            person = selector.select(frame.people)
            lifter.push(frame.t_s, None if person is None else person.keypoints)
    if refused is not None:
        raise refused
