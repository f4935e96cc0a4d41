"""The lifter's input centering folded into its first convolutions (``python -m export lifter
--int8-fold-centering``; off by default, so the shipped int8 lifter stays as it was built).

The exported lifter (``models.lifter.LifterNet``) starts with a linear map of each frame's 34 values: the root
joint's x/y, then 4 x (joint - root) for the 16 other joints (``/Slice``, ``/Slice_1``, ``/Sub``, ``/Mul``,
``/Concat``), read by the pose and the trajectory branches' expand convolutions. Folding that map into those two
convolutions' weights gives the same function up to float rounding (about 2e-6 m on the shipped fp32 graph)
with 5 graph nodes fewer. Why: at batch 1 each onnxruntime node costs about a microsecond, and in the int8 graph
the centering is 9 nodes of quantise / slice / dequantise glue; the folded int8 lifter's bench call is 12-16 %
faster on an AVX2-only x86 (reports/bench/s18_ortperf/report.md). The price: its first int8 convolutions then
read the raw keypoints, quantised on their whole image range instead of the centred ones, which costs some
accuracy (the same report: MPJPE +0.6-0.7 mm, root error up to +19 mm on development seeds), so it is a candidate
for the lead to weigh, not a default.
"""
from __future__ import annotations

import numpy as np
import onnx
from onnx import numpy_helper

INPUT_NAME = "keypoints_2d"
CENTERING = ("/Slice", "/Slice_1", "/Sub", "/Mul", "/Concat")
"""The fp32 graph's centering nodes, as torch names them on export."""
EXPAND_CONVS = ("/pose/expand_conv/Conv", "/trajectory/expand_conv/Conv")


def centering_matrix(joints: int, scale: float) -> np.ndarray:
    """(2J, 2J) A with centred = A @ raw, both joint-major and x/y minor: the root's x/y kept, every other
    joint's ``scale`` x (joint - root)."""
    a = np.zeros((2 * joints, 2 * joints))
    a[0, 0] = a[1, 1] = 1.0
    for j in range(1, joints):
        for c in range(2):
            a[2 * j + c, 2 * j + c] = scale
            a[2 * j + c, c] = -scale
    return a


def _constant(g: onnx.GraphProto, name: str) -> np.ndarray:
    inits = {i.name: i for i in g.initializer}
    if name in inits:
        return numpy_helper.to_array(inits[name])
    node = next((n for n in g.node if n.op_type == "Constant" and n.output[0] == name), None)
    if node is None:
        raise ValueError(f"lifter graph: {name} is not a constant")
    return numpy_helper.to_array(node.attribute[0].t)


def fold_input_centering(model: onnx.ModelProto) -> onnx.ModelProto:
    """A copy of the fp32 lifter graph ``model`` with its input centering folded into the expand convolutions.
    ValueError when the graph does not start with the centering this module knows (e.g. it is already folded)."""
    m = onnx.ModelProto()
    m.CopyFrom(model)
    g = m.graph
    nodes = {n.name: n for n in g.node}
    missing = [k for k in (*CENTERING, *EXPAND_CONVS) if k not in nodes]
    if missing:
        raise ValueError(f"lifter graph: no input centering to fold (missing {', '.join(missing)})")
    sub, mul, concat = nodes["/Sub"], nodes["/Mul"], nodes["/Concat"]
    root, rest = nodes["/Slice"], nodes["/Slice_1"]
    if (root.input[0], rest.input[0]) != (INPUT_NAME, INPUT_NAME) or list(sub.input) != [rest.output[0], root.output[0]] \
            or mul.input[0] != sub.output[0] or list(concat.input) != [root.output[0], mul.output[0]]:
        raise ValueError("lifter graph: the centering nodes are not wired as [root, scale x (joints - root)]")
    scale = float(_constant(g, mul.input[1]))
    joints = next(d.dim_value for d in g.input[0].type.tensor_type.shape.dim[2:3])
    a = centering_matrix(joints, scale)
    inits = {i.name: i for i in g.initializer}
    for name in EXPAND_CONVS:
        w_name = nodes[name].input[1]
        w = numpy_helper.to_array(inits[w_name]).astype(np.float64)  # (out, 2J, k) on the centred values
        if w.shape[1] != a.shape[0]:
            raise ValueError(f"lifter graph: {name} reads {w.shape[1]} values per frame, not {a.shape[0]}")
        inits[w_name].CopyFrom(numpy_helper.from_array(np.einsum("ock,cd->odk", w, a).astype(np.float32), w_name))
    for n in g.node:  # whatever read the centred values (the reshape and its shape) reads the raw ones
        for k, i in enumerate(n.input):
            if i == concat.output[0]:
                n.input[k] = INPUT_NAME
    keep = [n for n in g.node if n.name not in CENTERING]
    used = {i for n in keep for i in n.input}
    # the slices' starts/ends/axes were Constant nodes: left unread they make onnxruntime warn on every load
    keep = [n for n in keep if n.op_type != "Constant" or n.output[0] in used]
    del g.node[:]
    g.node.extend(keep)
    unused = [i for i in g.initializer if i.name not in used]
    for i in unused:
        g.initializer.remove(i)
    onnx.checker.check_model(m)
    return m
