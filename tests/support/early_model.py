"""A small stand-in for the early-decision ConvLSTM: ``imu`` (N, S, 33, 3) -> ``probs`` (N, 6).

The shipped model takes a fixed S = 6; the model trained for partial captures takes S = 1..6.
Tests build this one instead of depending on new assets: a softmax of a linear map of the
mean of the S sub-windows, so its answer depends on how many sub-windows it is given."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from edge_runtime.wearable.classifier import Engine
from edge_runtime.wearable.labels import CLASSES


def model_bytes(dynamic: bool = True, seed: int = 0, favour: str | None = None) -> bytes:
    """The stand-in's ONNX bytes; ``favour``: a class it answers with probability ~1 (a bias of 30)."""
    from onnx import TensorProto, helper, numpy_helper

    rng = np.random.default_rng(seed)
    w = rng.normal(0, 1.0, (3, len(CLASSES))).astype(np.float32)
    b = rng.normal(0, 0.5, len(CLASSES)).astype(np.float32)
    if favour is not None:
        b[CLASSES.index(favour)] += 30.0
    nodes = [helper.make_node("ReduceMean", ["imu"], ["m"], axes=[1, 2], keepdims=0),
             helper.make_node("MatMul", ["m", "w"], ["z0"]),
             helper.make_node("Add", ["z0", "b"], ["z"]),
             helper.make_node("Softmax", ["z"], ["probs"], axis=-1)]
    s_dim = "S" if dynamic else 6
    graph = helper.make_graph(
        nodes, "early_standin",
        [helper.make_tensor_value_info("imu", TensorProto.FLOAT, ["N", s_dim, 33, 3])],
        [helper.make_tensor_value_info("probs", TensorProto.FLOAT, ["N", len(CLASSES)])],
        [numpy_helper.from_array(w, "w"), numpy_helper.from_array(b, "b")])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    return model.SerializeToString()


def write_assets(directory: Path, early: dict | None = None, favour: str | None = "Phone", dynamic: bool = True
                 ) -> Path:
    """An assets directory with the stand-in as the int8 classifier and a manifest entry (with
    ``early`` when given), as ``--assets DIR`` takes it."""
    from edge_runtime.core.manifest import SCHEMA_VERSION, sha256_file, write_manifest

    directory.mkdir(parents=True, exist_ok=True)
    f = directory / "standin.int8.onnx"
    f.write_bytes(model_bytes(dynamic, favour=favour))
    entry = {"name": "standin-int8", "file": f.name, "sha256": sha256_file(f), "precision": "int8",
             "arch": "convlstm", "parameters": {"torch": 24}, "classes": list(CLASSES),
             "inputs": [{"name": "imu", "shape": ["N", "S" if dynamic else 6, 33, 3], "dtype": "float32"}],
             "outputs": [{"name": "probs", "shape": ["N", 6], "dtype": "float32"}]}
    if early is not None:
        entry["early"] = early
    write_manifest(directory, {"version": SCHEMA_VERSION, "created_by": "test", "models": [entry]})
    return directory


def engine(dynamic: bool = True, early: dict | None = None, seed: int = 0, favour: str | None = None) -> Engine:
    """The stand-in on onnxruntime, with a manifest entry carrying ``early`` when given."""
    entry = {"name": "standin", "precision": "fp32"}
    if early is not None:
        entry["early"] = early
    return Engine(model_bytes(dynamic, seed, favour), classes=CLASSES, name="standin", precision="fp32", entry=entry)


class Scripted:
    """A classifier that decides early: answers (label, p) per sub-window count S, records what it got."""

    classes = CLASSES

    def __init__(self, answers, early_steps=(1, 2, 3, 4, 5, 6), manifest_thresholds=None):
        self.answers, self.early_steps, self.seen = answers, tuple(early_steps), []
        self.early = type("Early", (), {"min_confidence_by_steps": manifest_thresholds or {}})()

    def _probs(self, label, p):
        probs = np.full(len(CLASSES), (1 - p) / (len(CLASSES) - 1), np.float32)
        probs[CLASSES.index(label)] = p
        return probs

    def classify_prefix(self, x, steps):
        self.seen.append((steps, np.array(x)))
        return self._probs(*self.answers.get(steps, ("Phone", 0.3)))

    def classify_capture(self, x700):
        return self.classify_prefix(x700, 6)


def step_signal(n: int, at, rest_mps2: float = 9.81) -> np.ndarray:
    """(n, 3) m/s^2 at rest with a 6 m/s^2 step on x at each frame of ``at`` (alternating up and down):
    each step triggers the detector."""
    acc = np.zeros((n, 3), np.float32)
    acc[:, 2] = rest_mps2
    for i, t in enumerate(at):
        acc[t:, 0] += 6.0 if i % 2 == 0 else -6.0
    return acc


NEUTRAL_WEIGHTS = (1.0,) * len(CLASSES)
"""[alerts] class_weights that leave a stand-in model's probabilities as scripted: the loop's mechanics,
not the shipped operating point (whose weights would reshuffle a stand-in's evenly spread remainder)."""
SCRIPTED_EARLY_THRESHOLDS = (0.9,) * 5 + (-1.0,)
"""[alerts] min_confidence_by_steps that a scripted early step at 0.95 clears (the manifest's for S = 6):
the loop's mechanics, not the shipped operating point (whose early thresholds are refitted per model)."""
