"""export/opsets.py: models declare only the opset domains their nodes use."""
import shutil

import onnx
import pytest
from onnx import TensorProto, helper

from edge_runtime.core.manifest import ASSETS_DIR, load_manifest, verify_all
from export.opsets import apply_to_assets, declare_used_opsets, used_domains

# What onnxruntime's quantiser declares on every model it writes (onnxruntime 1.32)
QUANTISER_DOMAINS = [("", 17), ("ai.onnx.ml", 5), ("ai.onnx.training", 1), ("ai.onnx.preview", 1),
                     ("com.microsoft", 1), ("ai.onnx.preview.training", 1), ("com.microsoft.experimental", 1),
                     ("com.microsoft.nchwc", 1), ("org.pytorch.aten", 1)]


def _model(nodes, domains=QUANTISER_DOMAINS):
    g = helper.make_graph(nodes, "g", [helper.make_tensor_value_info("x", TensorProto.FLOAT, [2])],
                          [helper.make_tensor_value_info("y", TensorProto.FLOAT, [2])])
    return helper.make_model(g, opset_imports=[helper.make_opsetid(d, v) for d, v in domains])


def test_unused_domains_are_dropped_and_used_ones_kept_at_their_version():
    m = _model([helper.make_node("Relu", ["x"], ["r"]),
                helper.make_node("Gelu", ["r"], ["y"], domain="com.microsoft")])
    declare_used_opsets(m)
    assert [(o.domain, o.version) for o in m.opset_import] == [("", 17), ("com.microsoft", 1)]


def test_a_domain_used_only_inside_a_subgraph_is_kept():
    body = helper.make_graph([helper.make_node("Gelu", ["x"], ["z"], domain="com.microsoft")], "body", [],
                             [helper.make_tensor_value_info("z", TensorProto.FLOAT, [2])])
    m = _model([helper.make_node("Constant", [], ["c"], value=helper.make_tensor("c", TensorProto.BOOL, [], [True])),
                helper.make_node("If", ["c"], ["y"], then_branch=body, else_branch=body)])
    assert used_domains(m) == {"", "com.microsoft"}
    assert {o.domain for o in declare_used_opsets(m).opset_import} == {"", "com.microsoft"}


def test_a_lean_model_keeps_its_bytes():
    m = _model([helper.make_node("Relu", ["x"], ["y"])], domains=[("", 17)])
    before = m.SerializeToString(deterministic=True)
    assert declare_used_opsets(m).SerializeToString(deterministic=True) == before


def test_every_shipped_model_declares_only_what_its_nodes_use():
    for e in load_manifest(ASSETS_DIR)["models"]:
        m = onnx.load(str(ASSETS_DIR / e["file"]))
        declared = {o.domain for o in m.opset_import}
        assert declared <= used_domains(m) | {""}, (e["file"], declared)


@pytest.fixture
def bloated_assets(tmp_path):
    """A copy of the shipped assets whose int8 ConvLSTM declares the quantiser's nine domains."""
    from edge_runtime.core.manifest import sha256_file, write_manifest

    dst = tmp_path / "assets"
    shutil.copytree(ASSETS_DIR, dst)
    m = load_manifest(dst)
    entry = next(e for e in m["models"] if e["name"] == "convlstm-int8")
    model = onnx.load(str(dst / entry["file"]))
    declared = {o.domain for o in model.opset_import}
    model.opset_import.extend(helper.make_opsetid(d, v) for d, v in QUANTISER_DOMAINS if d not in declared)
    (dst / entry["file"]).write_bytes(model.SerializeToString(deterministic=True))
    entry.update(sha256=sha256_file(dst / entry["file"]), size_bytes=(dst / entry["file"]).stat().st_size)
    write_manifest(dst, m)
    return dst, (ASSETS_DIR / entry["file"]).read_bytes()


def test_apply_to_assets_rewrites_the_file_and_its_manifest_entry_once(bloated_assets):
    dst, shipped = bloated_assets
    assert apply_to_assets(dst) == ["convlstm.int8.onnx"]
    assert (dst / "convlstm.int8.onnx").read_bytes() == shipped  # only opset_import changed
    verify_all(dst)  # sha256 and the file agree
    assert apply_to_assets(dst) == []


def test_cli_opsets(bloated_assets, capsys):
    from export.__main__ import main

    dst, _ = bloated_assets
    assert main(["opsets", "--assets", str(dst)]) == 0
    assert "rewrote convlstm.int8.onnx" in capsys.readouterr().out
    assert main(["opsets", "--assets", str(dst / "missing")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "missing" in err[0]
