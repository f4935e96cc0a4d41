"""fuzz.merge: shard reports of one campaign joined into one table (``python -m fuzz merge``)."""
from __future__ import annotations

import json
import types

from hypothesis import strategies as st

from fuzz.__main__ import main
from fuzz.harness import run_target


def _shard(path, names, crash_every=0):
    """A shard file as ``python -m fuzz --json`` writes it, from real runs of tiny fake targets."""
    def run(n: int) -> None:
        if n < 0:
            raise ValueError("documented refusal")
        if crash_every and n % crash_every == 0:
            raise KeyError(n)

    reports = [run_target(types.SimpleNamespace(NAME=name, DOCUMENTED=(ValueError,), run=run,
                                                strategy=lambda: st.integers(-3, 20)), 40, seed=1) for name in names]
    path.write_text(json.dumps({"command": f"python -m fuzz --target {' --target '.join(names)}", "seed": 0,
                                "inputs_per_target": 40, "targets": [r.to_json() for r in reports]}))
    return reports


def test_shards_are_merged_into_one_table_with_their_commands_and_commit(tmp_path, capsys):
    a = _shard(tmp_path / "a.json", ["t1", "t3"])
    b = _shard(tmp_path / "b.json", ["t2"], crash_every=7)
    out_json, out_md = tmp_path / "fuzz.json", tmp_path / "fuzz.md"
    rc = main(["merge", str(tmp_path / "a.json"), str(tmp_path / "b.json"), "--commit", "abc1234",
               "--json", str(out_json), "--md", str(out_md)])
    assert rc == 1  # t2 crashed: the merged run is not clean either
    doc = json.loads(out_json.read_text())
    assert [t["name"] for t in doc["targets"]] == ["t1", "t2", "t3"] and doc["commit"] == "abc1234"
    assert len(doc["commands"]) == 2
    by_name = {t["name"]: t for t in doc["targets"]}
    for r in a + b:
        assert (by_name[r.name]["inputs"], by_name[r.name]["refused"], by_name[r.name]["crashes"]) == \
            (r.inputs, r.refused, r.crashes)
    md = out_md.read_text()
    assert "`python -m fuzz --target t1 --target t3`" in md and "`python -m fuzz --target t2`" in md
    assert "abc1234" in md and "KeyError" in md
    total = next(line for line in md.splitlines() if line.startswith("| **all**"))
    assert total.split(" | ")[1] == str(sum(r.inputs for r in a + b))


def test_a_target_in_two_shards_or_a_foreign_file_is_one_line_and_exit_2(tmp_path, capsys):
    _shard(tmp_path / "a.json", ["t1"])
    _shard(tmp_path / "b.json", ["t1"])
    assert main(["merge", str(tmp_path / "a.json"), str(tmp_path / "b.json")]) == 2
    assert "t1 is also in" in capsys.readouterr().err
    (tmp_path / "c.json").write_text('{"targets": [{"nom": 1}]}')
    assert main(["merge", str(tmp_path / "c.json")]) == 2
    err = capsys.readouterr().err
    assert "c.json: not a python -m fuzz --json report" in err and len(err.strip().splitlines()) == 1


def test_a_running_shard_is_read_from_its_log_with_the_targets_it_finished(tmp_path, capsys):
    done = _shard(tmp_path / "a.json", ["t1", "t2"], crash_every=7)
    log = tmp_path / "b.log"
    # the header a shard prints first, then one row per finished target, among warnings
    header = "  ".join(("target", "inputs", "refused", "crashes", "silent acceptances", "hangs", "inputs/s"))
    rows = [f"{r.name.replace('t', 'u')}  {r.inputs}  {r.refused}  {r.crashes}  0  0  1,234" for r in done]
    log.write_text("\n".join([header, "/x.py:1: RuntimeWarning: overflow", *rows, "  r = det(a)"]) + "\n")
    out = tmp_path / "fuzz.json"
    rc = main(["merge", str(tmp_path / "a.json"), str(log), "--command", "python -m fuzz --target t1 --target t2",
               "--command", "python -m fuzz --target u1 --target u2", "--json", str(out)])
    doc = json.loads(out.read_text())
    assert rc == 1 and [t["name"] for t in doc["targets"]] == ["t1", "t2", "u1", "u2"]
    u1 = doc["targets"][2]
    assert (u1["inputs"], u1["crashes"], u1["rate_per_s"]) == (done[0].inputs, done[0].crashes, 1234.0)
    assert doc["commands"][1] == "python -m fuzz --target u1 --target u2"
    (tmp_path / "c.log").write_text("nothing here\n")
    assert main(["merge", str(tmp_path / "c.log")]) == 2
    assert "no table header" in capsys.readouterr().err


def test_shards_of_different_commits_keep_each_targets_commit_and_name_the_targets_not_run(tmp_path, capsys):
    _shard(tmp_path / "a.json", ["t1"])
    _shard(tmp_path / "b.json", ["t2"])
    out_json, out_md = tmp_path / "fuzz.json", tmp_path / "fuzz.md"
    assert main(["merge", str(tmp_path / "a.json"), str(tmp_path / "b.json"), "--commit", "aaa1111",
                 "--commit", "bbb2222", "--json", str(out_json), "--md", str(out_md)]) == 0
    doc = json.loads(out_json.read_text())
    assert {t["name"]: t["commit"] for t in doc["targets"]} == {"t1": "aaa1111", "t2": "bbb2222"}
    assert "csv_replay" in doc["missing"]  # a real target of fuzz/targets that no shard ran
    md = out_md.read_text()
    assert "| t1 |" in md and "`aaa1111` |" in md and "Not in this report" in md
    assert main(["merge", str(tmp_path / "a.json"), str(tmp_path / "b.json"), "--commit", "a", "--commit", "b",
                 "--commit", "c"]) == 2
    assert "one per shard" in capsys.readouterr().err
