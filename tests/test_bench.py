"""python -m bench: JSON shape from a tiny run (timings are never asserted)."""
import json

import pytest

from bench.__main__ import main
from bench.latency import format_table, run

ROW_KEYS = {"model", "precision", "runtime", "threads", "p50_us", "p99_us", "mean_us", "n"}


@pytest.fixture(scope="module")
def report():
    # assets: the shipped ones, or exported on the fly when absent
    return run([1], n=30, warmup=3, rounds=3)


def test_report_schema(report):
    assert {"cpu", "cores", "python", "onnxruntime", "torch"} <= set(report["machine"])
    rows = report["results"]
    assert rows and all(ROW_KEYS <= set(r) for r in rows)
    kinds = {(r["precision"], r["runtime"]) for r in rows}
    assert {("fp32", "onnxruntime"), ("int8", "onnxruntime"), ("fp32", "torch-eager")} <= kinds
    for r in rows:
        assert r["model"] == "convlstm" and r["threads"] == 1 and r["n"] == 30
        assert 0 < r["p50_us"] <= r["p99_us"] and r["mean_us"] > 0
    assert "threads=1" in report["checks"]
    assert "p50 us" in format_table(report)
    json.dumps(report)


def test_cli_writes_json(tmp_path, capsys):
    out = tmp_path / "b.json"
    assert main(["--n", "20", "--warmup", "2", "--rounds", "2", "--threads", "1", "2", "--no-torch",
                 "--json", str(out)]) == 0
    data = json.loads(out.read_text())
    assert {r["threads"] for r in data["results"]} == {1, 2}
    assert not any(r["runtime"] == "torch-eager" for r in data["results"])
    assert "int8" in capsys.readouterr().out


def test_cli_bad_input(tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        main(["--threads", "0"])
    assert e.value.code == 2
    (tmp_path / "manifest.json").write_text("{}")
    assert main(["--assets", str(tmp_path), "--n", "5"]) == 2
    err = capsys.readouterr().err.strip().splitlines()[-1]
    assert err.startswith("error:") and "manifest.json" in err


def test_bench_runs_without_torch():
    """The box has no torch: bench skips the torch rows and times the shipped models."""
    import subprocess
    import sys
    from pathlib import Path

    from edge_runtime.engine import ASSETS_DIR

    if not (ASSETS_DIR / "manifest.json").exists():
        pytest.skip("no shipped assets")
    code = ("import sys, importlib.abc\n"
            "class B(importlib.abc.MetaPathFinder):\n"
            "    def find_spec(self, name, path=None, target=None):\n"
            "        if name.split('.')[0] in ('torch', 'onnx', 'models', 'export'):\n"
            "            raise ImportError(name)\n"
            "sys.meta_path.insert(0, B())\n"
            "from bench.__main__ import main\n"
            "sys.exit(main(['--n', '20', '--warmup', '2', '--rounds', '2']))\n")
    root = Path(__file__).resolve().parent.parent
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=root, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "torch absent" in r.stdout and "torch-eager" not in r.stdout and "int8" in r.stdout
