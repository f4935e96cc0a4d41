"""Stand-in 2D pose ONNX models and videos for the camera-source and lift tests."""
from pathlib import Path

import cv2
import numpy as np

IN_H, IN_W = 96, 128
KP_INPUT_PX = np.stack([np.linspace(10, 118, 17), np.linspace(20, 76, 17)], axis=1)  # inside the letterboxed image


def _save(model, path: Path) -> Path:
    import onnx

    model.ir_version = 8
    onnx.checker.check_model(model)
    onnx.save(model, path)
    return path


def make_pose_model(path: Path) -> Path:
    from onnx import TensorProto, helper, numpy_helper

    xy = np.zeros((1, 2, 17, 2), np.float32)
    xy[0, 0] = KP_INPUT_PX
    weight = np.zeros((1, 2, 17, 1), np.float32)
    weight[0, 0] = 1.0
    inits = [numpy_helper.from_array(a, n) for a, n in (
        (xy, "xy"), (weight, "weight"), (np.array([0, 0, IN_H // 2, IN_W // 2], np.int64), "starts"),
        (np.array([1, 1, IN_H // 2 + 1, IN_W // 2 + 1], np.int64), "ends"))]
    nodes = [helper.make_node("Slice", ["image", "starts", "ends"], ["red"]),
             helper.make_node("Mul", ["red", "weight"], ["score"]),
             helper.make_node("Concat", ["xy", "score"], ["keypoints"], axis=3)]
    graph = helper.make_graph(nodes, "pose_standin",
                              [helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 3, IN_H, IN_W])],
                              [helper.make_tensor_value_info("keypoints", TensorProto.FLOAT, [1, 2, 17, 3])], inits)
    return _save(helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)]), path)


def make_heatmap_model(path: Path, peaks_hw) -> Path:
    from onnx import TensorProto, helper, numpy_helper

    hm = np.zeros((1, 17, 24, 32), np.float32)
    for j, (r, c) in enumerate(peaks_hw):
        hm[0, j, r, c] = 0.7
    nodes = [helper.make_node("ReduceMean", ["image"], ["m"], keepdims=1),
             helper.make_node("Mul", ["m", "zero"], ["z"]),
             helper.make_node("Add", ["hm", "z"], ["heatmaps"])]
    graph = helper.make_graph(nodes, "heatmap_standin",
                              [helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 3, IN_H, IN_W])],
                              [helper.make_tensor_value_info("heatmaps", TensorProto.FLOAT, [1, 17, 24, 32])],
                              [numpy_helper.from_array(hm, "hm"), numpy_helper.from_array(np.zeros(1, np.float32), "zero")])
    return _save(helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)]), path)


def write_video(path: Path, n: int = 8, size=(160, 80), bgr=(0, 0, 255), fps: float = 25.0) -> Path:
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, size)
    assert w.isOpened()
    for _ in range(n):
        w.write(np.full((size[1], size[0], 3), bgr, np.uint8))
    w.release()
    return path
