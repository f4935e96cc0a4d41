"""One TOML file configures the box; every mistake is named by file and key."""
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from edge_runtime import config
from edge_runtime.__main__ import load_all_sections
from edge_runtime.config import ConfigError

EXAMPLE = Path(__file__).resolve().parents[1] / "edge_runtime" / "box.example.toml"

load_all_sections()  # every component declares its section: the whole box's file is validated here
BoxConfig = config.box_config_type()


def test_example_file_is_the_defaults_and_print_config_round_trips(tmp_path):
    assert config.load(EXAMPLE) == BoxConfig()
    cfg = config.from_dict({"can": {"interface": "socketcand", "port": 4000}, "alerts": {"min_confidence": 0.8}})
    again = config.from_dict(tomllib.loads(cfg.to_toml()))
    assert again == cfg and again.can.port == 4000 and again.alerts.never_alert == ("Other",)


@pytest.mark.parametrize(
    "toml, match",
    [
        ("[can]\nbitrat = 5\n", r"box.toml: \[can\] bitrat: unknown key"),
        ("[cann]\n", r"box.toml: \[cann\]: unknown section"),
        ("[can]\nbitrate = \"fast\"\n", r"\[can\] bitrate: expected an integer"),
        ("[can]\ninterface = \"udp\"\n", r"\[can\] interface: must be one of virtual, socketcand"),
        ("[alerts]\nmin_confidence = 1.5\n", r"\[alerts\] min_confidence: must be a number in \[0, 1\]"),
        ("[model]\nthreads = 0\n", r"\[model\] threads: must be an integer of at least 1"),
        ("[imu]\nsample_rate_hz = 50\n", r"\[imu\] sample_rate_hz: must be 100"),
        ("[detector]\npre_frames = 300\n", r"\[detector\] pre_frames: must be 100"),
        ("[detector]\npost_frames = 700\n", r"\[detector\] post_frames: must be 600"),
        ("[alerts]\nclass_weights = [5e-324, 1, 1, 1, 1, 1]\n", r"\[alerts\] class_weights: must be"),
        ("[can\n", r"box.toml: not valid TOML"),
        # the limits that README, the DBC and docs/integrator.md promise (issue 16)
        ("[imu]\nsilence_timeout_s = 3600\n", r"\[imu\] silence_timeout_s: must be a number in \[0.02, 0.15\] s"),
        ("[imu]\nsilence_timeout_s = 0.2\n", r"\[imu\] silence_timeout_s: must be a number in \[0.02, 0.15\]"),
        ("[can]\nheartbeat_period_s = 10.0\n", r"\[can\] heartbeat_period_s: must be a number in \[0.01, 0.1\] s"),
        ("[imu]\nrange_mps2 = 1e300\n", r"\[imu\] range_mps2: must be a number in \[19.6, 1000\]"),
        ('[alerts]\nnever_alert = ["Phone", "Texting", "TouchScreen", "Drink", "Marker", "Other"]\n',
         r"\[alerts\] never_alert: .* holds every class"),
        # the streaming decider's (issue 12)
        ('[alerts]\ndecision = "streaming"\n', r"\[alerts\] decision: must be one of early, full_window, stream"),
        ("[stream]\nhop_s = 0.5\n", r"\[stream\] hop_s: must be a multiple of 0.04 s in \[0.04, 10\] s, got 0.5"),
        ("[stream]\nwindow_s = 0.4\n", r"\[stream\] window_s: must be a multiple of 0.04 s in \[0.64, 30\] s"),
        ('[stream]\nscore = "max"\n', r"\[stream\] score: must be top or any"),
        ("[stream]\nthreshold = 1.2\n", r"\[stream\] threshold: must be a number in \[0, 1\]"),
        ("[stream]\nconsecutive_hops = 0\n", r"\[stream\] consecutive_hops: must be an integer in 1..100"),
        ("[stream]\nhops = 3\n", r"box.toml: \[stream\] hops: unknown key"),
        # what a parser meets from a fuzzer: one line, never a traceback
        ("[detector]\nwindow_frames = " + "9" * 400 + "\n", r"\[detector\] window_frames: expected an integer, got 9+\.\.\.$"),
        ("[imu]\nrange_mps2 = " + "9" * 400 + "\n", r"\[imu\] range_mps2: expected a number"),
        ("a = " + "[" * 5000 + "\n", r"box.toml: not a usable TOML file \(RecursionError"),
    ],
)
def test_bad_config_names_file_and_key(tmp_path, toml, match):
    p = tmp_path / "box.toml"
    p.write_text(toml)
    with pytest.raises(ConfigError, match=match):
        config.load(p)


def test_non_utf8_config_is_one_line_naming_the_byte(tmp_path):
    p = tmp_path / "box.toml"
    p.write_bytes(b"[imu]\n\xff = 1\n")
    with pytest.raises(ConfigError, match=r"box.toml: not UTF-8 \(byte 6\)"):
        config.load(p)


def test_command_line_overrides_file_and_is_validated_the_same_way(tmp_path):
    p = tmp_path / "box.toml"
    p.write_text("[model]\nthreads = 2\n[alerts]\nmin_confidence = 0.7\n")
    cfg = config.override(config.load(p), "alerts", min_confidence=0.9)
    assert cfg.alerts.min_confidence == 0.9 and cfg.model.threads == 2
    with pytest.raises(ConfigError, match="command line: \\[model\\] threads"):
        config.override(cfg, "model", threads=-1)


def _cli(*args):
    return subprocess.run([sys.executable, "-m", "edge_runtime", "wearable", *args], capture_output=True, text=True)


@pytest.mark.slow
def test_cli_print_config_and_one_line_error(tmp_path):
    p = tmp_path / "box.toml"
    p.write_text("[detector]\nthreshold_mps2 = 4.0\n")
    r = _cli("--config", str(p), "--print-config")
    assert r.returncode == 0 and tomllib.loads(r.stdout)["alerts"]["decision"] == "stream"  # as shipped
    r = _cli("--config", str(p), "--print-config", "--decision", "early", "--min-confidence", "0.75")
    assert r.returncode == 0
    eff = tomllib.loads(r.stdout)
    assert eff["detector"]["threshold_mps2"] == 4.0 and eff["alerts"]["min_confidence"] == 0.75
    assert eff["alerts"]["decision"] == "early"
    p.write_text("[can]\nbitrat = 1\n")
    r = _cli("--config", str(p), "--print-config")
    assert r.returncode == 2 and "bitrat" in r.stderr and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


@pytest.mark.slow
def test_never_alert_must_name_model_classes(tmp_path):
    csv = tmp_path / "r.csv"
    csv.write_text("t,ax,ay,az\n" + "".join(f"{i / 100:.2f},0,0,9.81\n" for i in range(300)))
    p = tmp_path / "box.toml"
    p.write_text('[alerts]\ndecision = "early"\nnever_alert = ["Othr"]\n')  # the capture path's key
    r = _cli("--config", str(p), "--replay", str(csv))
    assert r.returncode == 2 and "never_alert" in r.stderr and "Othr" in r.stderr


def test_the_example_file_is_generated_from_every_declared_section():
    regen = "regenerate it: python -m edge_runtime.config > edge_runtime/box.example.toml"
    assert tuple(config.registered()) == config.BOX_SECTIONS, "a section is declared but not in BOX_SECTIONS"
    assert EXAMPLE.read_text() == config.example_toml(), regen
    example = tomllib.loads(EXAMPLE.read_text())
    assert tuple(example) == config.BOX_SECTIONS


def test_a_section_is_declared_once_by_a_frozen_dataclass_with_defaults():
    from dataclasses import dataclass

    with pytest.raises(ValueError, match="not a box section"):
        config.section("zonez")
    with pytest.raises(TypeError, match="frozen"):
        config.section("zones")(dataclass(type("Mutable", (), {"__annotations__": {"x": int}, "x": 1})))
    with pytest.raises(ValueError, match="declared twice"):
        config.section("zones")(dataclass(frozen=True)(type("Other", (), {"__annotations__": {"x": int}, "x": 1})))


PROBE = """
import json, sys
from edge_runtime import config
from edge_runtime.wearable import command
box = sys.argv[1]
cfg = command.effective_config(type("Args", (), dict(config=box, assets=None, model=None, threads=None,
                                                     min_confidence=None, threshold=None))())
print(json.dumps({"sections": [f for f in cfg.__dataclass_fields__],
                  "robot_or_posture_loaded": sorted(m for m in sys.modules
                                                    if m.startswith(("edge_runtime.robot", "edge_runtime.posture")))}))
"""


@pytest.mark.slow
def test_the_wearable_reads_the_shared_file_without_loading_the_robot_side(tmp_path):
    """A wearable box validates its own sections; the robot's sections in the same file are the
    robot command's to check, and reading them loads neither the lifter nor the posture code."""
    import json

    box = tmp_path / "box.toml"
    box.write_text("[detector]\nthreshold_mps2 = 4.0\n[zones]\nnot_a_key = 1\n")
    r = subprocess.run([sys.executable, "-c", PROBE, str(box)], capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    assert out["sections"] == ["imu", "detector", "model", "alerts", "stream", "can"]
    assert out["robot_or_posture_loaded"] == []
    with pytest.raises(ConfigError, match=r"\[zones\] not_a_key: unknown key"):
        config.load(box)  # this process has the robot side loaded: the section is checked


@pytest.mark.parametrize(
    "toml, match",
    [
        ("[zones]\nR2 = 1\n", r"\[zones\] R2: unknown key"),
        ("[zones]\nsizing = \"big\"\n", r"\[zones\] sizing: must be eq45 or iso15066"),
        ("[zones]\nstale_after_s = 2.0\n", r"\[zones\] stale_after_s: must be a number in \(0, 1\]"),
        ("[robot_loop]\ntask_waypoints_m = [[0.1, 0.2]]\n", r"\[robot_loop\] task_waypoints_m: expected a list of "
                                                            r"\[number, number, number\] lists"),
        ("[robot_loop]\ntask_waypoints_m = []\n", r"\[robot_loop\] task_waypoints_m: must be at least one"),
        ("[calibration]\nmarkers_xz_m = [[0, 1], [1, 1]]\n", r"\[calibration\] markers_xz_m: must be three"),
        ("[robot_link]\nserial = \"/dev/ttyS0\"\n", r"\[robot_link\] serial: must be empty or serial:PATH"),
    ],
)
def test_robot_sections_are_validated_like_the_rest(tmp_path, toml, match):
    p = tmp_path / "box.toml"
    p.write_text(toml)
    with pytest.raises(ConfigError, match=match):
        config.load(p)


def test_robot_sections_round_trip_through_print_config():
    cfg = config.from_dict({"robot_loop": {"task_waypoints_m": [[0.3, 0.1, 0.6], [0, 0.1, 0.9]]},
                            "calibration": {"markers_xz_m": [[0, 1], [2, 1], [0, 3]], "method": "eq2"}})
    again = config.from_dict(tomllib.loads(cfg.to_toml()))
    assert again == cfg and again.robot_loop.task_waypoints_m == ((0.3, 0.1, 0.6), (0.0, 0.1, 0.9))
    assert again.calibration.markers_xz_m[1] == (2.0, 1.0)
    iso = config.override(cfg, "zones", sizing="iso15066").zones
    assert iso.r1_m == pytest.approx(max(cfg.zones.protective_distance_m, iso.r2_m))  # S_p, never inside R2


def test_print_config_redacts_an_inline_signing_key(tmp_path):
    key = "ab" * 32
    p = tmp_path / "box.toml"
    p.write_text(f'[robot_link]\nkind = "mavlink"\nserial = "serial:/dev/ttyS1?key={key}"\n')
    text = config.load(p).to_toml()
    assert key not in text and 'serial = "serial:/dev/ttyS1?key=<redacted>"' in text
    p.write_text('[robot_link]\nkind = "mavlink"\nserial = "serial:/dev/ttyS1?key=@/etc/box/arm.key"\n')
    assert 'key=@/etc/box/arm.key"' in config.load(p).to_toml()  # a file name is not a secret
