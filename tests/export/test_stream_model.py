"""export/stream_model.py: the streaming classifier's ONNX graphs and manifest entries (issue 12). The shipped
stream-fp32 and stream-int8 must agree on the top class of a small fixture of windows the runtime makes; an export
adds its two entries and leaves every other entry and file of the assets as it was."""
import json
import shutil

import numpy as np
import pytest
import torch

from edge_runtime.core.manifest import ASSETS_DIR, STREAM_ARCH, load_manifest, sha256_file
from edge_runtime.wearable.labels import CLASSES
from edge_runtime.wearable.sources import ImuBlock
from edge_runtime.wearable.stream_decider import StreamLoop, StreamModel, StreamParams
from export import stream_model
from export.onnx_export import ExportError
from models.stream_net import StreamNet
from models.train import save_checkpoint

MIN_AGREEMENT = 0.99


class Both:
    """The two shipped stream models on every window the runtime's decider makes: their top classes."""

    classes = CLASSES

    def __init__(self):
        self.fp32 = StreamModel.from_manifest(ASSETS_DIR, "stream-fp32")
        self.int8 = StreamModel.from_manifest(ASSETS_DIR, "stream-int8")
        self.tops = []

    def classify_window(self, window):
        p = self.fp32.classify_window(window).copy()
        self.tops.append((int(p.argmax()), int(self.int8.classify_window(window).argmax())))
        return p


@pytest.fixture(scope="module")
def fixture_stream():
    """Four minutes of a training-cohort subject's distraction trial (cohort seed 0: no evaluation drive)."""
    from firmware_sim.devices.wrist import make_subjects, simulate_trial

    return simulate_trial(make_subjects(1, seed=0)[0], "exp1", 0, minutes=4.0).acc_mps2


def test_the_shipped_int8_stream_model_agrees_with_fp32_on_the_runtimes_windows(fixture_stream):
    both = Both()
    StreamLoop(both, StreamParams()).feed(ImuBlock(0.0, fixture_stream))
    tops = np.asarray(both.tops)
    assert len(tops) >= 400  # every 0.48 s of 4 min after the first 4 s
    assert len(set(tops[:, 0])) >= 3  # the fixture is not one class throughout
    assert np.mean(tops[:, 0] == tops[:, 1]) >= MIN_AGREEMENT


def test_the_shipped_stream_entries_say_what_they_were_built_from():
    entries = {e["name"]: e for e in load_manifest(ASSETS_DIR)["models"] if e["arch"] == STREAM_ARCH}
    assert set(entries) == {"stream-fp32", "stream-int8"}
    for e in entries.values():
        assert e["classes"] == list(CLASSES) and e["parameters"] == {"torch": 71_142, "width": 64}
        assert e["provenance"]["training"].startswith("python -m models stream-train")
        assert e["provenance"]["command"].startswith("python -m export stream")
    assert entries["stream-int8"]["metrics"]["agreement_with_fp32"] >= MIN_AGREEMENT


def _tiny_checkpoint(tmp_path):
    torch.manual_seed(0)
    net = StreamNet(width=8).eval()
    return save_checkpoint(tmp_path / "m", net, arch="stream", classes=CLASSES, seed=0, epochs=1, metrics={},
                           data={"cohort_seed": 0, "subjects": 1, "minutes_per_trial": 1.0}), net


def test_the_fp32_graph_is_the_torch_net_at_every_window_length(tmp_path):
    _, net = _tiny_checkpoint(tmp_path)
    onx = stream_model.to_stream_onnx(net, CLASSES, {})
    x = np.random.default_rng(0).normal(0, 3, (8, 100, 3)).astype(np.float32) + np.float32([0, 0, 9.81])
    parity = stream_model.stream_parity(net, onx, [np.ascontiguousarray(x[:, -t:]) for t in (50, 75, 100)])
    assert parity["ok"] and parity["max_abs_probs"] < 1e-5


def test_an_export_adds_its_two_entries_and_leaves_the_others_as_they_were(tmp_path, monkeypatch):
    assets = tmp_path / "assets"
    shutil.copytree(ASSETS_DIR, assets)
    before = {e["name"]: e for e in load_manifest(assets)["models"] if e["arch"] != STREAM_ARCH}
    files = {p.name: sha256_file(p) for p in assets.iterdir() if not p.name.startswith(("manifest", STREAM_ARCH))}
    ckpt, _ = _tiny_checkpoint(tmp_path)
    rng = np.random.default_rng(1)

    def windows(n, seed, window_s):  # stands in for the simulated cohort (30 s): the bookkeeping is tested here
        return rng.normal(0, 3, (n, 100, 3)).astype(np.float32) + np.float32([0, 0, 9.81]), rng.integers(0, 6, n)

    monkeypatch.setattr(stream_model, "cohort_windows", windows)
    monkeypatch.setattr(stream_model, "git_commit", lambda: "0" * 40)  # no git process in a fast test
    monkeypatch.setattr(stream_model, "N_CALIB", 64)
    monkeypatch.setattr(stream_model, "N_GATE", 256)
    monkeypatch.setattr(stream_model, "MIN_AGREEMENT", 0.0)  # an untrained net's near-ties: not the gate's test
    stream_model.build_stream_assets(ckpt, assets, command="python -m export stream --checkpoint X", log=lambda s: None)
    after = load_manifest(assets)["models"]
    assert {e["name"]: e for e in after if e["arch"] != STREAM_ARCH} == before
    assert {p.name: sha256_file(p) for p in assets.iterdir() if p.name in files} == files
    new = {e["name"]: e for e in after if e["arch"] == STREAM_ARCH}
    assert set(new) == {"stream-fp32", "stream-int8"}
    for name, e in new.items():
        assert sha256_file(assets / e["file"]) == e["sha256"]
        assert StreamModel.from_manifest(assets, name).classes == list(CLASSES)


def test_figures_go_to_the_entry_of_the_model_that_made_them(tmp_path):
    assets = tmp_path / "assets"
    shutil.copytree(ASSETS_DIR, assets)
    int8 = next(e for e in load_manifest(assets)["models"] if e["name"] == "stream-int8")
    score = {"event_recall": 0.96, "first_alert_class_accuracy": 0.94, "onset_to_first_alert_s": {"median": 2.5},
             "false_alerts_per_hour": 1.9, "false_alerts": 38, "repeat_alerts": 3, "distractions": 1655,
             "driving_hours": 20.0}
    report = {"seed": 5, "command": "python -m firmware_sim drive-eval ...", "scores": {"stream": score},
              "stream_path": {"sha256": int8["sha256"], "settings": {"threshold": 0.7}}}
    (tmp_path / "r.json").write_text(json.dumps(report))
    stream_model.add_figures(assets, [tmp_path / "r.json"], log=lambda s: None)
    got = next(e for e in load_manifest(assets)["models"] if e["name"] == "stream-int8")["metrics"]["drives"]["seed 5"]
    assert got["event_recall"] == 0.96 and got["stream"] == {"threshold": 0.7}
    report["stream_path"]["sha256"] = "0" * 64
    (tmp_path / "r.json").write_text(json.dumps(report))
    with pytest.raises(ExportError, match="is no stream model"):
        stream_model.add_figures(assets, [tmp_path / "r.json"], log=lambda s: None)
