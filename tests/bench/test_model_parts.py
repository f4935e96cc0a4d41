"""bench.model_parts: the shipped ConvLSTM cut at the LSTM's input, each part timed alone."""
from __future__ import annotations

import pytest

pytest.importorskip("onnx")

from bench.model_parts import measure  # noqa: E402
from edge_runtime.core.manifest import ASSETS_DIR  # noqa: E402


def test_every_part_of_both_precisions_is_timed():
    rows = {r["part"]: r for r in measure(ASSETS_DIR, n=8)}
    for precision in ("fp32", "int8"):
        assert {f"{precision} full", f"{precision} conv stack", f"{precision} lstm+head"} <= set(rows)
    assert {"fp32 lstm", "lstm dynamic int8", "empty run"} <= set(rows)
    assert all(r["n"] == 8 and r["p50_us"] > 0 for r in rows.values())


@pytest.mark.slow  # starts a process
@pytest.mark.parametrize("args, word", [(["--assets", "/nonexistent/assets"], "/nonexistent/assets"),
                                        (["--json", "/nonexistent/dir/out.json"], "/nonexistent/dir")])
def test_bad_input_is_one_line_and_exit_2(args, word):
    import subprocess
    import sys

    r = subprocess.run([sys.executable, "-m", "bench.model_parts", *args], capture_output=True, text=True, timeout=120)
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1 and word in r.stderr, r.stderr
