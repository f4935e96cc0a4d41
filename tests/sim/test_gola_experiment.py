"""``python -m firmware_sim gola``: chapter 4's protocol end to end on a small cohort."""
import json
import subprocess
import sys

import pytest
from support import REPO_ROOT

pytestmark = pytest.mark.slow  # every test here starts a process

ROOT = REPO_ROOT
CONDITIONS = ("Fixed", "ElbowHeight", "Learnt", "WorkerSelected")


def gola(*args, cwd=ROOT):
    return subprocess.run([sys.executable, "-m", "firmware_sim", "gola", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=300)


@pytest.fixture(scope="module")
def small_run(tmp_path_factory):
    d = tmp_path_factory.mktemp("gola")
    r = gola("--cohort", "2", "--seed", "1", "--json", str(d / "out.json"), "--plot", str(d / "box.png"),
             "--log", str(d / "logs"), "--quiet")
    assert r.returncode == 0, r.stderr
    return d, r, json.loads((d / "out.json").read_text())


def test_json_has_the_contracted_fields(small_run):
    _, _, out = small_run
    assert out["participants"] == 2 and len(out["per_participant"]) == 2
    assert out["mean_iterations"] == pytest.approx(sum(p["iterations"] for p in out["per_participant"]) / 2)
    for c in CONDITIONS:
        assert set(out["cap"][c]) >= {"mean", "sd"}
        assert out["cap"][c]["n"] == 6                                  # 2 participants x 3 repetitions
    p = out["p_values"]
    assert 0.0 <= p["kruskal_wallis"] <= 1.0
    assert set(p["steel_dwass"]) == {f"{a}-{b}" for i, a in enumerate(CONDITIONS) for b in CONDITIONS[i + 1:]}
    assert isinstance(out["ordering_holds"], bool)
    assert out["gola_iteration_us"]["n"] == sum(p["iterations"] for p in out["per_participant"])
    assert out["gola_iteration_us"]["median"] > 0


def test_each_participant_ran_the_protocol(small_run):
    _, _, out = small_run
    for p in out["per_participant"]:
        assert sorted(p["order"]) == sorted(CONDITIONS)
        assert all(len(p["cap"][c]) == 3 for c in CONDITIONS)
        assert p["positions"]["Fixed"] == {"height_m": 1.055, "pitch_deg": 0.0}
        assert p["positions"]["ElbowHeight"]["pitch_deg"] == 0.0
        assert 0.7 <= p["positions"]["Learnt"]["height_m"] <= 1.6


def test_means_are_the_means_of_the_repetitions(small_run):
    _, _, out = small_run
    for c in CONDITIONS:
        reps = [x for p in out["per_participant"] for x in p["cap"][c]]
        assert out["cap"][c]["mean"] == pytest.approx(sum(reps) / len(reps), abs=1e-3)   # reps rounded to 1e-4


def test_plots_and_session_logs_are_written(small_run):
    d, r, out = small_run
    for png in (d / "box.png", d / "box_iterations.png"):
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    logs = sorted((d / "logs").glob("*.jsonl"))
    assert [x.name for x in logs] == ["P01.jsonl", "P02.jsonl"]
    rows = [json.loads(x) for x in logs[0].read_text().splitlines()]
    its = [x for x in rows if x["event"] == "iteration"]
    assert len(its) == out["per_participant"][0]["iterations"]
    assert "mean" in r.stdout or "iterations" in r.stdout


def test_same_seed_same_results(small_run, tmp_path):
    _, _, out = small_run
    r = gola("--cohort", "2", "--seed", "1", "--json", str(tmp_path / "again.json"), "--quiet")
    assert r.returncode == 0, r.stderr
    again = json.loads((tmp_path / "again.json").read_text())
    assert again["cap"] == out["cap"] and again["mean_iterations"] == out["mean_iterations"]


@pytest.mark.parametrize("args,needle", [
    (["--cohort", "0"], "--cohort"),
    (["--cohort", "two"], "--cohort"),
    (["--link", "serial"], "--link"),
    (["--plot", "{tmp}/out.jpg"], "--plot"),
    (["--neck-weight", "-1"], "--neck-weight"),
])
def test_bad_arguments_give_one_line_and_exit_2(tmp_path, args, needle):
    r = gola("--json", str(tmp_path / "o.json"), "--quiet", *(a.format(tmp=tmp_path) for a in args))
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and needle in lines[0] and "Traceback" not in r.stderr
    assert not (tmp_path / "out.jpg").exists()


def test_unwritable_json_is_refused_before_the_run(tmp_path):
    r = gola("--json", str(tmp_path), "--cohort", "20", "--quiet")      # a directory
    assert r.returncode == 2
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and "--json" in lines[0] and "directory" in lines[0]


def _one(tmp_path, link):
    r = gola("--cohort", "1", "--seed", "4", "--json", str(tmp_path / f"{link}.json"), "--link", link, "--quiet")
    assert r.returncode == 0, r.stderr
    return json.loads((tmp_path / f"{link}.json").read_text())


@pytest.fixture(scope="module")
def in_process(tmp_path_factory):
    return _one(tmp_path_factory.mktemp("none"), "none")


@pytest.mark.parametrize("link", ["can", "mavlink"])
def test_over_the_robot_link_the_results_are_the_in_process_ones(tmp_path, in_process, link):
    outs = {"none": in_process, link: _one(tmp_path, link)}
    assert outs[link]["link"] == link
    assert outs[link]["cap"] == outs["none"]["cap"]
    # the same moves were accepted over the link as in process: at least one per GOLA iteration
    assert outs[link]["robot_moves"] == outs["none"]["robot_moves"] >= outs["none"]["per_participant"][0]["iterations"]


def _lifter_shipped() -> bool:
    manifest = json.loads((ROOT / "edge_runtime" / "assets" / "manifest.json").read_text())
    return any(m.get("arch") == "lifter" for m in manifest.get("models", []))


def test_vision_path_runs_with_the_shipped_lifter_or_says_it_is_missing(tmp_path):
    r = gola("--cohort", "1", "--seed", "0", "--json", str(tmp_path / "v.json"), "--vision", "--quiet")
    if _lifter_shipped():
        assert r.returncode == 0, r.stderr
        out = json.loads((tmp_path / "v.json").read_text())
        assert out["cap_from"].startswith("camera")
        assert all(len(out["per_participant"][0]["cap"][c]) == 3 for c in CONDITIONS)
    else:
        assert r.returncode == 2
        lines = r.stderr.strip().splitlines()
        assert len(lines) == 1 and "--vision" in lines[0] and "lifter" in lines[0]
