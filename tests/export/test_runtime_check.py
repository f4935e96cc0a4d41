"""export/runtime_check.py: the shipped models in another interpreter against this one."""
import sys

import numpy as np
import pytest

from edge_runtime.core.manifest import ASSETS_DIR, load_manifest
from export.runtime_check import TOL, compare, fixed_inputs, main, run_outputs


def test_fixed_inputs_follow_the_manifest_with_batch_4():
    m = load_manifest(ASSETS_DIR)
    feed = fixed_inputs(m)
    for e in m["models"]:
        for spec in e["inputs"]:
            x = feed[f"{e['name']}/{spec['name']}"]
            # the ConvLSTM timed at its full window, the stream model at the runtime's window (its "dims")
            want = [6 if d == "S" else spec.get("dims", {}).get(d, d) for d in spec["shape"][1:]]
            assert x.shape == (4, *want) and x.dtype == np.float32
    again = fixed_inputs(m)
    assert all(np.array_equal(feed[k], again[k]) for k in feed)


def test_compare_flags_a_refused_model_and_a_difference_beyond_the_tolerance():
    m = {"models": [{"name": "a", "classes": ["x", "y"]}, {"name": "b", "classes": []}, {"name": "c", "classes": []}]}
    ref = {"a/probs": np.array([[0.9, 0.1], [0.2, 0.8]]), "b/pose": np.zeros(3), "c/pose": np.zeros(3)}
    other = {"a/probs": np.array([[0.9, 0.1], [0.6, 0.4]]), "b/pose": np.full(3, TOL / 2),
             "c/__error__": np.array("opset ai.onnx.ml 5 unknown")}
    rows = compare(m, ref, other)
    assert rows["a"] == {"loaded": True, "max_abs": pytest.approx(0.4), "ok": False, "argmax_agree": 0.5}
    assert rows["b"]["ok"] and rows["b"]["max_abs"] == pytest.approx(TOL / 2)
    assert rows["c"] == {"loaded": False, "error": "opset ai.onnx.ml 5 unknown", "ok": False}


@pytest.mark.slow
def test_the_same_interpreter_gives_the_same_outputs_and_a_time_per_model(capsys):
    m = load_manifest(ASSETS_DIR)
    out = run_outputs([sys.executable], ASSETS_DIR, fixed_inputs(m), timed_calls=3)
    assert all(out[f"{e['name']}/__p50_us__"] > 0 for e in m["models"])
    assert main(["--python", sys.executable]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    assert len(lines) == len(m["models"]) and all("max |d| 0.00e+00" in line for line in lines)
