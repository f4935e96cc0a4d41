"""export assets / compare-int8 end to end at toy scale (the real build: python -m export assets --seed 0)."""
import json

import numpy as np
import pytest

from edge_runtime.core.manifest import load_manifest, select_model, verify_all
from edge_runtime.wearable.classifier import Engine
from edge_runtime.wearable.labels import CLASSES


@pytest.fixture(scope="module")
def small_assets(tmp_path_factory):
    from export.assets import build_assets

    out = tmp_path_factory.mktemp("assets")
    work = tmp_path_factory.mktemp("work")
    (out / "vehicle_alerts.dbc").write_text("VERSION \"\"\n")  # other assets must survive a rebuild
    build_assets(seed=1, subjects=2, epochs=2, minutes=2.0, out=out, work=work,
                 variants=["qdq_conv", "qdq_conv+dyn_lstm"], command="test", log=lambda s: None, progress=False,
                 auto_loso=False, selection=_tiny_selection(work), early_min_agreement=TOY_AGREEMENT)
    return out, work


TOY_AGREEMENT = 0.95
"""A 2-epoch model on 2 subjects leaves many captures near a class boundary, where int8 may flip
them; the shipped build gates at 0.99 (export.assets.EARLY_MIN_AGREEMENT)."""


def _tiny_selection(work):
    """A selection.json of 2 simulated subjects (its captures are simulated on first use)."""
    p = work / "selection" / "selection.json"
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_text(json.dumps({"selection_seed": 1001, "subjects": 2, "minutes_per_trial": 2.0,
                             "recipe": {"captures": True, "shift_fwd": 20, "epochs": 2, "schedule_epochs": 3,
                                        "chosen_on": "test"}}))
    return p


@pytest.mark.slow
def test_assets_build_writes_a_valid_manifest(small_assets):
    out, _ = small_assets
    m = verify_all(out)
    assert (out / "vehicle_alerts.dbc").exists()
    assert [e["arch"] for e in m["models"]] == ["convlstm"] * 2 + ["convlstm_step"] * 2
    by = {e["precision"]: e for e in m["models"] if e["arch"] == "convlstm"}
    assert set(by) == {"fp32", "int8"}
    for e in by.values():
        assert e["arch"] == "convlstm" and e["classes"] == list(CLASSES)
        assert e["step_model"] == f"convlstm-step-{e['precision']}"
        assert e["parameters"] == {"torch": 79998, "keras": 79598}
        assert e["inputs"][0]["name"] == "imu" and e["inputs"][0]["shape"] == ["N", "S", 33, 3]
        early = e["early"]
        assert early["steps"] == [1, 2, 3, 4, 5, 6] and "selection cohort" in early["chosen_on"]
        assert set(early["temperature_by_steps"]) == set(early["min_confidence_by_steps"]) == set("123456")
        assert all(0.05 <= t <= 20 for t in early["temperature_by_steps"].values())
        assert all(0.0 <= c <= 1.0 for c in early["min_confidence_by_steps"].values())
        assert early["min_confidence_by_steps"]["1"] == 1.0 and early["alert_steps"] == [2, 3, 4, 5, 6]
        assert e["provenance"]["training"]["recipe"]["shift_fwd"] == 20
        prov = e["provenance"]
        assert prov["seed"] == 1 and prov["versions"]["onnxruntime"] and "command" in prov
        assert "macro_f1" in e["metrics"]["test_captures"]
    q = by["int8"]["quantization"]
    assert q["method"] in ("qdq_conv", "qdq_conv+dyn_lstm") and q["int8_operators"]["Conv"] == 2
    assert abs(by["int8"]["metrics"]["macro_f1_delta_vs_fp32"]) <= 0.01
    assert by["fp32"]["metrics"]["parity_vs_torch"]["ok"]
    assert min(by["int8"]["metrics"]["early_agreement_with_fp32_by_steps"].values()) >= TOY_AGREEMENT
    eng = Engine.from_manifest(out, "int8")
    for s in range(1, 7):  # the early decisions: the first S sub-windows
        assert eng.classify(np.zeros((s, 33, 3), np.float32)).shape == (len(CLASSES),)


@pytest.mark.slow
def test_assets_build_adds_the_step_model(small_assets):
    """Step 7: the streaming step model of the same weights, fp32 and int8, each hash-checked, linked from
    the one-shot entry of its precision, and the Engine decides by it."""
    out, _ = small_assets
    steps = {e["precision"]: e for e in verify_all(out)["models"] if e["arch"] == "convlstm_step"}
    assert set(steps) == {"fp32", "int8"}
    assert steps["fp32"]["metrics"]["parity_vs_torch"]["ok"]
    assert [i["name"] for i in steps["int8"]["inputs"]] == ["imu", "h", "c"]
    q = steps["int8"]["quantization"]
    assert min(q["agreement_by_steps"][str(s)] for s in range(2, 7)) >= TOY_AGREEMENT
    assert q["int8_operators"] and abs(q["macro_f1_delta"]) <= 0.01
    eng = Engine.from_manifest(out, "int8")
    assert eng.streaming and eng.step_model.source.endswith("convlstm_step.int8.onnx")
    assert not Engine.from_manifest(out, "int8", stream=False).streaming


@pytest.mark.slow
def test_rebuild_keeps_entries_of_other_models(small_assets, tmp_path):
    """A manifest entry this command does not build (e.g. a pose lifter) is kept on rebuild."""
    import shutil

    from edge_runtime.core.manifest import write_manifest
    from export.assets import build_assets

    out, work = small_assets
    dst = tmp_path / "assets"
    shutil.copytree(out, dst)
    m = load_manifest(dst)
    extra = dict(m["models"][0], name="lifter-fp32", arch="lifter")
    m["models"].append(extra)
    write_manifest(dst, m)
    build_assets(seed=1, subjects=2, epochs=2, minutes=2.0, out=dst, work=work, variants=["qdq_conv"],
                 command="test", log=lambda s: None, progress=False, auto_loso=False,
                 selection=work / "selection" / "selection.json", early_min_agreement=TOY_AGREEMENT)
    names = [e["name"] for e in load_manifest(dst)["models"]]
    assert sorted(names) == ["convlstm-fp32", "convlstm-int8", "convlstm-step-fp32", "convlstm-step-int8", "lifter-fp32"]
    # same seed, same data, same commit -> the same fp32 model bytes
    assert (dst / "convlstm.fp32.onnx").read_bytes() == (out / "convlstm.fp32.onnx").read_bytes()


def test_compare_int8_over_loso_folds(tmp_path, capsys):
    from export.__main__ import main
    from models.dataset import save_npz
    from models.experiments import run_loso
    from models.toy import toy_windows

    ws = toy_windows(n_per_class=12, n_classes=len(CLASSES), n_subjects=3, seed=2, classes=list(CLASSES))
    npz = save_npz(tmp_path / "train.npz", ws)
    from models.dataset import load_npz

    run_loso("convlstm", load_npz(npz), None, tmp_path / "loso", epochs=3, seed=0, jobs=1, progress=False,
             final_model=False)
    rc = main(["compare-int8", "--loso-dir", str(tmp_path / "loso"), "--method", "qdq_conv",
               "--json", str(tmp_path / "cmp.json")])
    r = json.loads((tmp_path / "cmp.json").read_text())
    assert r["folds"] == 3 and r["n"] == len(ws)
    assert {"fp32_macro_f1", "int8_macro_f1", "macro_f1_delta", "holds"} <= set(r)
    assert r["max_parity_torch_onnx"] < 1e-4
    assert rc == (0 if r["holds"] else 1)
    assert "LOSO over 3 folds" in capsys.readouterr().out


@pytest.mark.slow
def test_int8_requantises_the_shipped_fp32_without_training(small_assets, tmp_path):
    """`python -m export int8`: the int8 file and entry replaced, the fp32 file untouched, and the
    int8 bytes are what build_variant makes of the fp32 file with the entry's calibration windows."""
    import shutil

    from edge_runtime.wearable.classifier import preprocess
    from export.assets import calibration_windows, cohort_of, requantize
    from export.quantize import build_variant

    out, work = small_assets
    dst = tmp_path / "assets"
    shutil.copytree(out, dst)
    fp32_before = (dst / "convlstm.fp32.onnx").read_bytes()
    method = select_model(verify_all(dst), "convlstm-int8")["quantization"]["method"]  # what the toy build chose
    m = requantize(out=dst, work=work, variants=[method], command="test", early_min_agreement=TOY_AGREEMENT,
                   log=lambda s: None)
    by = {e["precision"]: e for e in m["models"] if e["arch"] == "convlstm"}
    assert by["int8"]["quantization"]["method"] == method
    assert by["int8"]["quantization"]["command"] == "test"
    assert by["int8"]["quantization"]["runtime_op_types"].get("QLinearConv", 0) >= 1
    assert (dst / "convlstm.fp32.onnx").read_bytes() == fp32_before
    verify_all(dst)  # the manifest's sha256 is the new file's
    train, _ = cohort_of(by["fp32"], work, log=lambda s: None)
    again = build_variant(dst / "convlstm.fp32.onnx", tmp_path / "again.onnx", method,
                          calibration_windows(preprocess(train.X), train.y, seed=1))
    assert again.read_bytes() == (dst / "convlstm.int8.onnx").read_bytes()


@pytest.mark.slow  # simulates the 20-subject cohort the shipped model was calibrated on (about a minute)
def test_requantising_the_shipped_fp32_gives_the_shipped_int8_bytes(tmp_path):
    from edge_runtime.core.manifest import ASSETS_DIR
    from edge_runtime.wearable.classifier import preprocess
    from export.assets import calibration_windows, cohort_of
    from export.quantize import build_variant

    m = verify_all(ASSETS_DIR)
    fp32, int8 = select_model(m, "convlstm-fp32"), select_model(m, "convlstm-int8")
    train, _ = cohort_of(fp32, tmp_path, log=lambda s: None)
    again = build_variant(ASSETS_DIR / fp32["file"], tmp_path / "int8.onnx", int8["quantization"]["method"],
                          calibration_windows(preprocess(train.X), train.y, seed=fp32["provenance"]["seed"]),
                          reduce_range=int8["quantization"].get("reduce_range", False))  # absent: built before 7-bit
    assert again.read_bytes() == (ASSETS_DIR / int8["file"]).read_bytes()


def test_the_shipped_int8_models_compute_on_this_cpu_what_their_graphs_say():
    """The integer kernels of this machine (QLinearConv, ...) against the same QDQ graphs computed in
    float: equal unless the CPU saturates int8 dot products (x86 without VNNI, 8-bit weights), in
    which case the box's int8 figures would not hold here."""
    from edge_runtime.core.manifest import ASSETS_DIR
    from export.quantize import integer_kernel_drift
    from export.runtime_check import fixed_inputs
    from models.pose_data import DataConfig, build_splits

    m = verify_all(ASSETS_DIR)
    feed = fixed_inputs(m, n=64)  # ConvLSTM: m/s^2 around gravity
    poses = build_splits(DataConfig(train_subjects=1, test_subjects=1, seconds_per_subject=6, train_cameras=1,
                                    test_cameras=1, views=1, seed=3))["test"]  # the lifter: simulated keypoints
    feed["lifter-int8/keypoints_2d"] = poses.windows(np.flatnonzero(poses.valid)[::3][:64]).astype(np.float32)
    int8 = [e for e in m["models"] if e["precision"] == "int8"]
    assert {e["arch"] for e in int8} == {"convlstm", "convlstm_step", "lifter", "stream"}
    for e in int8:
        f = {s["name"]: feed[f"{e['name']}/{s['name']}"] for s in e["inputs"]}
        assert integer_kernel_drift(ASSETS_DIR / e["file"], f) < 1e-4, e["name"]
