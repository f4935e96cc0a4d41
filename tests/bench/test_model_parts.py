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
