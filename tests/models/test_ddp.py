"""`torchrun --nproc_per_node=2 -m models train ...`: data-parallel training over gloo on 127.0.0.1."""
from __future__ import annotations

import json
import os
import socket
import subprocess
import sys

import pytest
import torch
from support import REPO_ROOT

from models.dataset import save_npz
from models.toy import toy_windows

pytestmark = pytest.mark.slow  # every test here starts a process

ROOT = REPO_ROOT


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_torchrun_two_processes(tmp_path):
    save_npz(tmp_path / "tiny.npz", toy_windows(n_per_class=8, n_classes=3, n_subjects=2, seed=0))
    out = tmp_path / "ddp"
    env = {**os.environ, "GLOO_SOCKET_IFNAME": "lo", "OMP_NUM_THREADS": "1"}
    r = subprocess.run([sys.executable, "-m", "torch.distributed.run", "--nproc_per_node=2", "--nnodes=1",
                        "--master_addr=127.0.0.1", f"--master_port={free_port()}",
                        "-m", "models", "train", "--arch", "cnn", "--data", tmp_path / "tiny.npz",
                        "--out", out, "--epochs", "1", "--seed", "0", "--no-progress"],
                       cwd=ROOT, env=env, capture_output=True, text=True, timeout=240)
    assert r.returncode == 0, r.stderr[-3000:]
    m = json.loads((out / "metrics.json").read_text())
    assert m["ddp"] == {"world_size": 2, "backend": "gloo", "ranks_identical": True}
    ck = torch.load(out / "model.pt", weights_only=False)
    assert ck["arch"] == "cnn" and ck["n_classes"] == 3
    assert r.stdout.count("wrote") == 1  # only rank 0 writes and reports
