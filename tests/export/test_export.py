"""export/: torch -> ONNX (LSTM node, parity, metadata), int8 (what became int8, agreement), CLI."""
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import onnx
import pytest
import torch
from support import REPO_ROOT

from edge_runtime.core.onnx import open_session
from edge_runtime.wearable.classifier import preprocess
from edge_runtime.wearable.labels import CLASSES
from export import onnx_export as ox
from export import quantize as qz
from models.nets import build

ROOT = REPO_ROOT


def _scaled_model(arch, seed=0, k=len(CLASSES)):
    """Random weights, scaled up so that logits spread over several units (parity means something)."""
    torch.manual_seed(seed)
    m = build(arch, k)
    with torch.no_grad():
        for p in m.parameters():
            p.mul_(3.0)
    return m.eval()


@pytest.fixture(scope="module")
def toy():
    """A ConvLSTM trained a few epochs on separable toy windows (decisive predictions)."""
    from models.toy import toy_windows
    from models.train import fit

    ws = toy_windows(n_per_class=24, n_classes=len(CLASSES), n_subjects=3, seed=0, classes=list(CLASSES))
    model = fit("convlstm", ws.X, ws.y, len(CLASSES), epochs=6, seed=0, progress=False)
    return model, ws


@pytest.fixture(scope="module")
def toy_onnx(toy, tmp_path_factory):
    model, ws = toy
    d = tmp_path_factory.mktemp("toy_onnx")
    fp = ox.save_onnx(ox.to_onnx(model, CLASSES, commit="test"), d / "m.onnx")
    return fp, preprocess(ws.X), ws.y


def test_convlstm_graph_keeps_a_real_lstm_node():
    onx = ox.to_onnx(_scaled_model("convlstm"), CLASSES, commit="")
    ops = ox.op_counts(onx)
    assert ops.get("LSTM") == 1
    assert ops.get("Conv") == 2 and ops.get("Softmax") == 1
    assert not {"Loop", "Scan", "ConstantOfShape", "Shape"} & set(ops)  # lean, static graph
    assert max(o.version for o in onx.opset_import if o.domain in ("", "ai.onnx")) >= 17
    inp = onx.graph.input[0]
    assert inp.name == "imu" and inp.type.tensor_type.elem_type == onnx.TensorProto.FLOAT
    dims = [d.dim_param or d.dim_value for d in inp.type.tensor_type.shape.dim]
    assert dims == ["N", "S", 33, 3]  # S sub-windows: the early decisions (issue 12)
    assert [o.name for o in onx.graph.output] == ["probs", "logits"]
    cnn_in = ox.to_onnx(_scaled_model("cnn"), CLASSES, commit="").graph.input[0]
    assert [d.dim_param or d.dim_value for d in cnn_in.type.tensor_type.shape.dim] == ["N", 6, 33, 3]


def test_convlstm_onnx_decides_after_every_prefix(toy, toy_onnx, tmp_path):
    """fp32 and int8 run the first S = 1..6 sub-windows; fp32 is torch's decision after S steps, and
    int8 agrees with fp32 on it."""
    from models.evaluate import predict_steps
    from models.toy import toy_windows

    fp, X, _ = toy_onnx
    q = qz.build_variant(fp, tmp_path / "m.int8.onnx", "qdq_conv", X[:64])
    ws = toy_windows(n_per_class=10, n_classes=len(CLASSES), n_subjects=1, seed=3, classes=list(CLASSES))
    x = preprocess(ws.X)
    ref = predict_steps(toy[0], ws.X)
    s32, s8 = open_session(fp), open_session(q)
    agree = []
    for s in range(1, 7):
        prefix = np.ascontiguousarray(x[:, :s])
        p32 = s32.run(["probs"], {"imu": prefix})[0]
        p8 = s8.run(["probs"], {"imu": prefix})[0]
        assert p32.shape == p8.shape == (len(x), len(CLASSES))
        np.testing.assert_allclose(p32, ref[s - 1], atol=1e-4)
        agree.append(np.mean(p32.argmax(1) == p8.argmax(1)))
    assert min(agree) >= 0.9


@pytest.mark.parametrize("arch", ["convlstm", "cnn", "lstm"])
def test_parity_with_torch(arch):
    m = _scaled_model(arch, seed=3)
    onx = ox.to_onnx(m, CLASSES, commit="")
    x = ox.example_input(32, seed=5) * 1.5
    r = ox.check_parity(m, onx, x)
    assert r["ok"], r
    assert r["max_abs_logits"] < 1e-4 and r["max_abs_probs"] < 1e-4
    with torch.no_grad():
        assert float(m(torch.from_numpy(x)).abs().max()) > 1.0  # the logits are not trivially small
    sess = open_session(onx.SerializeToString())
    for n in (1, 7):  # dynamic batch
        probs, logits = sess.run(None, {"imu": x[:n]})
        assert probs.shape == logits.shape == (n, len(CLASSES))
        np.testing.assert_allclose(probs.sum(1), 1.0, atol=1e-5)


def test_metadata_round_trips():
    m = _scaled_model("convlstm")
    onx = ox.to_onnx(m, CLASSES, model_version="9.9.9+test", commit="abc123")
    meta = ox.get_metadata(onnx.load_from_string(onx.SerializeToString()))
    assert json.loads(meta["classes"]) == list(CLASSES)
    assert meta["input_layout"].startswith("N,S,33,3 (the first S = 1..6") and "dynamic" in meta["input_layout"]
    assert meta["sample_rate_hz"] == "100"
    assert float(meta["resampled_rate_hz"]) == pytest.approx(200 / 7)
    assert meta["model_version"] == "9.9.9+test" and meta["arch"] == "convlstm"
    assert meta["parameters_torch"] == "79998" and meta["parameters_keras"] == "79598"
    assert meta["git_commit"] == "abc123" and meta["precision"] == "fp32"
    # onnxruntime reads the same metadata (what the torch-free engine sees)
    sess = open_session(onx.SerializeToString())
    assert sess.get_modelmeta().custom_metadata_map["classes"] == meta["classes"]


def test_export_is_deterministic():
    m = _scaled_model("convlstm")
    a = ox.to_onnx(m, CLASSES, commit="x").SerializeToString(deterministic=True)
    b = ox.to_onnx(m, CLASSES, commit="x").SerializeToString(deterministic=True)
    assert a == b


def test_int8_graph_holds_int8_ops_and_agrees_with_fp32(toy_onnx, tmp_path):
    fp, X, y = toy_onnx
    q = qz.build_variant(fp, tmp_path / "m.int8.onnx", "qdq_conv", X[:64])
    rep = qz.int8_report(q)
    assert rep["int8_operators"].get("Conv") == 2
    assert rep["fp32_operators"].get("LSTM") == 1
    assert rep["graph_op_types"]["QuantizeLinear"] >= 1 and rep["graph_op_types"]["DequantizeLinear"] >= 1
    assert rep["runtime_op_types"].get("QLinearConv") == 2  # what onnxruntime actually runs
    onx = onnx.load(str(q))
    assert onnx.TensorProto.INT8 in {i.data_type for i in onx.graph.initializer}
    meta = ox.get_metadata(onx)
    assert meta["precision"] == "int8" and json.loads(meta["classes"]) == list(CLASSES)
    p32, p8 = qz.probs_of(fp, X), qz.probs_of(q, X)
    assert np.mean(p32.argmax(1) == p8.argmax(1)) >= 0.95
    # same inputs, same calibration -> same bytes
    q2 = qz.build_variant(fp, tmp_path / "again.onnx", "qdq_conv", X[:64])
    assert q.read_bytes() == q2.read_bytes()


def test_int8_weights_are_7_bit_so_no_cpu_saturates_them(toy_onnx, tmp_path):
    """x86 without VNNI adds pairs of u8 x s8 products in int16: 8-bit weights can saturate there,
    7-bit weights cannot. The integer kernels then compute what the QDQ graph says, on any CPU."""
    fp, X, _ = toy_onnx
    q = qz.build_variant(fp, tmp_path / "m.int8.onnx", "qdq_conv", X[:64])
    w = [onnx.numpy_helper.to_array(i) for i in onnx.load(str(q)).graph.initializer
         if i.data_type == onnx.TensorProto.INT8]
    assert w and max(int(np.abs(a.astype(np.int16)).max()) for a in w) <= 64
    assert qz.integer_kernel_drift(q, {"imu": X[:64]}) < 1e-4
    full = qz.build_variant(fp, tmp_path / "m.full.onnx", "qdq_conv", X[:64], reduce_range=False)
    assert max(int(np.abs(onnx.numpy_helper.to_array(i).astype(np.int16)).max())
               for i in onnx.load(str(full)).graph.initializer if i.data_type == onnx.TensorProto.INT8) > 64


def test_dynamic_variant_quantises_the_lstm(toy_onnx, tmp_path):
    fp, X, _ = toy_onnx
    q = qz.build_variant(fp, tmp_path / "dyn.onnx", "qdq_conv+dyn_lstm", X[:32])
    rep = qz.int8_report(q)
    assert rep["runtime_op_types"].get("DynamicQuantizeLSTM") == 1
    assert rep["int8_operators"].get("LSTM") == 1 and rep["int8_operators"].get("Conv") == 2


def test_choose_measures_and_reports(toy_onnx, tmp_path):
    fp, X, y = toy_onnx
    rep = qz.choose(fp, tmp_path / "c.onnx", X[:64], eval_x=X, eval_y=y,
                    variants=["qdq_conv", "qdq_conv+dyn_lstm"], n_timing=200)
    assert rep["method"] in ("qdq_conv", "qdq_conv+dyn_lstm")
    cands = rep["selection"]["candidates"]
    assert set(cands) == {"qdq_conv", "qdq_conv+dyn_lstm"}
    for c in cands.values():
        assert c["p50_us"] > 0 and 0 <= c["agreement"] <= 1 and "int8_operators" in c
        assert c["reduce_range"] is True and c["integer_kernel_drift"] < 1e-4
    assert rep["reduce_range"] is True and rep["int8_operators"] and (tmp_path / "c.onnx").exists()
    with pytest.raises(qz.QuantizeError):
        qz.choose(fp, tmp_path / "d.onnx", X[:8], eval_x=X, variants=["nope"])


def test_choose_gates_on_early_decisions(toy_onnx, tmp_path):
    """With an early gate, each candidate's agreement after 1..5 sub-windows is measured and must
    reach it: an unreachable gate refuses every candidate."""
    fp, X, y = toy_onnx
    rep = qz.choose(fp, tmp_path / "e.onnx", X[:64], eval_x=X, eval_y=y, variants=["qdq_conv"], n_timing=50,
                    early_min_agreement=0.5)
    early = rep["selection"]["candidates"]["qdq_conv"]["early_agreement"]
    assert 0.5 <= early <= 1.0 and "after every S in [1, 2, 3, 4, 5]" in rep["selection"]["rule"]
    with pytest.raises(qz.QuantizeError, match="no int8 variant"):
        qz.choose(fp, tmp_path / "f.onnx", X[:64], eval_x=X, eval_y=y, variants=["qdq_conv"], n_timing=50,
                  early_min_agreement=1.01)


def test_fastest_breaks_near_ties_by_candidate_order():
    p50 = {"a": 100.0, "b": 98.0, "c": 90.0}
    assert qz.fastest(p50, ["a", "b", "c"]) == "c"
    assert qz.fastest(p50, ["a", "b"]) == "b"                # strictly fastest without a tie margin
    assert qz.fastest(p50, ["a", "b"], tie=0.03) == "a"      # 2 % apart: tied, the earlier candidate wins
    assert qz.fastest(p50, ["b", "a"], tie=0.03) == "b"


def _write_checkpoint(model, d: Path):
    from models.train import save_checkpoint

    return save_checkpoint(d, model, arch="convlstm", classes=CLASSES, seed=0, epochs=6, metrics={}, data={})


@pytest.mark.slow
def test_cli_onnx_and_quantize(toy, tmp_path, capsys):
    from export.__main__ import main
    from models.dataset import save_npz

    model, ws = toy
    ck = _write_checkpoint(model, tmp_path / "ck")
    assert main(["onnx", "--checkpoint", str(ck), "--out", str(tmp_path / "m.onnx")]) == 0
    assert "parity" in capsys.readouterr().out
    npz = save_npz(tmp_path / "calib.npz", ws)
    rc = main(["quantize", "--onnx", str(tmp_path / "m.onnx"), "--calib", str(npz), "--out",
               str(tmp_path / "m.int8.onnx"), "--variants", "qdq_conv,qdq_conv_pt", "--calib-windows", "60",
               "--json", str(tmp_path / "q.json")])
    assert rc == 0
    rep = json.loads((tmp_path / "q.json").read_text())
    assert rep["method"] in ("qdq_conv", "qdq_conv_pt") and rep["int8_operators"]["Conv"] == 2


@pytest.mark.parametrize("argv, needle", [
    (["onnx", "--checkpoint", "/nonexistent/model.pt", "--out", "x.onnx"], "/nonexistent/model.pt"),
    (["quantize", "--onnx", "/nonexistent.onnx", "--calib", "c.npz", "--out", "o.onnx"], "/nonexistent.onnx"),
    (["compare-int8", "--loso-dir", "/nonexistent_dir"], "/nonexistent_dir"),
    (["assets", "--seed", "0", "--epochs", "0"], "--epochs"),
])
def test_cli_bad_input_is_one_line(argv, needle, capsys):
    from export.__main__ import main

    assert main(argv) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and needle in err and "Traceback" not in err


@pytest.mark.slow
def test_cli_bad_checkpoint_file_subprocess(tmp_path):
    bad = tmp_path / "model.pt"
    bad.write_bytes(b"not a torch file")
    r = subprocess.run([sys.executable, "-m", "export", "onnx", "--checkpoint", str(bad), "--out",
                        str(tmp_path / "x.onnx")], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert r.returncode == 2
    assert len(r.stderr.strip().splitlines()) == 1 and str(bad) in r.stderr and "Traceback" not in r.stderr


def test_quantize_refuses_mismatched_classes(toy_onnx, tmp_path, capsys):
    from export.__main__ import main
    from models.dataset import save_npz
    from models.toy import toy_windows

    fp, _, _ = toy_onnx
    npz = save_npz(tmp_path / "other.npz", toy_windows(n_per_class=3, n_classes=3))
    assert main(["quantize", "--onnx", str(fp), "--calib", str(npz), "--out", str(tmp_path / "o.onnx")]) == 2
    err = capsys.readouterr().err
    assert "classes" in err and str(npz) in err
