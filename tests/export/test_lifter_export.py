"""`python -m export lifter` end to end on a tiny configuration (tens of seconds)."""
import json
import shutil
import subprocess
import sys

import numpy as np
import pytest
from support import REPO_ROOT

from edge_runtime.core.manifest import load_manifest, sha256_file
from edge_runtime.robot.lifter import LifterParams, StreamingLifter

pytestmark = pytest.mark.slow  # every test here starts a process

REPO = REPO_ROOT
TINY = ["--channels", "16", "--trajectory-channels", "16", "--subjects", "2", "--test-subjects", "1",
        "--seconds", "10", "--cameras", "2", "--test-cameras", "1", "--views", "1", "--epochs", "1",
        "--eval-frames", "200", "--latency-runs", "30", "--no-progress"]


def _run(*args, cwd=REPO):
    return subprocess.run([sys.executable, "-m", "export", "lifter", *args], cwd=cwd, capture_output=True,
                          text=True, timeout=300)


@pytest.fixture(scope="module")
def shipped(tmp_path_factory):
    d = tmp_path_factory.mktemp("lifter")
    shutil.copytree(REPO / "edge_runtime" / "assets", d / "assets",
                    ignore=shutil.ignore_patterns("lifter.*"))
    r = _run("--seed", "5", *TINY, "--sweep", "16,24", "--out", str(d / "assets"), "--report", str(d / "report"),
             "--work", str(d / "work"))
    assert r.returncode == 0, r.stderr[-2000:]
    return d, r.stdout


def test_export_ships_the_contract_and_keeps_the_convlstm(shipped):
    d, _ = shipped
    m = load_manifest(d / "assets")
    arch = [e["arch"] for e in m["models"]]
    assert arch.count("convlstm") >= 1 and arch.count("lifter") == 2
    for e in (x for x in m["models"] if x["arch"] == "lifter"):
        assert e["name"] == f"lifter-{e['precision']}" and e["file"] == f"lifter.{e['precision']}.onnx"
        assert e["sha256"] == sha256_file(d / "assets" / e["file"])
        assert e["receptive_field"] == 27 and e["joints"] == "h36m-17" and e["classes"] == []
        assert e["camera"]["fx_px"] == pytest.approx(640 / np.tan(np.radians(50)))
        assert e["camera"]["cx_px"] == 640.0 and e["camera"]["height_px"] == 720
        assert e["inputs"][0]["name"] == "keypoints_2d" and e["inputs"][0]["shape"] == ["N", 27, 17, 2]
        assert [o["name"] for o in e["outputs"]] == ["pose_3d", "root_3d"]
        assert e["parameters"]["pose"] > 0 and "test" in e["metrics"]["held_out"]
    int8 = next(x for x in m["models"] if x["name"] == "lifter-int8")
    assert int8["quantization"]["method"] in {"qdq", "qdq_fp32_out", "qdq_pt", "dynamic"}
    # the torch-free runtime loads and runs what was shipped
    lifter = StreamingLifter.from_manifest(d / "assets", LifterParams(precision="int8"), keypoint_format="h36m")
    kp = np.column_stack([np.linspace(600, 680, 17), np.linspace(250, 470, 17), np.full(17, 0.9)])
    pose = lifter.push(0.0, kp)
    assert pose.valid and np.isfinite(pose.joints_cam_m).all()


def test_report_has_the_channels_table_and_a_figure(shipped):
    d, out = shipped
    rep = json.loads((d / "report" / "report.json").read_text())
    assert set(rep["sizes"]) == {"16", "24"} and rep["shipped_channels"] == 16
    for row in rep["sizes"].values():
        for key in ("mpjpe_mm", "p_mpjpe_mm", "root_error_mm"):
            assert np.isfinite(row["fp32"]["test"][key]) and np.isfinite(row["int8"]["test"][key])
        assert row["latency"]["fp32"]["p50_us"] > 0 and row["parity"]["ok"]
    md = (d / "report" / "report.md").read_text()
    assert "| 16 (shipped) |" in md and "| 24 |" in md
    assert (d / "report" / "lifter_errors.png").stat().st_size > 10_000
    assert "shipped c16" in out


def test_same_seed_same_weights(shipped, tmp_path):
    d, _ = shipped
    first = json.loads((d / "report" / "report.json").read_text())["sizes"]["16"]["train"]["weights_sha256_16"]
    r = _run("--seed", "5", *TINY, "--out", str(tmp_path / "a"), "--report", str(tmp_path / "r"),
             "--work", str(tmp_path / "w"))
    assert r.returncode == 0, r.stderr[-2000:]
    again = json.loads((tmp_path / "r" / "report.json").read_text())["sizes"]["16"]["train"]["weights_sha256_16"]
    assert again == first


@pytest.mark.parametrize("args,field", [(["--sweep", "256,x"], "--sweep"), (["--seconds", "0"], "--seconds"),
                                        (["--epochs-by-size", "1024"], "--epochs-by-size"),
                                        (["--channels", "-3"], "--channels"),
                                        (["--data", "varied", "--holdout-motions", "juggle"], "--holdout-motions"),
                                        (["--data", "varied", "--random-limbs", "1.5"], "--random-limbs"),
                                        (["--lr-decay", "0"], "--lr-decay"), (["--lr-decay", "1.5"], "--lr-decay")])
def test_bad_arguments_are_one_line_errors(args, field, tmp_path):
    r = _run("--seed", "0", *args, "--out", str(tmp_path / "a"), "--report", str(tmp_path / "r"),
             "--work", str(tmp_path / "w"))
    assert r.returncode == 2 and field in r.stderr and len(r.stderr.strip().splitlines()) == 1
    assert not (tmp_path / "a").exists()
