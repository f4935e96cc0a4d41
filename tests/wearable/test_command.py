"""wearable/command.py (``python -m edge_runtime wearable``), and the command table it is
registered in (edge_runtime/__main__.py, cli.run_command)."""
import argparse
import importlib
import json
import logging
import re
import subprocess
import sys

import can
import numpy as np
import pytest
from support.early_model import write_assets

from edge_runtime import __main__ as table
from edge_runtime.cli import run_command
from edge_runtime.errors import InputError, LinkError, ModelIntegrityError
from edge_runtime.wearable import command
from edge_runtime.wearable.alerts import AlertEncoder, WearableStatus
from edge_runtime.wearable.labels import CLASSES
from edge_runtime.wearable.loop import BATCH_CAPTURES, WearableLoop
from edge_runtime.wearable.mavlink_source import SourceStatus
from edge_runtime.wearable.sources import ImuBlock, ReplayStats

DECISION_KEYS = ["t_trigger_s", "t_alert_s", "label", "confidence", "alerted", "status", "probs", "compute_us",
                 "latency_ms", "alert_seq", "steps", "event_start_s"]


def _steps_csv(path, n=3000, steps=(1000,)):
    """A 100 Hz recording at rest with +6 m/s^2 steps on x: each one triggers the detector."""
    acc = np.tile([0.0, 0.0, 9.81], (n, 1))
    for t in steps:
        acc[t:, 0] += 6.0
    rows = "\n".join(f"{i / 100:.2f},{a:.3f},{b:.3f},{c:.3f}" for i, (a, b, c) in enumerate(acc))
    path.write_text("t,ax,ay,az\n" + rows + "\n")
    return path


# ---------------------------------------------------------------------------- the command table


def test_every_command_is_registered_through_its_module():
    sub = next(a for a in table.build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    assert list(sub.choices) == ["wearable", "lift", "robot"]
    for name, module, _ in table.COMMANDS:
        mod = importlib.import_module(f"edge_runtime.{module}")
        assert callable(mod.add_arguments) and isinstance(mod.BAD_INPUT, tuple)
        assert sub.choices[name].get_default("func") is mod.cmd
    args = table.build_parser().parse_args(["wearable", "--replay", "x.csv"])
    assert args.func is command.cmd and args.bad_input == command.BAD_INPUT


class Declared(Exception):
    """An exception a command declares in its BAD_INPUT."""


def _raise(exc):
    def func(args):
        raise exc
    return func


@pytest.mark.parametrize("exc", [InputError("bad.csv:3:\nnot a number"), ModelIntegrityError("model.onnx: sha256"),
                                 LinkError("cannot open CAN bus socketcand"), Declared("declared by the command")])
def test_run_command_makes_bad_input_and_link_errors_one_line_and_exit_2(exc, capsys):
    assert run_command(argparse.Namespace(func=_raise(exc), bad_input=(Declared,))) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("error: ") and " ".join(str(exc).split()) in err


def test_anything_else_is_a_bug_and_keeps_its_traceback():
    with pytest.raises(ZeroDivisionError):
        run_command(argparse.Namespace(func=_raise(ZeroDivisionError("bug")), bad_input=()))


def test_no_command_is_a_usage_error():
    with pytest.raises(SystemExit) as e:
        table.main([])
    assert e.value.code == 2


# ---------------------------------------------------------------------------- the wearable command


def test_replay_writes_each_decision_once_to_the_log_and_the_console(tmp_path, capsys):
    csv, log = _steps_csv(tmp_path / "steps.csv", n=4000, steps=(1000, 2000)), tmp_path / "alerts.jsonl"
    # one decision per capture (the dissertation's full window), so the lines pair up one to one; the early
    # path's several decisions per capture are tested in test_loop and tests/e2e
    assert table.main(["wearable", "--replay", str(csv), "--alerts", str(log), "--decision", "full_window"]) == 0
    out = capsys.readouterr().out.splitlines()
    decisions = [json.loads(line) for line in log.read_text().splitlines()]
    assert len(decisions) == 2 and all(list(d) == DECISION_KEYS for d in decisions)
    assert [d["t_trigger_s"] for d in decisions] == [10.0, 20.0]
    printed = out[:len(decisions)]
    for d, line in zip(decisions, printed):
        assert line.split()[2] == d["label"] and line.endswith("ALERT" if d["alerted"] else d["status"])
    assert out[len(decisions)].startswith("summary: 40.0 s of IMU data (4000 samples)")
    assert f"captures {len(decisions)} (full-window decisions" in out[len(decisions) + 1]


@pytest.mark.slow
def test_cli_reports_bad_csv_in_one_line_without_traceback(tmp_path):
    p = tmp_path / "bad.csv"
    p.write_text("t,ax,ay,az\n0,1,2,3\n0.01,1,2,oops\n")
    r = subprocess.run([sys.executable, "-m", "edge_runtime", "wearable", "--replay", str(p)], capture_output=True, text=True)
    assert r.returncode == 2
    assert r.stderr.strip().count("\n") == 0 and "bad.csv:3" in r.stderr and "Traceback" not in r.stderr


class Classifier:
    classes = CLASSES

    def classify_capture(self, x700):
        return np.eye(len(CLASSES), dtype=np.float32)[0]


class Publisher:
    """Stands in for AlertPublisher: the status, how many heartbeats went out at once, and the loop's turns
    at the periodic heartbeat."""

    def __init__(self):
        self.status, self.heartbeats, self.turns = WearableStatus(), 0, 0

    def beat_if_due(self):
        self.turns += 1

    def send_heartbeat(self):
        self.heartbeats += 1
        return True

    def publish_alert(self, alert):
        return 0

    def check_running(self):
        pass


class Live:
    """A live source's counters."""

    def __init__(self):
        self.stats = argparse.Namespace(saturated=2, dropped=7)


def test_drive_reports_each_change_of_the_sensor_once_and_stops_when_it_is_gone(caplog):
    pub = Publisher()
    loop = WearableLoop(Classifier(), publisher=pub)
    rest = np.tile(np.float32([0, 0, 9.81]), (10, 1))
    events = [SourceStatus("silent", 0.2), SourceStatus("silent", 0.25), ImuBlock(0.0, rest), ImuBlock(0.1, rest),
              SourceStatus("disconnected", 1.0), ImuBlock(0.2, rest)]
    source = command._Source(iter(events), ReplayStats(), live=Live())
    caplog.set_level(logging.INFO, logger="edge_runtime")
    command._drive(source, loop, outputs=[])
    lines = [(r.levelname, r.event, r.getMessage()) for r in caplog.records if getattr(r, "event", "") == "sensor_state"]
    assert lines == [("WARNING", "sensor_state", "sensor silent (0.20 s since the last sample)"),
                     ("INFO", "sensor_state", "sensor ok"),
                     ("WARNING", "sensor_state", "sensor disconnected (1.00 s since the last sample)")]
    assert pub.heartbeats == 3  # one at each change, at once
    assert pub.turns == 5  # and the periodic one offered at every event up to the disconnection
    counts = pub.status.counts()
    assert (counts.sensor, counts.samples, counts.saturated, counts.source_dropped) == ("disconnected", 20, 2, 7)


KEY_HEX = "0f" * 32


@pytest.mark.parametrize("spec, env, expect", [
    ("serial:/nonexistent/tty", {}, r"no signing key; give key=@FILE .* or add \?unsigned=yes"),
    (f"serial:/nonexistent/tty?key={KEY_HEX}", {}, r"a signing key on the command line is visible to every user"),
    ("serial:/nonexistent/tty?key=env:FUZZW_NO_SUCH_KEY", {}, r"environment variable FUZZW_NO_SUCH_KEY is not set"),
    ("serial:/nonexistent/tty?key=env:FUZZW_KEY", {"FUZZW_KEY": "zz" * 32}, r"\(variable FUZZW_KEY\) is not 64 hex"),
    ("serial:/nonexistent/tty?key=env:FUZZW_KEY", {"FUZZW_KEY": KEY_HEX}, r"cannot open IMU serial line"),
    ("serial:/nonexistent/tty?unsigned=yes", {}, r"cannot open IMU serial line"),
])
def test_the_imu_line_is_signed_unless_the_spec_says_unsigned(spec, env, expect, monkeypatch, capsys):
    for name, value in env.items():
        monkeypatch.setenv(name, value)
    assert table.main(["wearable", "--imu", spec]) == 2
    err = capsys.readouterr().err
    assert len([line for line in err.splitlines() if line.startswith("error")]) == 1
    assert re.search(expect, err) and KEY_HEX not in err and "Traceback" not in err
    assert ("is unsigned (unsigned=yes)" in err) == ("unsigned=yes" in spec)


def test_a_key_file_is_read_and_never_shown(tmp_path, capsys):
    key = tmp_path / "imu.key"
    key.write_text(KEY_HEX + "\n")
    assert table.main(["wearable", "--imu", f"serial:/nonexistent/tty?key=@{key}"]) == 2
    err = capsys.readouterr().err
    assert "cannot open IMU serial line '/nonexistent/tty'" in err and KEY_HEX not in err


def test_a_model_that_takes_partial_captures_makes_early_decisions_unless_full_window_is_asked(tmp_path, capsys):
    assets = write_assets(tmp_path / "assets", early={"steps": [2, 3, 4, 5, 6],
                                                      "min_confidence_by_steps": {"2": 0.5}})
    csv = _steps_csv(tmp_path / "steps.csv", n=4000, steps=(1000,))
    runs = {}
    for mode in ("early", "full_window"):
        log = tmp_path / f"{mode}.jsonl"
        assert table.main(["wearable", "--replay", str(csv), "--assets", str(assets), "--decision", mode,
                           "--alerts", str(log), "--can-log", str(tmp_path / f"{mode}.log")]) == 0
        runs[mode] = [json.loads(line) for line in log.read_text().splitlines()]
    out = capsys.readouterr().out
    early = [(d["status"], d["steps"], d["label"], d["alert_seq"], d["t_alert_s"]) for d in runs["early"]]
    assert early == [("preliminary", 2, "Phone", 0, 11.62), ("confirmed", 6, "Phone", 0, 15.99)]
    assert [(d["status"], d["steps"]) for d in runs["full_window"]] == [("alert", 6)]
    assert "early decisions after S = 2,3,4,5,6" in out and "PRELIMINARY  (after 2 of 6 sub-windows" in out
    enc = AlertEncoder()
    frames = [enc.decode(m) for m in can.LogReader(str(tmp_path / "early.log")) if m.arbitration_id == 0x3A0]
    assert [(f["AlertSeq"], str(f["Status"])) for f in frames] == [(0, "preliminary")] * 5 + [(0, "confirmed")] * 5


def test_the_min_confidence_flag_is_the_full_windows_threshold_before_the_models_manifest(capsys):
    assert table.main(["wearable", "--min-confidence", "0.7", "--decision", "full_window", "--print-config"]) == 0
    out = capsys.readouterr().out
    from edge_runtime.wearable.loop import AlertPolicy

    early = ", ".join(map(repr, AlertPolicy().min_confidence_by_steps[:-1]))  # the early steps keep the shipped ones
    assert "min_confidence = 0.7" in out and f"min_confidence_by_steps = [{early}, 0.7]" in out
    assert 'decision = "full_window"' in out


def test_the_box_decides_by_the_stream_unless_told_and_model_names_the_deciders_model(capsys):
    """As shipped the effective configuration says decision = "stream"; --model then names the streaming
    classifier ([stream] model), and the capture path's ConvLSTM with --decision early or full_window."""
    import tomllib

    def effective(*flags):
        assert table.main(["wearable", *flags, "--print-config"]) == 0
        return tomllib.loads(capsys.readouterr().out)

    shipped = effective()
    assert shipped["alerts"]["decision"] == "stream" and shipped["stream"]["model"] == "stream-int8"
    fp32 = effective("--model", "fp32")
    assert (fp32["stream"]["model"], fp32["model"]["name"]) == ("fp32", "int8")
    capture = effective("--decision", "early", "--model", "fp32")
    assert (capture["alerts"]["decision"], capture["model"]["name"], capture["stream"]["model"]) == (
        "early", "fp32", "stream-int8")


@pytest.mark.parametrize("flag", [["--threshold", "4.0"], ["--min-confidence", "0.7"]])
def test_a_capture_path_flag_without_the_capture_path_is_refused_in_one_line(capsys, flag):
    assert table.main(["wearable", *flag, "--print-config"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and flag[0] in err[0] and "--decision early" in err[0]
    assert table.main(["wearable", *flag, "--decision", "early", "--print-config"]) == 0


def _replayed(cfg, events, can_log):
    """Decisions (without their wall-clock compute time) and CAN frames of ``events`` driven as a replay."""
    from edge_runtime.wearable.classifier import Engine

    engine = Engine.from_manifest()
    pub = command._open_publisher(cfg, str(can_log), command._status_of(engine), data_clock=True)
    decisions = []
    try:
        loop = WearableLoop(engine, cfg.detector, cfg.alerts, publisher=pub)
        command._drive(command._Source(events, ReplayStats()), loop, [lambda d: decisions.append(d.to_json())])
    finally:
        pub.close()
    for d in decisions:
        d.pop("compute_us")
    frames = [(round(m.timestamp, 3), m.arbitration_id, bytes(m.data)) for m in can.LogReader(str(can_log))]
    return decisions, frames


def test_a_recording_fed_in_blocks_decides_as_sample_by_sample_and_beats_as_in_heartbeat_pieces(tmp_path):
    """The replay feeds whole blocks of finite samples. Its decisions are those of the live path (one
    sample at a time); its frames are those of feeding every heartbeat period on its own, which a
    heartbeat's counts are defined by (what was fed by its data time)."""
    from firmware_sim.devices.wrist import simulate_drive

    acc = np.ascontiguousarray(simulate_drive(3.0, seed=5).acc_mps2, dtype=np.float32)
    acc[9000:9030] = np.nan  # a run of bad samples: the detector restarts, a heartbeat says degraded
    cut = 12_345  # a gap of 2 s there: a new block that does not continue the previous one
    blocks = [ImuBlock(0.0, acc[:cut]), ImuBlock(cut / 100 + 2.0, acc[cut:], continuous=False)]

    def split(n):
        return [ImuBlock(b.t0_s + i / 100, b.acc_mps2[i : i + n], b.continuous or i > 0)
                for b in blocks for i in range(0, len(b.acc_mps2), n)]

    cfg = command.effective_config(argparse.Namespace(config=None, assets=None, model=None, threads=None,
                                                      min_confidence=None, decision="early", threshold=None))
    fast, fast_frames = _replayed(cfg, blocks, tmp_path / "blocks.log")
    per_sample, _ = _replayed(cfg, split(1), tmp_path / "samples.log")
    _, piece_frames = _replayed(cfg, split(10), tmp_path / "pieces.log")
    assert len(fast) >= 5 and any(d["alerted"] for d in fast)
    assert fast == per_sample
    beats = [f for f in fast_frames if f[1] == 0x3A1]
    assert beats == [f for f in piece_frames if f[1] == 0x3A1] and len(beats) >= 10 * 180
    degraded = [t for t, i, d in beats if str(AlertEncoder().decode(can.Message(arbitration_id=i, data=d))["State"])
                == "degraded"]
    gap_s = cut / 100 + 2.0
    assert degraded and all(90.0 < t <= 90.4 or gap_s < t <= gap_s + 0.1 for t in degraded)  # bad samples, the gap
    assert any(t > gap_s for t in degraded)

    def alerts(frames):  # TimeSinceTrigger counts wall-clock compute time: counter and status, class, confidence, AlertSeq
        return [(t, d[1:4] + d[6:8]) for t, i, d in frames if i == 0x3A0]

    assert alerts(fast_frames) == alerts(piece_frames)


class _PerCapture:
    """The shipped classifier without its batch call: the loop asks it once per capture and step, as
    a live box does."""

    def __init__(self, engine):
        self.engine, self.classes, self.early = engine, engine.classes, engine.early
        self.early_steps, self.entry = engine.early_steps, engine.entry
        self.classify_prefix, self.classify_capture = engine.classify_prefix, engine.classify_capture


def test_a_replay_classifies_a_block_s_captures_together_and_decides_as_one_call_per_capture(tmp_path, monkeypatch):
    """``--replay FILE.imu`` hands the loop blocks of many captures and the loop classifies them in
    one model run per step; its --alerts lines (without the wall-clock fields) are those of the
    per-capture path on the same recording, every probability included."""
    from edge_runtime.wearable.classifier import Engine
    from edge_runtime.wearable.recording import RecordingWriter
    from firmware_sim.devices.wrist import simulate_drive

    acc = np.ascontiguousarray(simulate_drive(30.0, seed=11).acc_mps2, dtype=np.float32)
    imu = tmp_path / "d.imu"
    w = RecordingWriter(imu)
    w.write(ImuBlock(0.0, acc))
    w.close()
    batches = []
    groups = Engine.classify_capture_groups

    def counted(self, asked):
        batches.append(sum(len(captures) for captures, _ in asked))
        return groups(self, asked)

    monkeypatch.setattr(Engine, "classify_capture_groups", counted)
    assert table.main(["wearable", "--replay", str(imu), "--decision", "early", "--alerts", str(tmp_path / "a.jsonl"),
                       "--quiet"]) == 0
    replayed = [json.loads(line) for line in (tmp_path / "a.jsonl").read_text().splitlines()]
    monkeypatch.undo()
    cfg = command.effective_config(argparse.Namespace(config=None, assets=None, model=None, threads=None,
                                                      min_confidence=None, decision="early", threshold=None))
    per_capture = []
    command.replay(cfg, _PerCapture(command._load_classifier(cfg)), acc, [lambda d: per_capture.append(d.to_json())])
    for d in replayed + per_capture:
        d.pop("compute_us"), d.pop("latency_ms")
    steps = {d["steps"] for d in replayed}
    assert len(replayed) >= 100 and {"preliminary", "continued", "confirmed"} <= {d["status"] for d in replayed}
    assert steps >= {2, 6} and max(batches) == BATCH_CAPTURES  # many captures in one run
    assert replayed == per_capture


@pytest.mark.slow
@pytest.mark.parametrize("given", [None, "3"])
def test_the_wearable_command_keeps_openblas_on_one_thread_unless_told(given):
    """The wearable command sets OPENBLAS_NUM_THREADS=1 before numpy loads (its products are small, a
    thread pool only costs CPU); a value the environment gives is kept; a process that merely imports
    the wearable's modules (the bench's parent, an evaluation) is left alone and passes nothing on."""
    import os

    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    if given is not None:
        env["OPENBLAS_NUM_THREADS"] = given
    code = ("import builtins, os, sys\n"
            "seen, real = [], builtins.__import__\n"
            "def spy(name, *a, **k):\n"
            "    if name == 'numpy' and 'numpy' not in sys.modules and not seen:\n"
            "        seen.append(os.environ.get('OPENBLAS_NUM_THREADS'))\n"
            "    return real(name, *a, **k)\n"
            "builtins.__import__ = spy\n"
            "from edge_runtime.__main__ import main\n"
            "main(['wearable', '--print-config'])\n"
            "print(seen[0])\n")
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
    assert out.split()[-1] == (given or "1")  # set before numpy was imported
    code = "import os, edge_runtime.wearable.sources; print(os.environ.get('OPENBLAS_NUM_THREADS'))"
    out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True).stdout
    assert out.split() == [str(given)]


def test_a_live_box_that_cannot_parse_the_dbc_stops_at_start_with_its_bus_shut(tmp_path, monkeypatch, caplog):
    """A live publisher parses the DBC when it is made: a missing cantools is the command's one line at start (exit 2),
    and the bus opened for it is shut, not left for python-can to warn about at exit."""
    import gc

    import can

    from edge_runtime import config
    from edge_runtime.wearable import alerts

    def no_cantools():
        raise ModuleNotFoundError("No module named 'cantools'", name="cantools")

    monkeypatch.setattr(alerts, "load_vehicle_dbc", no_cantools)
    box = tmp_path / "box.toml"
    box.write_text('[can]\ninterface = "virtual"\nchannel = "no-dbc"\n')
    with pytest.raises(ModuleNotFoundError):
        command._open_publisher(config.load(box), None, WearableStatus())
    gc.collect()  # a bus nobody shut is shut by python-can's finaliser, which warns
    assert not can.interfaces.virtual.channels.get("no-dbc")
    assert not [r for r in caplog.records if "not properly shut down" in r.getMessage()]
