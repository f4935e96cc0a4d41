"""``python -m export lifter-int8`` on a tiny lifter: the shipped fp32 file quantised again, without training.

Its "shipped" assets are made here as ``python -m export lifter`` makes them (an fp32 export, the int8 recipe
``qdq_pt`` with 8-bit weights as the shipped lifter's entry records, calibrated on the training split of the
recipe its provenance names), so that the command must rebuild that int8 file byte for byte."""
from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from edge_runtime.core.manifest import SCHEMA_VERSION, load_manifest, sha256_file, write_manifest
from edge_runtime.robot.lifter import LifterParams, StreamingLifter
from export.__main__ import _parser, main
from export.lifter_assets import (
    CANDIDATES,
    FOLDED_CENTERING,
    _slim,
    calibration_windows,
    export_onnx,
    manifest_entries,
    onnx_runner,
    simulate,
)

TINY_DATA = dict(train_scenes=1, val_scenes=1, test_scenes=1, seconds_per_scene=4.0, train_cameras=1,
                 eval_cameras=1, seed=3)


@pytest.fixture(scope="module")
def shipped(tmp_path_factory):
    """A tiny lifter's assets directory (fp32 + int8 + manifest), and the work directory holding its data."""
    import torch

    from export.quantize import build_variant, int8_report
    from models.lifter import LifterConfig, LifterNet
    from models.lifter_train import evaluate
    from models.pose_data import VariedConfig

    d = tmp_path_factory.mktemp("lifter_int8")
    assets, work = d / "assets", d / "work"
    dcfg = VariedConfig(**TINY_DATA)
    splits = simulate(dcfg)
    for name, ps in splits.items():  # what the command would simulate: kept so that it need not
        work.mkdir(exist_ok=True)
        ps.save(work / f"{name}.npz")
    torch.manual_seed(0)
    mcfg = LifterConfig(channels=8, trajectory_channels=8)
    model = LifterNet(mcfg).eval()
    fp32 = export_onnx(model, assets / "lifter.fp32.onnx", {"arch": "lifter", "precision": "fp32"})
    qdq_pt = next(v for v in CANDIDATES if v.name == "qdq_pt")
    int8 = build_variant(fp32, assets / "lifter.int8.onnx", qdq_pt, calibration_windows(splits["train"]),
                         describe=False, reduce_range=False)
    scores = {p: {s: _slim(evaluate(None, splits[s], 1000, runner=onnx_runner(f))) for s in ("val", "test")}
              for p, f in (("fp32", fp32), ("int8", int8))}
    row = {"channels": 8, "config": mcfg.to_dict(), "parameters": model.parameter_counts(), **scores,
           "parity": {}, "latency": {"fp32": {}, "int8": {}},
           # as the shipped entry: no reduce_range (8-bit weights)
           "quantization": {"method": "qdq_pt", "description": qdq_pt.description, **int8_report(int8)}}
    prov = {"seed": 3, "data": dcfg.to_dict(), "version": "0.0.0"}
    write_manifest(assets, {"version": SCHEMA_VERSION, "created_by": "test",
                            "models": manifest_entries(row, fp32, int8, prov)})
    return assets, work


def _run(*args) -> int:
    return main(["lifter-int8", *map(str, args), "--latency-runs", "20", "--no-progress"])


def _entry(out, name="lifter-int8") -> dict:
    return next(e for e in load_manifest(out)["models"] if e["name"] == name)


def test_default_rebuilds_the_shipped_int8_file_byte_for_byte(shipped, tmp_path):
    assets, work = shipped
    assert _run("--assets", assets, "--out", tmp_path, "--work", work) == 0
    assert sha256_file(tmp_path / "lifter.int8.onnx") == sha256_file(assets / "lifter.int8.onnx")
    new, old = _entry(tmp_path), _entry(assets)
    assert new["sha256"] == old["sha256"]
    q = new["quantization"]
    assert q["method"] == "qdq_pt" and q["reduce_range"] is False and q["rebuilt_from"]["same_bytes"]
    assert q["input_centering"] == "in the graph, as exported"
    assert q["calibration"] == old["quantization"].get("calibration", q["calibration"])
    # scored on the validation split only, and the same file scores the same
    assert set(new["metrics"]["held_out"]) == {"val"}
    assert new["metrics"]["held_out"]["val"]["mpjpe_mm"] == old["metrics"]["held_out"]["val"]["mpjpe_mm"]
    assert _entry(tmp_path, "lifter-fp32") == _entry(assets, "lifter-fp32")  # the fp32 entry and file as shipped
    assert sha256_file(tmp_path / "lifter.fp32.onnx") == sha256_file(assets / "lifter.fp32.onnx")


def test_fold_centering_builds_the_folded_candidate_the_runtime_loads(shipped, tmp_path):
    assets, work = shipped
    assert _run("--assets", assets, "--out", tmp_path, "--work", work, "--fold-centering") == 0
    new, old = _entry(tmp_path), _entry(assets)
    assert new["sha256"] == sha256_file(tmp_path / "lifter.int8.onnx") != old["sha256"]
    q = new["quantization"]
    assert q["input_centering"] == FOLDED_CENTERING and not q["rebuilt_from"]["same_bytes"]
    # the folded graph's default recipe leaves the pose branch's output convolution fp32
    assert q["kept_fp32"] == ["/pose/shrink/Conv"] and q["fp32_operators"].get("Conv") == 1
    before = load_manifest(assets)  # the assets it read are untouched
    assert [e["sha256"] for e in before["models"]] == [sha256_file(assets / e["file"]) for e in before["models"]]
    # the centering's quantise / slice / subtract glue is gone from what onnxruntime runs
    runtime = sum(q["runtime_op_types"].values())
    assert runtime < sum(old["quantization"]["runtime_op_types"].values())
    assert "Sub" not in q["int8_operators"] and {"held_out", "rule_vs_fp32", "latency_1thread_us"} <= set(new["metrics"])
    lifter = StreamingLifter.from_manifest(tmp_path, LifterParams(precision="int8"), keypoint_format="h36m")
    kp = np.column_stack([np.linspace(600, 680, 17), np.linspace(250, 470, 17), np.full(17, 0.9)])
    assert lifter.push(0.0, kp).valid


def test_keep_fp32_none_quantises_every_node_of_the_folded_graph(shipped, tmp_path):
    assets, work = shipped
    assert _run("--assets", assets, "--out", tmp_path, "--work", work, "--fold-centering", "--keep-fp32", "none") == 0
    q = _entry(tmp_path)["quantization"]
    assert "kept_fp32" not in q and "Conv" not in q["fp32_operators"] and q["input_centering"] == FOLDED_CENTERING


def test_the_default_is_the_unfolded_recipe():
    args = _parser().parse_args(["lifter-int8", "--out", "x"])
    assert args.fold_centering is False and args.keep_fp32 is None
    assert _parser().parse_args(["lifter-int8", "--out", "x", "--fold-centering"]).fold_centering is True


def _bad_manifest(assets, tmp_path, change):
    d = tmp_path / "bad"
    shutil.copytree(assets, d)
    m = json.loads((d / "manifest.json").read_text())
    change(next(e for e in m["models"] if e["name"] == "lifter-int8"),
           next(e for e in m["models"] if e["name"] == "lifter-fp32"))
    (d / "manifest.json").write_text(json.dumps(m))
    return d


def _set_method(i8, f32):
    i8["quantization"]["method"] = "qdq_per_row"


def _other_data(i8, f32):
    f32["metrics"]["held_out"]["val"]["mpjpe_mm"] += 5.0


def _no_data(i8, f32):
    del f32["provenance"]["data"]


@pytest.mark.parametrize("args, change, field", [
    (["--out", "{assets}"], None, "--out"),
    (["--out", "{tmp}/o", "--splits", "train"], None, "--splits"),
    (["--out", "{tmp}/o", "--splits", ","], None, "--splits"),
    (["--out", "{tmp}/o"], _set_method, "quantization.method"),
    (["--out", "{tmp}/o"], _other_data, "not the ones the lifter was exported on"),
    (["--out", "{tmp}/o"], _no_data, "provenance.data"),
    (["--out", "{tmp}/o", "--assets", "{tmp}/nowhere"], None, "manifest not found"),
])
def test_bad_input_is_one_line_and_exit_2(shipped, tmp_path, capsys, args, change, field):
    assets, work = shipped
    if change is not None:
        assets = _bad_manifest(assets, tmp_path, change)
    argv = [a.format(assets=assets, tmp=tmp_path) for a in args]
    if "--assets" not in argv:
        argv += ["--assets", str(assets)]
    capsys.readouterr()
    assert _run(*argv, "--work", work) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("error:") and field in err
    assert not (tmp_path / "o" / "lifter.int8.onnx").exists() or change is _other_data
