"""One TOML file configures the box; every mistake is named by file and key."""
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

from edge_runtime import config
from edge_runtime.config import BoxConfig, ConfigError

EXAMPLE = Path(__file__).resolve().parents[1] / "edge_runtime" / "box.example.toml"


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
        ("[detector]\npre_frames = 300\n", r"\[detector\] pre_frames: must be below window_frames"),
        ("[can\n", r"box.toml: not valid TOML"),
    ],
)
def test_bad_config_names_file_and_key(tmp_path, toml, match):
    p = tmp_path / "box.toml"
    p.write_text(toml)
    with pytest.raises(ConfigError, match=match):
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
    r = _cli("--config", str(p), "--print-config", "--min-confidence", "0.75")
    assert r.returncode == 0
    eff = tomllib.loads(r.stdout)
    assert eff["detector"]["threshold_mps2"] == 4.0 and eff["alerts"]["min_confidence"] == 0.75
    p.write_text("[can]\nbitrat = 1\n")
    r = _cli("--config", str(p), "--print-config")
    assert r.returncode == 2 and "bitrat" in r.stderr and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1


@pytest.mark.slow
def test_never_alert_must_name_model_classes(tmp_path):
    csv = tmp_path / "r.csv"
    csv.write_text("t,ax,ay,az\n" + "".join(f"{i / 100:.2f},0,0,9.81\n" for i in range(300)))
    p = tmp_path / "box.toml"
    p.write_text('[alerts]\nnever_alert = ["Othr"]\n')
    r = _cli("--config", str(p), "--replay", str(csv))
    assert r.returncode == 2 and "never_alert" in r.stderr and "Othr" in r.stderr


def test_every_section_and_key_is_in_the_example_file():
    example = tomllib.loads(EXAMPLE.read_text())
    cfg = BoxConfig()
    from dataclasses import asdict, fields

    regen = "regenerate it: python -m edge_runtime.config > edge_runtime/box.example.toml"
    for sec in fields(cfg):
        assert sec.name in example, f"[{sec.name}] missing from box.example.toml; {regen}"
        assert set(example[sec.name]) == set(asdict(getattr(cfg, sec.name))), f"[{sec.name}]: {regen}"
    # the robot-side sections are registered, and so are the other modules' when present
    assert {"robot_link", "camera", "calibration", "tracker", "zones", "robot_loop"} <= set(config.SECTION_TYPES)
    assert set(config.SECTION_TYPES) | set(config.MISSING_SECTIONS) == {name for name, _ in config.SECTIONS}


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
    assert config.override(cfg, "zones", sizing="iso15066").zones.r1_m == pytest.approx(cfg.zones.protective_distance_m)
