"""`python -m models import`: CSV stream + events -> NPZ through the detector; bad input -> one line."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from support import REPO_ROOT

from edge_runtime.wearable.labels import CLASSES
from models.dataset import load_npz
from models.importer import import_recording
from models.toy import toy_stream

ROOT = REPO_ROOT
EVENTS = [(10.0, 14.0, "Phone"), (40.0, 44.0, "Drink"), (70.0, 72.0, "Other")]


def run(*args):
    return subprocess.run([sys.executable, "-m", "models", "import", *map(str, args)], cwd=ROOT,
                          capture_output=True, text=True, timeout=120)


def write_stream(path, rate=100.0, seconds=120.0, t0=0.0):
    rec = toy_stream(EVENTS, seconds=seconds, false_alarms=[95.0])
    acc = rec.acc_mps2
    if rate != 100.0:  # sample the same motion at another rate
        t_new = np.arange(int(seconds * rate)) / rate
        t_old = np.arange(len(acc)) / 100.0
        acc = np.stack([np.interp(t_new, t_old, acc[:, i]) for i in range(3)], axis=1)
    t = t0 + np.arange(len(acc)) / rate
    with open(path, "w") as f:
        f.write("t,ax,ay,az\n")
        for ti, a in zip(t, acc):
            f.write(f"{ti:.5f},{a[0]:.4f},{a[1]:.4f},{a[2]:.4f}\n")
    return path


def write_events(path, events=EVENTS, header="start_s,end_s,label"):
    with open(path, "w") as f:
        f.write(header + "\n")
        for s, e, lab in events:
            f.write(f"{s},{e},{lab}\n")
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("imp")
    return write_stream(d / "rec.csv"), write_events(d / "events.csv")


@pytest.mark.slow
def test_import_test_and_train_splits(tmp_path, files):
    rec, ev = files
    r = run("--csv", rec, "--events", ev, "--subject", 4, "--out", tmp_path / "test.npz")
    assert r.returncode == 0, r.stderr
    ws = load_npz(tmp_path / "test.npz")
    labels = [ws.classes[k] for k in ws.y]
    assert labels[:2] == ["Phone", "Drink"] and labels[-1] == "Other" and np.all(ws.subject == 4)
    assert ws.classes == list(CLASSES)
    r = run("--csv", rec, "--events", ev, "--subject", 4, "--out", tmp_path / "train.npz", "--split", "train")
    assert r.returncode == 0, r.stderr
    tr = load_npz(tmp_path / "train.npz")
    assert [tr.classes[k] for k in tr.y] == ["Phone", "Drink", "Other"]
    # --append adds a second subject
    r = run("--csv", rec, "--events", ev, "--subject", 5, "--out", tmp_path / "train.npz", "--split", "train",
            "--append")
    assert r.returncode == 0, r.stderr
    assert sorted(set(load_npz(tmp_path / "train.npz").subject.tolist())) == [4, 5]


def test_import_custom_classes_and_faster_stream(tmp_path):
    rec = write_stream(tmp_path / "r200.csv", rate=200.0, t0=5.0)
    ev = write_events(tmp_path / "e.csv", [(15.0, 19.0, "Wave"), (45.0, 49.0, "Wave")])
    ws, info = import_recording(str(rec), str(ev), 1, split="train", classes=["Wave"])
    assert ws.classes == ["Wave", "Other"] and info["resampled"] and info["rate_hz"] == pytest.approx(200.0)
    assert len(ws) == 2 and ws.X.shape == (2, 700, 3)
    np.testing.assert_allclose(ws.t_s, [14.0, 44.0], atol=0.02)


def _err(r, *needles):
    assert r.returncode == 2, (r.stdout, r.stderr)
    err = r.stderr.strip()
    assert "Traceback" not in r.stderr and "\n" not in err, r.stderr
    for n in needles:
        assert n in err, (n, err)


@pytest.mark.slow
def test_import_errors(tmp_path, files):
    rec, ev = files
    out = tmp_path / "o.npz"
    lines = Path(rec).read_text().splitlines()

    bad = tmp_path / "hdr.csv"
    bad.write_text("\n".join(["time,x,y,z"] + lines[1:]) + "\n")
    _err(run("--csv", bad, "--events", ev, "--subject", 1, "--out", out), "hdr.csv", "line 1", "header")

    nan = tmp_path / "nan.csv"
    rows = list(lines)
    rows[7] = "0.06000,nan,0.1,9.8"
    nan.write_text("\n".join(rows) + "\n")
    _err(run("--csv", nan, "--events", ev, "--subject", 1, "--out", out), "nan.csv", "line 8", "'ax'")

    txt = tmp_path / "txt.csv"
    rows = list(lines)
    rows[11] = "0.10000,0.1,abc,9.8"
    txt.write_text("\n".join(rows) + "\n")
    _err(run("--csv", txt, "--events", ev, "--subject", 1, "--out", out), "txt.csv", "line 12", "'ay'")

    slow = write_stream(tmp_path / "slow.csv", rate=50.0)
    _err(run("--csv", slow, "--events", ev, "--subject", 1, "--out", out), "slow.csv", "100 Hz")

    gap = tmp_path / "gap.csv"
    gap.write_text("\n".join(lines[:500] + lines[600:]) + "\n")
    _err(run("--csv", gap, "--events", ev, "--subject", 1, "--out", out), "gap.csv", "line 501", "'t'")

    unk = write_events(tmp_path / "unk.csv", [(10.0, 14.0, "Phone"), (40.0, 44.0, "Juggling")])
    _err(run("--csv", rec, "--events", unk, "--subject", 1, "--out", out), "unk.csv", "line 3", "Juggling")

    outside = write_events(tmp_path / "out.csv", [(10.0, 14.0, "Phone"), (118.0, 130.0, "Drink")])
    _err(run("--csv", rec, "--events", outside, "--subject", 1, "--out", out), "out.csv", "line 3", "outside")

    backwards = write_events(tmp_path / "back.csv", [(14.0, 10.0, "Phone")])
    _err(run("--csv", rec, "--events", backwards, "--subject", 1, "--out", out), "back.csv", "line 2", "'end_s'")

    ehdr = write_events(tmp_path / "ehdr.csv", header="begin,end,what")
    _err(run("--csv", rec, "--events", ehdr, "--subject", 1, "--out", out), "ehdr.csv", "line 1", "header")

    _err(run("--csv", tmp_path / "missing.csv", "--events", ev, "--subject", 1, "--out", out), "missing.csv")


@pytest.mark.slow
def test_import_truth_json_events(tmp_path, files):
    import json

    rec, _ = files
    truth = tmp_path / "truth.json"
    truth.write_text(json.dumps({"sample_rate_hz": 100, "events": [
        {"start_s": s, "end_s": e, "label": lab, "detail": {}} for s, e, lab in EVENTS]}))
    ws, info = import_recording(str(rec), str(truth), 2, split="train")
    assert [ws.classes[k] for k in ws.y] == ["Phone", "Drink", "Other"]
    truth.write_text(json.dumps({"events": [{"start_s": 1.0, "end_s": 2.0, "label": "Yodel"}]}))
    _err(run("--csv", rec, "--events", truth, "--subject", 1, "--out", tmp_path / "o.npz"),
         "truth.json", "events[0]", "Yodel")
