"""export.lifter_fold: the lifter's input centering folded into its expand convolutions computes the same function
(float rounding aside) with 5 nodes fewer; ``python -m export lifter`` does it only when asked."""
from __future__ import annotations

import argparse

import numpy as np
import onnx
import pytest

from edge_runtime.core.manifest import ASSETS_DIR
from edge_runtime.core.onnx import open_session
from export.lifter_assets import add_arguments
from export.lifter_fold import CENTERING, fold_input_centering

OUTPUTS = ["pose_3d", "root_3d"]


@pytest.fixture(scope="module")
def fp32():
    return onnx.load(str(ASSETS_DIR / "lifter.fp32.onnx"))


def test_the_folded_graph_gives_the_same_poses_up_to_float_rounding(fp32):
    folded = fold_input_centering(fp32)
    assert not {n.name for n in folded.graph.node} & set(CENTERING)
    read = {i for n in folded.graph.node for i in n.input}
    gone = [n for n in fp32.graph.node if n.name not in {k.name for k in folded.graph.node}]
    assert all(n.name in CENTERING or n.op_type == "Constant" for n in gone)  # the centering and its constants
    assert all(n.output[0] in read for n in folded.graph.node if n.op_type == "Constant")
    a, b = open_session(fp32.SerializeToString()), open_session(folded.SerializeToString())
    rng = np.random.default_rng(0)
    for scale in (0.3, 1.0):  # normalised image coordinates, and beyond the image
        x = rng.normal(0.0, scale, (32, 27, 17, 2)).astype(np.float32)
        for p, q in zip(a.run(OUTPUTS, {"keypoints_2d": x}), b.run(OUTPUTS, {"keypoints_2d": x})):
            np.testing.assert_allclose(q, p, rtol=0, atol=2e-5)  # metres: float rounding, not a different function


def test_the_model_it_was_given_is_left_as_it_was(fp32):
    before = fp32.SerializeToString()
    fold_input_centering(fp32)
    assert fp32.SerializeToString() == before


def test_a_graph_without_the_centering_is_refused(fp32):
    with pytest.raises(ValueError, match="no input centering"):
        fold_input_centering(fold_input_centering(fp32))


def test_the_export_folds_only_when_asked():
    p = argparse.ArgumentParser()
    add_arguments(p)
    assert p.parse_args(["--seed", "0"]).int8_fold_centering is False
    assert p.parse_args(["--seed", "0", "--int8-fold-centering"]).int8_fold_centering is True
