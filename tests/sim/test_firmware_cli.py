"""``python -m firmware_sim drive|cohort`` (docs/design.md section 7)."""
from __future__ import annotations

import csv
import json
import os
import subprocess
import sys

import numpy as np
import pytest
from support import REPO_ROOT

from edge_runtime.wearable.labels import CLASSES
from firmware_sim.__main__ import main
from firmware_sim.devices.wrist import make_subjects, simulate_drive
from firmware_sim.scenarios.cohort import load_cohort

ROOT = REPO_ROOT


def run(*args: str) -> subprocess.CompletedProcess:
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.run([sys.executable, "-m", "firmware_sim", *args], capture_output=True, text=True,
                          cwd=ROOT, env=env, timeout=120)


@pytest.mark.slow
def test_drive_writes_csv_and_truth(tmp_path):
    out = tmp_path / "drive"
    p = run("drive", "--minutes", "1.5", "--seed", "4", "--out", str(out), "--plot")
    assert p.returncode == 0, p.stderr
    lines = (out / "imu.csv").read_text().splitlines()
    assert lines[0] == "t,ax,ay,az"
    assert len(lines) == 1 + 90 * 100
    rows = list(csv.reader(lines[1:4]))
    assert [r[0] for r in rows] == ["0.00", "0.01", "0.02"]
    data = np.loadtxt(out / "imu.csv", delimiter=",", skiprows=1)
    assert np.allclose(np.diff(data[:, 0]), 0.01, atol=1e-6)
    assert 8.0 < np.median(np.linalg.norm(data[:, 1:], axis=1)) < 11.5  # m/s^2, gravity dominates
    truth = json.loads((out / "truth.json").read_text())
    assert truth["sample_rate_hz"] == 100
    assert isinstance(truth["subject"], dict) and "height_m" in truth["subject"]
    assert truth["events"], "a drive has events"
    for e in truth["events"]:
        assert {"start_s", "end_s", "label"} <= set(e) and e["label"] in CLASSES
        assert 0 <= e["start_s"] < e["end_s"] <= 90.0
    # the same drive through the API: the CSV holds exactly its samples (4 decimals)
    rec = simulate_drive(1.5, seed=4)
    assert np.allclose(data[:, 1:], rec.acc_mps2, atol=6e-5)
    png = out / "drive.png"
    assert png.exists() and png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_drive_subject_picks_cohort_member(tmp_path):
    assert main(["drive", "--minutes", "0.5", "--seed", "1", "--out", str(tmp_path), "--subject", "3"]) == 0
    truth = json.loads((tmp_path / "truth.json").read_text())
    assert truth["subject"]["subject_id"] == 3
    assert truth["subject"]["height_m"] == make_subjects(20, 0)[2].height_m


def test_cohort_one_command(tmp_path, capsys):
    out = tmp_path / "cohort"
    assert main(["cohort", "--subjects", "2", "--seed", "5", "--out", str(out), "--trial-minutes", "1",
                 "--quiet"]) == 0
    index = json.loads((out / "cohort.json").read_text())
    assert index["n_subjects"] == 2 and len(index["recordings"]) == 12
    assert {r["trial"] for r in index["recordings"]} == {"baseline", "exp1", "exp2", "exp3", "exp4", "exp5"}
    assert {"recall", "precision", "false_alarms"} <= set(index["detector"])
    recs = list(load_cohort(out))
    assert len(recs) == 12 and all(r.acc_mps2.shape == (6000, 3) and r.acc_mps2.dtype == np.float32 for r in recs)
    assert recs[1].trial == "exp1" and all(e.label in CLASSES for r in recs for e in r.events)
    assert "recall" in capsys.readouterr().out


@pytest.mark.slow
@pytest.mark.parametrize("args, needle", [
    (["drive", "--minutes", "-2", "--seed", "1", "--out", "OUT"], "--minutes"),
    (["drive", "--minutes", "abc", "--seed", "1", "--out", "OUT"], "--minutes"),
    (["drive", "--minutes", "1", "--seed", "x", "--out", "OUT"], "--seed"),
    (["drive", "--minutes", "1", "--seed", "1", "--out", "FILE/sub"], "cannot write"),
    (["drive", "--minutes", "1", "--seed", "1", "--out", "OUT", "--subject", "0"], "--subject"),
    (["cohort", "--subjects", "0", "--out", "OUT"], "--subjects"),
    (["cohort", "--subjects", "2", "--out", "OUT", "--trial-minutes", "0"], "--trial-minutes"),
    (["fly"], "invalid choice"),
])
def test_bad_arguments_one_line_error(tmp_path, args, needle):
    blocker = tmp_path / "FILE"
    blocker.write_text("not a directory")
    args = [a.replace("OUT", str(tmp_path / "o")).replace("FILE", str(blocker)) for a in args]
    p = run(*args)
    assert p.returncode != 0
    err = p.stderr.strip().splitlines()
    assert len(err) == 1, p.stderr
    assert "Traceback" not in p.stderr and needle in err[0]
