"""export.step_model: the ConvLSTM as one step per sub-window, exported with the trained weights."""
import numpy as np
import pytest
import torch

from edge_runtime.core.onnx import open_session
from edge_runtime.wearable.labels import CLASSES
from export.onnx_export import ExportError, example_input, get_metadata
from export.step_model import StepConvLSTM, check_step_parity, run_steps, step_states, to_step_onnx
from models.nets import build


@pytest.fixture(scope="module")
def model():
    torch.manual_seed(0)
    return build("convlstm", len(CLASSES)).eval()


def test_the_torch_step_module_gives_the_convlstm_decision_after_every_s(model):
    x = torch.from_numpy(example_input(5))
    step = StepConvLSTM(model).eval()
    h = c = torch.zeros(5, model.lstm.hidden_size)
    with torch.no_grad():
        ref = torch.softmax(model(x, all_steps=True), dim=2)
        for s in range(6):
            p, h, c = step(x[:, s], h, c)
            torch.testing.assert_close(p, ref[:, s], atol=1e-6, rtol=0)


def test_the_onnx_step_graph_matches_torch_and_declares_its_contract(model):
    onx = to_step_onnx(model, CLASSES, commit="")
    assert [i.name for i in onx.graph.input] == ["imu", "h", "c"]
    assert [o.name for o in onx.graph.output] == ["probs", "h_out", "c_out"]
    assert "LSTM" not in {n.op_type for n in onx.graph.node}  # the cell as MatMul/Gemm: the quantiser reaches it
    assert {o.domain for o in onx.opset_import} <= {"", "ai.onnx"}
    meta = get_metadata(onx)
    assert meta["arch"] == "convlstm_step" and meta["hidden"] == "100"
    assert check_step_parity(model, onx, example_input(16, seed=2))["ok"]


def test_step_states_are_the_feeds_the_steps_saw(model):
    sess = open_session(to_step_onnx(model, CLASSES, commit="").SerializeToString())
    x = example_input(3)
    feeds = step_states(sess, x)
    assert len(feeds) == 6 and not feeds[0]["h"].any() and feeds[5]["h"].any()
    probs = run_steps(sess, x)
    last, _, _ = sess.run(["probs", "h_out", "c_out"], feeds[5])
    np.testing.assert_array_equal(last, probs[5])


def test_only_a_convlstm_becomes_a_step_model():
    with pytest.raises(ExportError, match="ConvLSTM"):
        to_step_onnx(build("cnn", len(CLASSES)), CLASSES, commit="")
