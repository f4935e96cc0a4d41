"""edge_runtime.wearable.classifier + core.onnx + core.manifest: the capture -> model-input path (scipy's
anti-aliased polyphase resampler, then 6 x 33), hash-checked loading, session settings, classify shapes, bad input."""
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import signal
from support import REPO_ROOT
from support.drive import drive_captures
from support.early_model import engine as early_engine

from edge_runtime.core.manifest import (
    ASSETS_DIR,
    SCHEMA_VERSION,
    ManifestError,
    ModelIntegrityError,
    load_manifest,
    select_model,
    sha256_file,
    write_manifest,
)
from edge_runtime.core.onnx import session_options
from edge_runtime.wearable.classifier import (
    MEAN_EDGE_FRAMES,
    Engine,
    calibrate,
    needed_frames,
    preprocess,
    preprocess_prefix,
    preprocess_prefix_steps,
    preprocess_prefixes,
    resample_capture,
    resample_matrix,
    resample_poly,
    to_subsequences,
)
from edge_runtime.wearable.labels import CLASSES

ROOT = REPO_ROOT


# ---------------------------------------------------------------------------- capture -> model input


def test_matches_scipy_resample_poly():
    rng = np.random.default_rng(0)
    x = rng.normal(0, 3, size=(4, 700, 3)) + np.array([9.8, -1.0, 2.0])
    ref = signal.resample_poly(x, 2, 7, axis=1, padtype="mean")
    np.testing.assert_allclose(resample_capture(x), ref, atol=2e-5)


def test_anti_aliasing_rejects_above_new_nyquist_and_keeps_low_band():
    t = np.arange(700) / 100.0
    low = np.sin(2 * np.pi * 2.0 * t)  # 2 Hz: kept
    high = np.sin(2 * np.pi * 20.0 * t)  # 20 Hz > 14.3 Hz Nyquist of 200/7 Hz: removed
    x = np.stack([low, high, np.zeros_like(t)], axis=1)
    y = resample_capture(x)[20:-20]  # away from the edges
    assert np.abs(y[:, 1]).max() < 0.01
    assert 0.95 < np.abs(y[:, 0]).max() < 1.05


def test_dc_gain_is_one_and_constant_gravity_survives():
    x = np.tile([0.5, -2.0, 9.81], (700, 1))
    np.testing.assert_allclose(resample_capture(x), np.tile([0.5, -2.0, 9.81], (200, 1)), atol=1e-5)
    assert np.allclose(resample_matrix().sum(axis=1)[30:-30], 1.0, atol=1e-3)  # polyphase ripple


def test_reshape_order_is_subsequence_frame_axis():
    x200 = np.arange(200 * 3, dtype=np.float32).reshape(200, 3)
    s = to_subsequences(x200)
    assert s.shape == (6, 33, 3)
    np.testing.assert_array_equal(s[1, 0], x200[33])
    np.testing.assert_array_equal(s[5, 32], x200[197])
    assert preprocess(np.zeros((2, 700, 3))).shape == (2, 6, 33, 3)


def test_wrong_length_is_refused():
    with pytest.raises(ValueError, match="700"):
        resample_capture(np.zeros((699, 3)))


@pytest.mark.parametrize("up,down", [(1, 2), (2, 1), (4, 5), (2, 7)])
def test_stream_resampler_matches_scipy(up, down):
    x = np.random.default_rng(up * 10 + down).normal(size=(3001, 3)) + 9.0
    ref = signal.resample_poly(x, up, down, axis=0, padtype="mean")
    np.testing.assert_allclose(resample_poly(x, up, down), ref, atol=1e-9)


# ---------------------------------------------------------------------------- the ONNX engine


@pytest.fixture(scope="module")
def assets(tmp_path_factory):
    """fp32 + int8 ConvLSTM (random weights) with a manifest, built with export/."""
    import torch

    from export.onnx_export import example_input, save_onnx, to_onnx
    from export.quantize import build_variant
    from models.nets import build

    d = tmp_path_factory.mktemp("assets")
    torch.manual_seed(0)
    m = build("convlstm", len(CLASSES)).eval()
    fp = save_onnx(to_onnx(m, CLASSES, commit=""), d / "convlstm.fp32.onnx")
    q = build_variant(fp, d / "convlstm.int8.onnx", "qdq_conv", example_input(64))
    entries = [{"name": f"convlstm-{p}", "file": f.name, "sha256": sha256_file(f), "precision": p,
                "arch": "convlstm", "parameters": {"torch": 79998, "keras": 79598}, "classes": list(CLASSES),
                "inputs": [{"name": "imu", "shape": ["N", 6, 33, 3], "dtype": "float32"}],
                "outputs": [{"name": "probs", "shape": ["N", 6], "dtype": "float32"}]}
               for f, p in ((fp, "fp32"), (q, "int8"))]
    write_manifest(d, {"version": SCHEMA_VERSION, "created_by": "test", "models": entries})
    return d


def _copy(src: Path, dst: Path) -> Path:
    shutil.copytree(src, dst)
    return dst


def test_load_by_precision_and_name(assets):
    e8 = Engine.from_manifest(assets, "int8")
    assert e8.precision == "int8" and e8.name == "convlstm-int8" and e8.classes == list(CLASSES)
    e32 = Engine.from_manifest(assets, "convlstm-fp32")
    assert e32.precision == "fp32"
    assert e8.metadata["arch"] == "convlstm" and json.loads(e8.metadata["classes"]) == list(CLASSES)


def test_session_settings(assets):
    e = Engine.from_manifest(assets, "int8", threads=2)
    so = e.session.get_session_options()
    assert so.intra_op_num_threads == 2 and so.inter_op_num_threads == 1
    assert so.get_session_config_entry("session.intra_op.allow_spinning") == "0"
    assert e.session.get_providers() == ["CPUExecutionProvider"]
    with pytest.raises(ValueError):
        session_options(0)


def test_classify_shapes_and_capture_path(assets):
    e = Engine.from_manifest(assets, "fp32")
    rng = np.random.default_rng(0)
    x700 = (rng.normal(0, 2, (3, 700, 3)) + [0, 0, 9.81]).astype(np.float32)
    x = preprocess(x700)
    p1 = e.classify(x[0])
    assert p1.shape == (len(CLASSES),) and abs(float(p1.sum()) - 1) < 1e-5
    pn = e.classify(x)
    assert pn.shape == (3, len(CLASSES))
    np.testing.assert_allclose(pn[0], p1, atol=1e-6)
    np.testing.assert_allclose(e.classify_capture(x700), pn, atol=1e-6)
    np.testing.assert_allclose(e.classify_capture(x700[1]), pn[1], atol=1e-6)
    assert e.classify(x[:0]).shape == (0, len(CLASSES))
    assert e.classify(x.astype(np.float64)).dtype == np.float32
    assert e.predict(x[0]) in CLASSES and len(e.predict(x)) == 3
    assert e.classify(np.asfortranarray(x[0])).shape == (len(CLASSES),)


@pytest.mark.parametrize("bad", [np.zeros((6, 33, 2)), np.zeros((2, 6, 32, 3)), np.zeros((33, 3)),
                                 np.full((6, 33, 3), np.nan)])
def test_classify_refuses_bad_input(assets, bad):
    e = Engine.from_manifest(assets, "int8")
    with pytest.raises(ValueError):
        e.classify(bad)


def test_sha_mismatch_is_refused_naming_the_file(assets, tmp_path):
    d = _copy(assets, tmp_path / "a")
    f = d / "convlstm.int8.onnx"
    data = bytearray(f.read_bytes())
    data[len(data) // 2] ^= 0x01
    f.write_bytes(bytes(data))
    with pytest.raises(ModelIntegrityError, match="convlstm.int8.onnx.*sha256 mismatch"):
        Engine.from_manifest(d, "int8")
    Engine.from_manifest(d, "fp32")  # the untouched model still loads


def test_missing_and_malformed_manifests(assets, tmp_path):
    with pytest.raises(ManifestError, match="manifest not found"):
        Engine.from_manifest(tmp_path, "int8")
    d = _copy(assets, tmp_path / "b")
    (d / "convlstm.fp32.onnx").unlink()
    with pytest.raises(ModelIntegrityError, match="convlstm.fp32.onnx.*missing"):
        Engine.from_manifest(d, "fp32")
    (d / "manifest.json").write_text("{not json")
    with pytest.raises(ManifestError, match="manifest.json"):
        load_manifest(d)
    m = load_manifest(assets)
    m["models"][0]["file"] = "../escape.onnx"
    (d / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(ManifestError, match="file"):
        load_manifest(d)
    m = load_manifest(assets)
    m["version"] = 99
    (d / "manifest.json").write_text(json.dumps(m))
    with pytest.raises(ManifestError, match="version"):
        load_manifest(d)
    with pytest.raises(ManifestError, match="int4"):
        select_model(load_manifest(assets), "int4")


def test_classes_disagreeing_with_model_metadata_are_refused(assets, tmp_path):
    d = _copy(assets, tmp_path / "c")
    m = load_manifest(d)
    for e in m["models"]:
        e["classes"] = list(reversed(e["classes"]))
    write_manifest(d, m)
    with pytest.raises(ModelIntegrityError, match="classes"):
        Engine.from_manifest(d, "int8")


def _assert_cli_refuses_tampered(d: Path, model_file: str, tmp_path: Path, *flags: str) -> None:
    """``python -m edge_runtime wearable`` on the assets ``d`` with ``model_file`` overwritten: refused in one line."""
    (d / model_file).write_bytes(b"\x00" * 100)
    csv = tmp_path / "rec.csv"
    t = np.arange(300) / 100
    rows = "\n".join(f"{ti:.2f},0.0,0.0,9.81" for ti in t)
    csv.write_text("t,ax,ay,az\n" + rows + "\n")
    r = subprocess.run([sys.executable, "-m", "edge_runtime", "wearable", "--replay", str(csv), "--assets", str(d),
                        *flags], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert r.returncode != 0
    err = r.stderr.strip()
    assert "Traceback" not in err and "sha256 mismatch" in err and model_file in err


@pytest.mark.slow
def test_wearable_cli_refuses_tampered_model_in_one_line(assets, tmp_path):
    _assert_cli_refuses_tampered(_copy(assets, tmp_path / "d"), "convlstm.int8.onnx", tmp_path, "--decision", "early")


@pytest.mark.slow
@pytest.mark.skipif(not (ASSETS_DIR / "manifest.json").exists(), reason="no shipped assets")
def test_wearable_cli_by_default_refuses_a_tampered_stream_model_in_one_line(tmp_path):
    """The default decider loads the streaming classifier, hash-checked like the capture path's."""
    _assert_cli_refuses_tampered(_copy(ASSETS_DIR, tmp_path / "d"), "stream.int8.onnx", tmp_path)


@pytest.mark.skipif(not (ASSETS_DIR / "manifest.json").exists(), reason="no shipped assets")
def test_shipped_manifest_describes_its_models():
    m = load_manifest(ASSETS_DIR)
    by = {e["precision"]: e for e in m["models"] if e["arch"] == "convlstm"}
    assert {"fp32", "int8"} <= set(by)
    for e in by.values():
        assert sha256_file(ASSETS_DIR / e["file"]) == e["sha256"]
        assert e["parameters"] == {"torch": 79998, "keras": 79598}
        assert "macro_f1" in e["metrics"]["test_captures"]
        assert e["provenance"]["seed"] is not None and e["provenance"]["versions"]["onnxruntime"]
    q = by["int8"]["quantization"]
    assert q["int8_operators"] and q["method"]
    assert abs(by["int8"]["metrics"]["macro_f1_delta_vs_fp32"]) <= 0.01


# ---------------------------------------------------------------------------- early decisions (partial captures)


def _capture(seed: int = 0) -> np.ndarray:
    """A capture with the hand moving: gravity swings between the axes, as a reach does."""
    rng = np.random.default_rng(seed)
    t = np.arange(700) / 100.0
    lift = 1 / (1 + np.exp(-(t - 2.0) * 3))
    x = np.stack([9.81 * np.sin(lift), 2 * np.sin(3 * t), 9.81 * np.cos(lift)], axis=1)
    return (x + rng.normal(0, 0.3, x.shape)).astype(np.float32)


def test_needed_frames_are_the_last_raw_frames_the_first_s_subwindows_read():

    assert [needed_frames(s) for s in range(1, 7)] == [148, 263, 379, 494, 610, 700]
    m = resample_matrix()
    for s in range(1, 7):  # nothing after needed_frames(s) reaches the first s * 33 resampled frames
        assert not m[: s * 33, needed_frames(s):].any() and m[: s * 33, needed_frames(s) - 1].any()
    with pytest.raises(ValueError):
        needed_frames(0)


@pytest.mark.parametrize("steps", [1, 2, 3, 4, 5, 6])
def test_a_prefix_gives_the_full_preprocessing_of_its_subwindows(steps):

    x = _capture(steps)
    full = preprocess(x)[:steps].reshape(-1, 3)
    part = preprocess_prefix(x[: needed_frames(steps)], steps)
    assert part.shape == (steps, 33, 3)
    part = part.reshape(-1, 3)
    if steps == 6:  # the whole capture: exactly preprocess
        np.testing.assert_array_equal(part, full)
        return
    # Only the mean padding differs: row j is off by (mean of the padded prefix - mean of the capture)
    # times (1 - the row's sum), which is within 4e-5 of 0 from MEAN_EDGE_FRAMES on.
    rows = 1 - resample_matrix().sum(axis=1)[: steps * 33, None]
    x64 = x.astype(np.float64)
    padded = np.concatenate([x64[: needed_frames(steps)], np.repeat(x64[needed_frames(steps) - 1 : needed_frames(steps)],
                                                                   700 - needed_frames(steps), axis=0)])
    bound = np.abs(rows) * np.abs(padded.mean(axis=0) - x64.mean(axis=0)) + 2e-5  # + float32 rounding
    assert (np.abs(part - full) <= bound).all()
    assert np.abs(rows[MEAN_EDGE_FRAMES:]).max() < 4e-5 < 1e-3 < np.abs(rows[MEAN_EDGE_FRAMES - 1])
    np.testing.assert_allclose(part[MEAN_EDGE_FRAMES:], full[MEAN_EDGE_FRAMES:], rtol=0, atol=1e-3)
    with pytest.raises(ValueError):
        preprocess_prefix(x[: needed_frames(steps) - 1], steps)


def test_a_dynamic_s_model_decides_on_prefixes_with_the_manifests_temperature():

    eng = early_engine(early={"steps": [2, 3, 4, 5, 6], "temperature_by_steps": {"2": 2.0},
                        "min_confidence_by_steps": {"2": 0.8}})
    assert eng.early_steps == (2, 3, 4, 5, 6) and eng.early.min_confidence_by_steps == {2: 0.8}
    x = _capture(1)
    raw2 = eng.classify(preprocess_prefix(x[: needed_frames(2)], 2))
    got2 = eng.classify_prefix(x[: needed_frames(2)], 2)
    want2 = np.exp(np.log(raw2) / 2.0) / np.exp(np.log(raw2) / 2.0).sum()
    np.testing.assert_allclose(got2, want2, rtol=1e-5)
    assert got2.max() < raw2.max()  # T > 1 softens
    np.testing.assert_allclose(eng.classify_prefix(x, 6), eng.classify_capture(x), rtol=1e-6)  # no T for S = 6
    assert not np.allclose(eng.classify_prefix(x[: needed_frames(3)], 3), eng.classify_capture(x))
    with pytest.raises(ValueError):
        eng.classify_prefix(x[: needed_frames(1)], 1)  # not among the manifest's steps
    np.testing.assert_allclose(calibrate(raw2, 1.0), raw2)


def test_a_fixed_s_model_decides_on_the_full_window_only_whatever_the_manifest_says():

    assert early_engine(dynamic=False, early={"steps": [1, 2, 3]}).early_steps == (6,)
    assert early_engine(dynamic=True).early_steps == (1, 2, 3, 4, 5, 6)  # dynamic S, no manifest 'early'
    shipped = Engine.from_manifest(ASSETS_DIR, "int8")
    assert shipped.early_steps == (1, 2, 3, 4, 5, 6)  # the shipped model: S dynamic, every step in its manifest


@pytest.mark.parametrize("early", [{"steps": [0, 2]}, {"temperature_by_steps": {"2": 0}}, {"steps": "x"},
                                   {"min_confidence_by_steps": {"3": 1.5}}])
def test_a_malformed_early_object_is_refused(early):

    with pytest.raises(ModelIntegrityError, match="early"):
        early_engine(early=early)


def test_calibrating_one_decision_gives_the_batch_path_s_float32_values():
    """The loop calibrates one probability vector at a time in Python floats; a batch goes through
    numpy. Both are softmax(log p / T) and give the same float32 values."""
    rng = np.random.default_rng(4)
    probs = rng.dirichlet(np.full(6, 0.3), size=5000).astype(np.float32)
    probs[0] = [1.0, 0, 0, 0, 0, 0]  # a zero probability: clipped to 1e-12, as in the batch path
    for t in (0.6357, 0.8944, 1.2611):
        batch = calibrate(probs, t)
        single = np.stack([calibrate(p, t) for p in probs])
        np.testing.assert_array_equal(single, batch)
        logp = np.log(np.clip(probs.astype(np.float64), 1e-12, 1.0)) / t
        want = np.exp(logp - logp.max(1, keepdims=True))
        np.testing.assert_allclose(batch, want / want.sum(1, keepdims=True), rtol=1e-6, atol=1e-30)


def test_prefixes_preprocessed_together_are_each_one_preprocessed_alone_bit_for_bit():
    """The replay preprocesses the captures of a block together, every step from one product of the
    resampler; each prefix's model input must be exactly what the per-capture path gives it."""
    caps = drive_captures()
    assert len(caps) >= 20
    steps = (1, 2, 3, 4, 5, 6)
    together = preprocess_prefix_steps(caps, steps)
    for s, got in zip(steps, together):
        n = needed_frames(s)
        alone = np.stack([preprocess_prefix(c[:n], s) for c in caps])
        np.testing.assert_array_equal(got, alone)
        np.testing.assert_array_equal(preprocess_prefixes(caps[:, :n], s), alone)
    for s, got in zip((2, 5), preprocess_prefix_steps(caps[:3], (2, 5))):  # any subset of steps
        np.testing.assert_array_equal(got, together[s - 1][:3])
    longer = np.stack([preprocess_prefix(c[:650], 4) for c in caps[:4]])  # a prefix longer than it needs
    np.testing.assert_array_equal(preprocess_prefixes(caps[:4, :650], 4), longer)
    with pytest.raises(ValueError):
        preprocess_prefix_steps(caps[:, :600], (2, 6))  # S = 6 needs every frame


def test_the_shipped_model_classifies_a_batch_as_each_capture_alone():
    """One model run for many captures (a replay's block) gives each the probabilities it gets alone,
    to the last bit: onnxruntime computes each item of a batch as it computes it alone."""
    eng = Engine.from_manifest(ASSETS_DIR, "int8")
    caps = drive_captures()
    groups = [(caps[:-3], (2, 3, 4, 5, 6)), (caps[-3:], (6,)), (caps[:1], (3, 6))]
    got = eng.classify_capture_groups(groups)
    for (captures, steps), by_steps in zip(groups, got):
        assert sorted(by_steps) == list(steps)
        for s in steps:
            n = needed_frames(s)
            alone = np.stack([eng.classify_prefix(c[:n], s) for c in captures])
            np.testing.assert_array_equal(by_steps[s], alone)
            np.testing.assert_array_equal(eng.classify_prefixes(captures[:, :n], s), alone)
