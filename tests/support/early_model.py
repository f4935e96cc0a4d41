"""A small stand-in for the early-decision ConvLSTM: ``imu`` (N, S, 33, 3) -> ``probs`` (N, 6).

The shipped model takes a fixed S = 6; the model trained for partial captures takes S = 1..6.
Tests build this one instead of depending on new assets: a softmax of a linear map of the
mean of the S sub-windows, so its answer depends on how many sub-windows it is given."""
from __future__ import annotations

import numpy as np

from edge_runtime.wearable.classifier import Engine
from edge_runtime.wearable.labels import CLASSES


def model_bytes(dynamic: bool = True, seed: int = 0) -> bytes:
    from onnx import TensorProto, helper, numpy_helper

    rng = np.random.default_rng(seed)
    w = rng.normal(0, 1.0, (3, len(CLASSES))).astype(np.float32)
    b = rng.normal(0, 0.5, len(CLASSES)).astype(np.float32)
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


def engine(dynamic: bool = True, early: dict | None = None, seed: int = 0) -> Engine:
    """The stand-in on onnxruntime, with a manifest entry carrying ``early`` when given."""
    entry = {"name": "standin", "precision": "fp32"}
    if early is not None:
        entry["early"] = early
    return Engine(model_bytes(dynamic, seed), classes=CLASSES, name="standin", precision="fp32", entry=entry)
