"""`python -m models train|evaluate`: outputs, and bad input -> one line, exit 2, no traceback."""
from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
import torch
from support import REPO_ROOT

from models.dataset import save_npz
from models.toy import toy_windows

pytestmark = pytest.mark.slow  # every test here starts a process

ROOT = REPO_ROOT


def run(*args, cwd=ROOT):
    return subprocess.run([sys.executable, "-m", "models", *map(str, args)], cwd=cwd, capture_output=True,
                          text=True, timeout=300)


def assert_one_line_error(r, *needles):
    assert r.returncode == 2, (r.returncode, r.stdout, r.stderr)
    err = r.stderr.strip()
    assert "Traceback" not in r.stderr and "\n" not in err, r.stderr
    for n in needles:
        assert n in err, (n, err)


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    d = tmp_path_factory.mktemp("data")
    save_npz(d / "train.npz", toy_windows(n_per_class=12, n_classes=3, n_subjects=3, seed=0))
    save_npz(d / "test.npz", toy_windows(n_per_class=4, n_classes=3, n_subjects=3, seed=1))
    return d


def test_train_test_writes_metrics_checkpoint_png(tmp_path, data):
    out = tmp_path / "run"
    r = run("train", "--arch", "convlstm", "--data", data / "train.npz", "--test", data / "test.npz", "--out", out,
            "--epochs", "2", "--seed", "3", "--no-progress")
    assert r.returncode == 0, r.stderr
    m = json.loads((out / "metrics.json").read_text())
    assert {"accuracy", "macro_f1", "per_class", "confusion"} <= set(m)
    assert len(m["confusion"]) == 3 and set(m["per_class"]) == {"C0", "C1", "C2"}
    ck = torch.load(out / "model.pt", weights_only=False)
    assert ck["arch"] == "convlstm" and ck["classes"] == ["C0", "C1", "C2"] and ck["n_classes"] == 3
    assert ck["seed"] == 3 and ck["epochs"] == 2 and "macro_f1" in ck["metrics"] and "train" in ck["data"]
    assert (out / "confusion.png").stat().st_size > 1000
    # the checkpoint scores the same data the same way through `evaluate`
    r = run("evaluate", "--checkpoint", out / "model.pt", "--data", data / "test.npz", "--out", tmp_path / "ev")
    assert r.returncode == 0, r.stderr
    m2 = json.loads((tmp_path / "ev" / "metrics.json").read_text())
    assert m2["confusion"] == m["confusion"]


def test_loso_and_within_cli(tmp_path, data):
    out = tmp_path / "loso"
    r = run("train", "--arch", "lda", "--data", data / "train.npz", "--test", data / "test.npz", "--loso",
            "--within", "--out", out, "--no-progress")
    assert r.returncode == 0, r.stderr
    m = json.loads((out / "metrics.json").read_text())
    assert m["protocol"] == "leave-one-subject-out" and m["folds"] == ["s0", "s1", "s2"]
    assert set(m["per_subject"]) == {"0", "1", "2"}
    assert all((out / "folds" / f"s{s}" / "model.pkl").exists() for s in range(3))
    assert (out / "model.pkl").exists()
    w = json.loads((out / "within" / "metrics.json").read_text())
    assert w["protocol"].startswith("within-subject")


def _save_raw(path, **arrays):
    with open(path, "wb") as f:
        np.savez(f, **arrays)
    return path


def test_bad_npz_inputs_give_one_line_errors(tmp_path, data):
    good = np.load(data / "train.npz")
    base = {k: good[k] for k in ("X", "y", "subject", "classes")}
    out = tmp_path / "o"

    def train(path):
        return run("train", "--arch", "lda", "--data", path, "--out", out)

    assert_one_line_error(train(tmp_path / "nope.npz"), "nope.npz", "not found")
    p = _save_raw(tmp_path / "shape.npz", **{**base, "X": base["X"][:, :500]})
    assert_one_line_error(train(p), "shape.npz", "'X'", "(N, 700, 3)")
    X = base["X"].copy()
    X[2, 5, 0] = np.nan
    assert_one_line_error(train(_save_raw(tmp_path / "nan.npz", **{**base, "X": X})), "nan.npz", "'X'", "NaN")
    y = base["y"].copy()
    y[0] = 7
    assert_one_line_error(train(_save_raw(tmp_path / "lab.npz", **{**base, "y": y})), "lab.npz", "'y'", "7")
    p = _save_raw(tmp_path / "nosub.npz", **{k: v for k, v in base.items() if k != "subject"})
    assert_one_line_error(train(p), "nosub.npz", "'subject'", "missing")
    p = _save_raw(tmp_path / "dtype.npz", **{**base, "X": base["X"].astype(np.int32)})
    assert_one_line_error(train(p), "dtype.npz", "'X'", "dtype")
    (tmp_path / "junk.npz").write_bytes(b"garbage")
    assert_one_line_error(train(tmp_path / "junk.npz"), "junk.npz")
    # a test set whose classes differ from the training set's
    other = toy_windows(n_per_class=2, n_classes=4, n_subjects=1)
    save_npz(tmp_path / "k4.npz", other)
    r = run("train", "--arch", "lda", "--data", data / "train.npz", "--test", tmp_path / "k4.npz", "--out", out)
    assert_one_line_error(r, "k4.npz", "'classes'")
    # LOSO needs two subjects
    save_npz(tmp_path / "one.npz", toy_windows(n_per_class=3, n_classes=3, n_subjects=1))
    r = run("train", "--arch", "lda", "--data", tmp_path / "one.npz", "--loso", "--out", out)
    assert_one_line_error(r, "one.npz", "'subject'")


def test_bad_arguments_exit_2(tmp_path, data):
    r = run("train", "--arch", "transformer", "--data", data / "train.npz", "--out", tmp_path)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    r = run("evaluate", "--checkpoint", tmp_path / "none.pt", "--data", data / "test.npz", "--out", tmp_path)
    assert_one_line_error(r, "none.pt")


def test_report_on_given_data(tmp_path, data):
    out = tmp_path / "rep"
    r = run("report", "--out", out, "--data", data / "train.npz", "--test", data / "test.npz", "--archs",
            "lda,lda_summary", "--jobs", "1", "--no-progress", "--folds", "2")
    assert r.returncode == 0, r.stderr
    rep = json.loads((out / "report.json").read_text())
    assert set(rep["loso"]) == {"lda", "lda_summary"} and set(rep["loso"]["lda"]["per_subject"]) == {"0", "1"}
    assert "lda" in rep["within"]
    md = (out / "report.md").read_text()
    # the product figure leads; the dissertation's tables follow as the comparison
    assert md.index("every capture it classifies") < md.index("Onset captures") < md.index("Comparison with")
    assert "| LDA (12 summary stats) | 2 of 3 |" in md
    assert "Table 2.2" in md and "Table 2.3" in md and "Table 2.1" in md and "python -m models report" in md
    assert (out / "lda" / "loso" / "confusion.png").exists()
    # --reuse-only reports the saved folds and trains none: still 2 of the 3 subjects
    r = run("report", "--out", out, "--data", data / "train.npz", "--test", data / "test.npz", "--archs",
            "lda", "--jobs", "1", "--no-progress", "--no-within", "--reuse-only")
    assert r.returncode == 0, r.stderr
    rep = json.loads((out / "report.json").read_text())
    assert rep["loso"]["lda"]["folds"] == ["s0", "s1"]
    assert "| LDA | 2 of 3 |" in (out / "report.md").read_text()
    assert_one_line_error(run("report", "--out", out, "--archs", "svm"), "--archs")
