"""A stand-in ONNX lifter with the shipped contract (keypoints_2d (N, 27, 17, 2) -> pose_3d, root_3d), and keypoints to feed it."""
import math
from pathlib import Path

import numpy as np

from edge_runtime.core.manifest import (
    SCHEMA_VERSION,
    sha256_file,
    write_manifest,
)

RF = 27


F_CANON = 640 / math.tan(math.radians(50))


CANONICAL = {"width_px": 1280, "height_px": 720, "fx_px": F_CANON, "fy_px": F_CANON, "cx_px": 640.0, "cy_px": 360.0}


def _standin_model(seed: int = 0, rf: int = RF):
    import onnx
    from onnx import TensorProto, helper, numpy_helper

    rng = np.random.default_rng(seed)
    n_in = rf * 17 * 2
    w_pose = rng.normal(0, 0.05, (n_in, 51)).astype(np.float32)
    w_root = rng.normal(0, 0.05, (n_in, 3)).astype(np.float32)
    b_root = np.array([0.0, 0.0, 5.0], np.float32)  # 5 m in front of the camera
    inits = [numpy_helper.from_array(a, n) for a, n in (
        (w_pose, "w_pose"), (w_root, "w_root"), (b_root, "b_root"),
        (np.array([-1, n_in], np.int64), "flat"), (np.array([-1, 1, 17, 3], np.int64), "pose_shape"),
        (np.array([-1, 1, 3], np.int64), "root_shape"))]
    nodes = [helper.make_node("Reshape", ["keypoints_2d", "flat"], ["x"]),
             helper.make_node("MatMul", ["x", "w_pose"], ["p"]),
             helper.make_node("Reshape", ["p", "pose_shape"], ["pose_3d"]),
             helper.make_node("MatMul", ["x", "w_root"], ["r0"]),
             helper.make_node("Add", ["r0", "b_root"], ["r1"]),
             helper.make_node("Reshape", ["r1", "root_shape"], ["root_3d"])]
    graph = helper.make_graph(
        nodes, "lifter_standin",
        [helper.make_tensor_value_info("keypoints_2d", TensorProto.FLOAT, ["N", rf, 17, 2])],
        [helper.make_tensor_value_info("pose_3d", TensorProto.FLOAT, ["N", 1, 17, 3]),
         helper.make_tensor_value_info("root_3d", TensorProto.FLOAT, ["N", 1, 3])], inits)
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    model.ir_version = 8
    onnx.checker.check_model(model)
    return model


def make_lifter_assets(d: Path, seed: int = 0, rf: int = RF, extra_entries=()) -> Path:
    """fp32 + int8 (static QDQ quantisation, batch-independent) stand-in lifters with a
    manifest in ``d``."""
    import onnx
    from onnxruntime.quantization import CalibrationDataReader, QuantFormat, QuantType, quantize_static

    class Calibration(CalibrationDataReader):
        def __init__(self):
            rng = np.random.default_rng(seed)
            self.items = iter([{"keypoints_2d": rng.uniform(-1, 1, (8, rf, 17, 2)).astype(np.float32)}
                               for _ in range(4)])

        def get_next(self):
            return next(self.items, None)

    d.mkdir(parents=True, exist_ok=True)
    fp = d / "lifter.fp32.onnx"
    onnx.save(_standin_model(seed, rf), fp)
    q = d / "lifter.int8.onnx"
    quantize_static(str(fp), str(q), Calibration(), quant_format=QuantFormat.QDQ,
                    activation_type=QuantType.QInt8, weight_type=QuantType.QInt8)
    entries = [{"name": f"lifter-{p}", "file": f.name, "sha256": sha256_file(f), "precision": p, "arch": "lifter",
                "parameters": {"onnx": rf * 17 * 2 * 54 + 3}, "classes": [],
                "inputs": [{"name": "keypoints_2d", "shape": ["N", rf, 17, 2], "dtype": "float32"}],
                "outputs": [{"name": "pose_3d", "shape": ["N", 1, 17, 3], "dtype": "float32"},
                            {"name": "root_3d", "shape": ["N", 1, 3], "dtype": "float32"}],
                "metrics": {}, "provenance": {"command": "test stand-in"},
                "receptive_field": rf, "joints": "h36m-17", "camera": dict(CANONICAL)}
               for f, p in ((fp, "fp32"), (q, "int8"))]
    write_manifest(d, {"version": SCHEMA_VERSION, "created_by": "test", "models": [*extra_entries, *entries]})
    return d


def random_walk_keypoints(rng, n: int, width=1280, height=720) -> np.ndarray:
    """(n, 17, 3) plausible-looking canonical pixels (a skeleton drifting), scores 0.9."""
    base = rng.uniform([400, 150], [880, 550], (17, 2))
    drift = np.cumsum(rng.normal(0, 4, (n, 1, 2)), axis=0) + rng.normal(0, 1.5, (n, 17, 2))
    xy = np.clip(base + drift, 0, [width - 1, height - 1])
    return np.concatenate([xy, np.full((n, 17, 1), 0.9)], axis=2)


def onnx_calls(template, monkeypatch) -> list[int]:
    """The batch sizes of every onnxruntime call a lifter (``template``, a StreamingLifter, and the siblings made of
    it from now on) makes: its plain call (session.run or its compiled run) and its bound one (IOBinding, made per
    batch size by ``edge_runtime.robot.lifter._bind``, session 24)."""
    import edge_runtime.robot.lifter as lm

    sizes = []
    run = template._run
    template._run = lambda outs, feed, opts: sizes.append(len(feed[lm.INPUT_NAME])) or run(outs, feed, opts)
    bind = lm._bind

    def counted(session, windows):
        bound = bind(session, windows)
        if bound is None:
            return None
        call, x, pose, root = bound
        return (lambda: sizes.append(len(x)) or call()), x, pose, root

    monkeypatch.setattr(lm, "_bind", counted)
    return sizes
