"""Keypoint JSON lines -> person selection -> the streaming lifter's model input.

An input is a few lines of a keypoint file: plausible frames (people, keypoints around the
image, scores, nulls, a point far off now and then), about half of them with a few fields
made hostile (NaN/Infinity literals, 1e308, 400-digit integers, strings and booleans where
numbers belong, wrong list shapes) and the bytes maybe damaged (non-UTF-8 bytes, deep
nesting, cut short). Every line is parsed; a
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
from fuzz.targets.calibration_json import mutated_json

NAME = "keypoints_jsonl"
DOCUMENTED = (KeypointInputError,)

RF = 27
CANONICAL = CameraModel.from_fov(1280, 720)
CAMERA = CameraModel(900.0, 900.0, 640.0, 360.0, 1280, 720, (-0.28, 0.07, 0.001, -0.001, 0.0))

def plausible_frame(i: int, seed: int) -> dict:
    """Frame ``i`` of a stream (t = i / 30 s): 1-3 people, COCO keypoints around the image,
    scores in [0, 1], some not seen (null), now and then one far outside the image."""
    rng = np.random.default_rng(seed)
    people = []
    for pid in range(int(rng.integers(0, 4))):
        kp = np.column_stack([rng.normal(640, 200, 17), rng.normal(360, 150, 17), rng.uniform(0, 1, 17)])
        kp[rng.random(17) < 0.02, 0] = rng.choice([-9e5, 9e5, 5e4])  # finite, in range, far off
        rows = [[None if rng.random() < 0.03 else float(v) for v in row] for row in kp]
        people.append({"id": pid, "keypoints": rows if rng.random() < 0.8 else [v for r in rows for v in r]})
    return {"t": i / 30, "frame": i, "format": "coco", "people": people}


def stream(frame_of) -> st.SearchStrategy[list[bytes]]:
    """1-8 lines of ``frame_of(i, seed)`` frames, each either as written or with a few fields
    made hostile and the bytes maybe damaged (:func:`fuzz.targets.calibration_json.mutated_json`)."""
    def line(i: int, seed: int) -> st.SearchStrategy[bytes]:
        frame = frame_of(i, seed)
        return st.one_of(st.just(json.dumps(frame).encode()), mutated_json(frame))

    return st.lists(st.integers(0, 2**32 - 1), min_size=1, max_size=8).flatmap(
        lambda seeds: st.tuples(*(line(i, s) for i, s in enumerate(seeds))).map(list))


class ModelProbe:
    """The lifter's ONNX session stand-in: checks every window the lifter hands the model."""

    def get_inputs(self):
        return [SimpleNamespace(name=INPUT_NAME, shape=[1, RF, 17, 2])]

    def get_outputs(self):
        return [SimpleNamespace(name=POSE_OUTPUT), SimpleNamespace(name=ROOT_OUTPUT)]

    def run(self, outputs, feeds, run_options=None):  # onnxruntime's signature: the lifter passes run_options
        x = feeds[INPUT_NAME]
        if not np.isfinite(x).all() or np.abs(x).max() > MAX_NORMALISED:
            raise SilentAcceptance(f"the lifter's model got a window with max |x| = {np.abs(x).max()}")
        n = x.shape[0]
        return np.zeros((n, 1, 17, 3), np.float32), np.full((n, 1, 3), 3.0, np.float32)


ENTRY = {"name": "lifter-probe", "receptive_field": RF, "joints": "h36m-17", "camera": CANONICAL.to_dict()}


def strategy():
    return stream(plausible_frame)


def run(lines) -> None:
    fmt = "coco"
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
