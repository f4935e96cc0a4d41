"""python -m bench: manifest-driven rows, per-process memory, loops, profiles, --compare, bad input.

Timings are never asserted (the machine is shared); shapes, counts, file sizes,
process isolation and the ratios' arithmetic are.
"""
import copy
import json
import os
import shutil
import subprocess
import sys
import time

import pytest
from support import REPO_ROOT

from bench.__main__ import main
from bench.report import compare, format_markdown
from edge_runtime.core.manifest import ASSETS_DIR, load_manifest, sha256_file, write_manifest

ROOT = REPO_ROOT
ROW_KEYS = {"model", "precision", "runtime", "threads", "p50_us", "p99_us", "mean_us", "n", "file_bytes",
            "peak_rss_mb"}
QUICK_N = 100
DRIVE_SAMPLES = 2 * 60 * 100  # --quick simulates a 2-minute drive at 100 Hz

pytestmark = pytest.mark.skipif(not (ASSETS_DIR / "manifest.json").exists(), reason="no shipped assets")


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench")
    code = main(["--quick", "--threads", "1", "--json", str(out / "b.json"), "--markdown", str(out / "b.md")])
    assert code == 0
    return json.loads((out / "b.json").read_text()), (out / "b.md").read_text()


def _torch_importable() -> bool:
    try:
        import torch  # noqa: F401
    except ImportError:
        return False
    return True


def _openvino_importable() -> bool:
    from bench.machine import openvino_version

    return openvino_version() is not None


@pytest.mark.slow
def test_rows_follow_the_manifest(quick):
    report, _ = quick
    assert {"cpu", "cores", "python", "onnxruntime", "torch", "cpus_used"} <= set(report["machine"])
    entries = load_manifest(ASSETS_DIR)["models"]
    rows = report["results"]
    assert all(ROW_KEYS <= set(r) for r in rows)
    ort = {(r["name"], r["threads"]) for r in rows if r["runtime"] == "onnxruntime"}
    assert ort == {(e["name"], 1) for e in entries}
    for r in rows:
        assert r["n"] == QUICK_N and 0 < r["p50_us"] <= r["p99_us"] and r["mean_us"] > 0
        assert r["peak_rss_mb"] >= r["rss_idle_mb"] > 0
        if r["runtime"] == "onnxruntime":
            e = next(e for e in entries if e["name"] == r["name"])
            assert r["file_bytes"] == (ASSETS_DIR / e["file"]).stat().st_size
            assert (r["model"], r["precision"]) == (e["arch"], e["precision"])
    # torch eager: every fp32 entry is either timed or skipped with a note, never silently missing
    torch_rows = {(r["name"], r["threads"]) for r in rows if r["runtime"] == "torch-eager"}
    torch_skips = {(s["model"], s["threads"]) for s in report["skipped"] if s["runtime"] == "torch-eager"}
    for e in entries:
        if e["precision"] == "fp32" and _torch_importable():
            assert (e["name"], 1) in torch_rows or (e["arch"], 1) in torch_skips
        else:
            assert (e["name"], 1) not in torch_rows
    if _torch_importable():
        assert ("convlstm-fp32", 1) in torch_rows  # models.nets rebuilds the ConvLSTM
    # openvino: every entry timed when it is installed, else each skipped with the extra to install
    ov_rows = {(r["name"], r["threads"]) for r in rows if r["runtime"] == "openvino"}
    ov_skips = [s for s in report["skipped"] if s["runtime"] == "openvino"]
    if _openvino_importable():
        assert ov_rows == {(e["name"], 1) for e in entries} and not ov_skips
    else:
        assert not ov_rows and len(ov_skips) == len(entries)
        assert all("edge-safety[openvino]" in s["note"] for s in ov_skips)


@pytest.mark.slow
def test_each_configuration_has_its_own_process(quick):
    """onnxruntime children never load torch, so their peak memory is not torch's."""
    report, _ = quick
    rows = report["results"]
    assert not any(r["torch_loaded"] for r in rows if r["runtime"] == "onnxruntime")
    torch_rows = [r for r in rows if r["runtime"] == "torch-eager"]
    if torch_rows:
        assert all(r["torch_loaded"] for r in torch_rows)
        assert min(r["rss_idle_mb"] for r in torch_rows) > max(r["peak_rss_mb"] for r in rows
                                                               if r["runtime"] == "onnxruntime")


@pytest.mark.slow
def test_loops(quick):
    report, _ = quick
    loops = {lp["name"]: lp for lp in report["loops"]}
    assert {"wearable_100hz", "detector", "alert_latency", "decision_latency", "robot_30hz"} <= set(loops)
    w = loops["wearable_100hz"]
    # fed in the blocks the live source hands over (one per read period): every sample, n blocks
    assert w["samples"] == w["n"] * w["block_samples"] == 100 and 0 < w["cpu_share_pct"] and w["deadline_misses"] >= 0
    assert w["peak_rss_mb"] > 0
    # the decider the box ships, labelled: the streaming one counts its hops, not captures
    assert w["decision"] == "stream" and "streaming decider" in w["what"] and "stream-int8" in w["what"]
    assert "hops" in w and "captures" not in w
    d = loops["detector"]
    assert d["samples"] == d["n"] == DRIVE_SAMPLES and d["triggers"] >= 1
    assert loops["detector_sample"]["n"] == DRIVE_SAMPLES and loops["detector_sample"]["triggers"] == d["triggers"]
    # every stream decision is an alert (one per distraction event: 3 on this drive), and each went out on the bus
    assert loops["alert_latency"]["n"] == loops["decision_latency"]["n"] >= 1
    r = loops["robot_30hz"]
    assert r.get("available") is False and r["note"] or (r["frames"] == r["n"] == 30 and r["cpu_share_pct"] > 0)


@pytest.mark.slow
def test_profiles_and_markdown(quick):
    report, md = quick
    entries = {e["name"]: e for e in load_manifest(ASSETS_DIR)["models"]}
    prof = next(p for p in report["profiles"] if p["model"] == "convlstm" and p["threads"] == 1)
    size = {prec: (ASSETS_DIR / entries[f"convlstm-{prec}"]["file"]).stat().st_size for prec in ("fp32", "int8")}
    assert prof["fp32"]["file_bytes"] == size["fp32"] and prof["int8"]["file_bytes"] == size["int8"]
    assert prof["int8_over_fp32"]["file_bytes"] == round(size["int8"] / size["fp32"], 3)
    assert prof["int8_speedup_vs_fp32"] == round(prof["fp32"]["p50_us"] / prof["int8"]["p50_us"], 3)
    table = [line for line in md.splitlines() if line.startswith("| ") and "µs" not in line and "cost" not in line]
    assert len(table) == len(report["results"]) + len(report["skipped"]) + len(report["loops"])
    assert md == format_markdown(report)
    # the step model's rows say they are one step per decision, the one-shot's the whole capture in one run
    assert {"convlstm", "convlstm_step"} <= {r["model"] for r in report["results"]}
    assert "convlstm_step: per decision: one step" in md and "convlstm: the whole capture" in md
    # the step is timed as the box calls it (a capture's steps, its state kept in the IOBinding on this onnxruntime)
    assert {r.get("call") for r in report["results"] if r["model"] == "convlstm_step"
            and r["runtime"] == "onnxruntime"} == {"StepModel.step_stream (iobinding, state kept bound; captures "
                                                   "of 6 steps from the zero state)"}


def test_an_arch_brings_its_step_model_and_an_entry_name_only_itself():
    from bench.sweep import _entries

    names = [e["name"] for e in _entries(ASSETS_DIR, ("convlstm",))]
    assert names == ["convlstm-fp32", "convlstm-int8", "convlstm-step-fp32", "convlstm-step-int8"]
    assert [e["name"] for e in _entries(ASSETS_DIR, ("convlstm-int8",))] == ["convlstm-int8"]


@pytest.mark.slow
def test_compare_flags_regressions(quick):
    new, _ = quick
    old = copy.deepcopy(new)
    row = old["results"][0]
    row["p50_us"] /= 2  # the new run is twice as slow on this row
    lines, regressions = compare(new, old, tolerance=0.10)
    assert regressions == 1
    assert any("REGRESSION" in line and line.startswith(" ".join(str(row[k]) for k in
                                                                  ("model", "precision", "runtime", "threads")))
               for line in lines)
    old["results"].append({**row, "model": "gone"})
    lines, _ = compare(new, old)
    assert any(line.startswith("gone ") and "only in old" in line for line in lines)
    assert compare(new, new)[1] == 0


@pytest.mark.slow
def test_threads_and_compare_cli_exit_status(tmp_path, capsys):
    base = ["--quick", "--no-torch", "--no-openvino", "--no-loops", "--threads", "1", "2", "--models", "convlstm-int8"]
    out = tmp_path / "now.json"
    assert main(base + ["--json", str(out)]) == 0
    old = json.loads(out.read_text())
    assert sorted((r["name"], r["threads"]) for r in old["results"]) == [("convlstm-int8", 1), ("convlstm-int8", 2)]
    for r in old["results"]:
        r["p50_us"] = r["p99_us"] = r["mean_us"] = 1e-6  # impossibly fast: anything new is a regression
    (tmp_path / "old.json").write_text(json.dumps(old))
    assert main(base + ["--compare", str(tmp_path / "old.json")]) == 1
    assert "REGRESSION" in capsys.readouterr().out


@pytest.mark.slow
def test_unknown_arch_is_timed_on_onnxruntime_and_skipped_on_torch(tmp_path):
    """Entries come from the manifest: a model torch cannot rebuild still gets its onnxruntime rows."""
    assets = tmp_path / "assets"
    shutil.copytree(ASSETS_DIR, assets)
    m = load_manifest(assets)
    fp = next(e for e in m["models"] if e["name"] == "convlstm-fp32")
    m["models"] = [{**fp, "name": "mystery-fp32", "arch": "mystery"}]
    write_manifest(assets, m)
    out = tmp_path / "b.json"
    assert main(["--quick", "--no-loops", "--threads", "1", "--assets", str(assets), "--json", str(out)]) == 0
    rep = json.loads(out.read_text())
    assert [(r["model"], r["runtime"]) for r in rep["results"]] == [("mystery", "onnxruntime")] + (
        [("mystery", "openvino")] if _openvino_importable() else [])
    skipped = {s["runtime"]: s for s in rep["skipped"] if s["model"] == "mystery"}
    assert ("openvino" in skipped) != _openvino_importable()  # an uninstalled peer is skipped, named
    if _torch_importable():
        assert "mystery" in skipped["torch-eager"]["note"]


@pytest.mark.slow
def test_a_failing_configuration_is_reported_not_hidden(tmp_path, capsys):
    """A model onnxruntime cannot load (hash fine, bytes garbage): a FAILED row, exit status 1."""
    assets = tmp_path / "assets"
    shutil.copytree(ASSETS_DIR, assets)
    (assets / "broken.onnx").write_bytes(b"not an onnx model")
    m = load_manifest(assets)
    i8 = next(e for e in m["models"] if e["name"] == "convlstm-int8")
    broken = {**i8, "name": "broken-int8", "file": "broken.onnx", "sha256": sha256_file(assets / "broken.onnx")}
    m["models"] = [i8, broken]
    write_manifest(assets, m)
    out = tmp_path / "b.json"
    assert main(["--quick", "--no-loops", "--no-openvino", "--threads", "1", "--assets", str(assets), "--json",
                 str(out)]) == 1
    rep = json.loads(out.read_text())
    assert [r["name"] for r in rep["results"]] == ["convlstm-int8"] and rep["failures"] == 1
    assert rep["skipped"][0]["note"].startswith("FAILED") and "broken-int8" in rep["skipped"][0]["note"]
    assert "FAILED" in capsys.readouterr().err


def _last_err(capsys) -> str:
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines
    return lines[-1]


def test_bad_input(tmp_path, capsys):
    with pytest.raises(SystemExit) as e:
        main(["--threads", "0"])
    assert e.value.code == 2
    (tmp_path / "manifest.json").write_text("{}")
    assert main(["--assets", str(tmp_path), "--quick"]) == 2
    err = _last_err(capsys)
    assert err.startswith("error:") and "manifest.json" in err
    assert main(["--quick", "--compare", str(tmp_path / "missing.json")]) == 2
    assert "missing.json" in _last_err(capsys)
    assert main(["--quick", "--cpus", "0,x"]) == 2
    assert "--cpus" in _last_err(capsys)
    assert main(["--quick", "--models", "nosuchmodel", "--no-loops"]) == 2
    assert "nosuchmodel" in _last_err(capsys)


def test_tampered_model_is_refused(tmp_path, capsys):
    assets = tmp_path / "assets"
    shutil.copytree(ASSETS_DIR, assets)
    victim = assets / load_manifest(assets)["models"][0]["file"]
    data = bytearray(victim.read_bytes())
    data[-1] ^= 0xFF
    victim.write_bytes(bytes(data))
    assert sha256_file(victim) != load_manifest(assets)["models"][0]["sha256"]
    assert main(["--quick", "--no-loops", "--assets", str(assets)]) == 2
    err = _last_err(capsys)
    assert victim.name in err and "sha256" in err


def _run_bench(args, blocked=()) -> subprocess.CompletedProcess:
    code = ("import sys, importlib.abc\n"
            f"BLOCKED = {tuple(blocked)!r}\n"
            "class B(importlib.abc.MetaPathFinder):\n"
            "    def find_spec(self, name, path=None, target=None):\n"
            "        if name.split('.')[0] in BLOCKED:\n"
            "            raise ImportError(name)\n"
            "sys.meta_path.insert(0, B())\n"
            "from bench.__main__ import main\n"
            f"sys.exit(main({list(args)!r}))\n")
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)


@pytest.mark.slow
def test_cpus_pins_the_run(tmp_path):
    out = tmp_path / "b.json"
    r = _run_bench(["--quick", "--no-loops", "--no-torch", "--threads", "1", "--models", "convlstm-int8",
                    "--cpus", "0", "--json", str(out)])
    assert r.returncode == 0, r.stderr[-2000:]
    assert json.loads(out.read_text())["machine"]["cpus_used"] == [0]
    r = _run_bench(["--quick", "--no-loops", "--cpus", "4096"])
    assert r.returncode == 2 and r.stderr.strip().splitlines()[-1].startswith("error: --cpus")


@pytest.mark.slow
def test_bench_runs_without_torch():
    """The box has no torch: bench skips the torch rows and times the shipped models."""
    r = _run_bench(["--quick", "--no-loops", "--threads", "1"], blocked=("torch", "onnx", "models", "export"))
    assert r.returncode == 0, r.stderr[-2000:]
    assert "torch absent" in r.stdout and "torch-eager" not in r.stdout and "int8" in r.stdout


def test_openvino_missing_is_a_skip_naming_the_extra(monkeypatch):
    from bench.inference import InferenceConfig, measure

    monkeypatch.setitem(sys.modules, "openvino", None)  # import openvino raises ImportError
    r = measure(InferenceConfig(str(ASSETS_DIR), "convlstm-int8", "openvino", n=5, warmup=1))
    assert r == {"skipped": "openvino not installed (pip install 'edge-safety[openvino]')"}


@pytest.mark.slow  # OpenVINO's CPU plugin forks a helper process when it loads
def test_openvino_times_the_shipped_file():
    pytest.importorskip("openvino")
    from bench.inference import InferenceConfig, measure

    r = measure(InferenceConfig(str(ASSETS_DIR), "convlstm-int8", "openvino", n=5, warmup=1))
    assert len(r["times_ns"]) == 5 and min(r["times_ns"]) > 0
    assert r["file_bytes"] == (ASSETS_DIR / "convlstm.int8.onnx").stat().st_size and r["openvino"]


@pytest.mark.slow
def test_load_generator_keeps_a_pinned_process_busy_only_while_measuring():
    from bench.machine import LoadGenerator

    with LoadGenerator([0]) as gen:
        (proc,) = gen.procs
        deadline = time.monotonic() + 10
        while os.sched_getaffinity(proc.pid) != {0} and time.monotonic() < deadline:
            time.sleep(0.05)  # the child pins itself as it starts
        assert proc.is_alive() and os.sched_getaffinity(proc.pid) == {0}
    assert not proc.is_alive()


def test_busy_cpus_that_are_not_there_are_one_line(capsys):
    assert main(["--quick", "--no-loops", "--busy-cpus", "4096"]) == 2
    assert _last_err(capsys).startswith("error: --busy-cpus")
