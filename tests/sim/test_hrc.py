"""The closed-loop proof ``python -m firmware_sim hrc``: world, judging, JSON contract, bad input."""
from __future__ import annotations

import json
import math
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from edge_runtime.robot.hazard import ZoneParams
from edge_runtime.robot.loop import LoopParams
from firmware_sim.scenarios import hrc
from firmware_sim.scenarios.hrc_hard import COCO_SIGMAS_H36M, PERSON_SCALE_OF_HEIGHT, HardNoise, coco_noise, occlude
from firmware_sim.scenarios.hrc_world import (
    CAMERA_6M,
    HardParams,
    RandomParams,
    RunResult,
    Scenario,
    TruthPerception,
    WorldParams,
    clearance_m,
    dissertation_scenarios,
    hard_scenarios,
    path_base_distance,
    random_scenarios,
    run_scenario,
)

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "edge_runtime" / "box.example.toml"
VALIDATED = ROOT / "reports" / "hrc" / "validated.json"
ASSETS = ROOT / "edge_runtime" / "assets"
CONTRACT_KEYS = ("scenarios", "collisions", "min_separation_m", "stops", "retracts", "false_alarms", "reaction_ms")


@pytest.fixture(scope="module")
def front():
    return next(s for s in dissertation_scenarios(0) if s.name == "front")


@pytest.fixture(scope="module")
def baseline_front(front):
    return run_scenario(front, "can", runtime=False).summary


def test_without_the_runtime_the_worker_walks_into_the_tool(baseline_front):
    # the check can fail: an arm that never sees the worker is hit
    assert baseline_front["collision"]
    assert baseline_front["min_separation_m"] < 0.10
    assert baseline_front["stops"] == 0 and baseline_front["retracts"] == 0
    assert baseline_front["max_state"] == "NORMAL"
    # nothing commands the arm: it stood still from the start until he walked into it
    assert baseline_front["arm_still_at_contact_s"] == pytest.approx(baseline_front["first_collision_s"])


def test_collisions_say_whether_the_arm_was_still_moving(baseline_front):
    """A collision into an arm that had stood still for STILL_BEFORE_CONTACT_S (a worker reaching into a
    stopped, retracted arm) is counted apart from one with the arm moving; both are collisions."""
    moving = {**baseline_front, "name": "moving", "arm_still_at_contact_s": 0.0}
    just = {**baseline_front, "name": "just stopped", "arm_still_at_contact_s": hrc.STILL_BEFORE_CONTACT_S - 0.1}
    resumed = {**baseline_front, "name": "resumed", "arm_moved_in_contact": True}  # still at first, then into him
    clear = {**baseline_front, "name": "clear", "collision": False, "collision_steps": 0,
             "first_collision_s": None, "arm_still_at_contact_s": None, "arm_moved_in_contact": False}
    empty = np.empty(0)
    out = hrc.summarize([RunResult(s, empty, empty, empty, empty)
                         for s in (baseline_front, moving, just, resumed, clear)], {})
    assert not baseline_front["arm_moved_in_contact"]
    assert out["collisions"] == 4 and out["collisions_arm_moving"] == 3
    assert out["arm_still_at_contact_s"]["just stopped"] == hrc.STILL_BEFORE_CONTACT_S - 0.1


HEAD_BOX = replace(hrc.load_box(), zones=replace(ZoneParams(), separation="head"))
"""The dissertation's head-to-effector zones (``--protection head``)."""


@pytest.mark.parametrize("link", ["can", "mavlink"])
def test_the_runtime_stops_and_retracts_in_time_on_both_links(front, baseline_front, link):
    s = run_scenario(front, link, runtime=True, perception="truth", box=HEAD_BOX).summary
    assert not s["collision"], s
    assert s["min_separation_m"] > 0.10
    assert s["min_separation_m"] > baseline_front["min_separation_m"] + 0.2
    assert s["stops"] >= 1 and s["retracts"] >= 1
    assert s["max_state"] == "LEVEL2"
    assert s["false_alarms"] == 0
    # both zone levels were entered, each with the true worker inside its radius (+ margin)
    assert [e["level"] for e in s["zone_entries"]][:2] == ["LEVEL1", "LEVEL2"]
    assert s["reaction_ms"]["n"] >= 2 and s["reaction_ms"]["median"] > 0
    # the head the runtime saw (detector noise at the true depth) is within centimetres of the truth
    assert 0.005 < s["head_error_m"]["median"] < 0.1


def test_whole_body_speed_scaling_keeps_the_arm_clear_and_working_longer(front, baseline_front):
    scaled = run_scenario(front, "can", runtime=True, perception="truth").summary
    head = run_scenario(front, "can", runtime=True, perception="truth", box=HEAD_BOX).summary
    assert not scaled["collision"] and scaled["min_separation_m"] > baseline_front["min_separation_m"] + 0.2
    assert scaled["retracts"] >= 1                                    # he walks at the tool: it retracts
    assert scaled["productive_time_share"] > head["productive_time_share"] > 0.0
    assert 0 < scaled["productive_s"] < scaled["scenario_s"] and scaled["worker_s"] == pytest.approx(
        scaled["scenario_s"], abs=0.05)
    # the time per monitor state adds up to the scenario; NORMAL is the productive time; halted time is by reason
    assert sum(scaled["state_s"].values()) == pytest.approx(scaled["scenario_s"], abs=0.05)
    assert scaled["state_s"]["NORMAL"] == pytest.approx(scaled["productive_s"], abs=1e-6)
    assert scaled["state_s"]["LEVEL2"] > 0 and "level2_retract" in scaled["halt_s"]
    assert sum(scaled["halt_s"].values()) == pytest.approx(scaled["scenario_s"] - scaled["productive_s"], abs=0.05)


def test_clearance_measures_to_sphere_surfaces_and_the_end_effector():
    centres = np.array([[0.0, 0.0, 1.0]])
    radii = np.array([0.1])
    joints = np.full((17, 3), 10.0)
    joints[3] = [0.0, 0.0, 1.25]                      # 0.15 m from the sphere's surface
    assert clearance_m(joints, centres, radii, np.array([5.0, 5.0, 5.0])) == pytest.approx(0.15)
    joints[5] = [5.0, 5.05, 5.0]                      # 0.05 m from the end effector
    assert clearance_m(joints, centres, radii, np.array([5.0, 5.0, 5.0])) == pytest.approx(0.05)


def test_random_scenarios_are_reproducible_and_avoidable():
    a = random_scenarios(40, seed=3, max_speed_mps=1.4)
    b = random_scenarios(40, seed=3, max_speed_mps=1.4)
    assert [s.describe() for s in a] == [s.describe() for s in b]
    assert {s.kind for s in a} == {"pass", "stop"}
    for s in a:
        assert 0.5 <= s.speed_mps <= 1.4
        assert path_base_distance(s.waypoints_xz_m) >= RandomParams().min_base_distance_m - 1e-9
        start = np.asarray(s.waypoints_xz_m[0])
        assert 2.9 <= np.linalg.norm(start - (0.0, 1.0)) <= 6.1 or s.kind == "pass"
        eye = np.asarray(s.camera_eye_m)
        assert 1.0 - 0.914 - 1e-6 <= eye[1] <= 3.0 - 0.914 + 1e-6
    assert random_scenarios(40, seed=4)[0].describe() != a[0].describe()


def test_path_base_distance():
    assert path_base_distance(((-3.0, 1.5), (3.0, 1.5))) == pytest.approx(1.5)
    assert path_base_distance(((2.0, 0.0), (5.0, 0.0))) == pytest.approx(2.0)


def test_truth_perception_holds_a_missed_joint_then_reports_the_frame_invalid():
    from firmware_sim.devices.camera import PERFECT, detect

    sc = Scenario("t", ((0.0, 3.0), (0.0, 2.0)), 1.0, camera_eye_m=CAMERA_6M[0], camera_target_m=CAMERA_6M[1])
    cam = sc.camera(30.0)
    from firmware_sim.people import human

    j = human.joints(human.Body.from_height(1.75), human.Posture(), pelvis_xz_m=(0.0, 2.0))
    J = np.repeat(j[None], 8, axis=0)
    kp = detect(cam, J, np.random.default_rng(0), PERFECT)
    kp[2:, 10, :2] = np.nan                            # the head is missed from frame 2 on
    kp[2:, 10, 2] = 0.0
    world = WorldParams(depth_noise_m=0.0)
    p = TruthPerception(cam, J, kp, world, 1.0, np.random.default_rng(1))
    outs = [p.push(k, k / 30.0) for k in range(8)]
    assert outs[0].valid and np.allclose(outs[0].joints_cam_m, j, atol=1e-6)   # robot frame, exact
    assert all(o.valid for o in outs[:2 + world.hold_frames])                 # held for 3 frames
    assert not outs[2 + world.hold_frames].valid
    assert outs[2 + world.hold_frames].reason.startswith("missing_joints")
    kp[:, :, :2] = np.nan
    p2 = TruthPerception(cam, J, kp, world, 1.0, np.random.default_rng(1))
    assert p2.push(0, 0.0).reason.startswith("no_person")


def test_cli_writes_the_contract_json_and_the_figure(tmp_path, capsys):
    from firmware_sim.__main__ import main

    out, png = tmp_path / "hrc.json", tmp_path / "hrc.png"
    rc = main(["hrc", "--scenario", "front", "--link", "mavlink", "--seed", "2", "--perception", "truth",
               "--json", str(out), "--plot", str(png), "--quiet"])
    assert rc == 0
    d = json.loads(out.read_text())
    for key in CONTRACT_KEYS:
        assert key in d, key
    assert d["scenarios"] == 1 and d["link"] == "mavlink" and d["perception"] == "truth"
    assert set(d["reaction_ms"]) >= {"median", "p99"}
    det = d["details"][0]
    for key in ("name", "link", "speed_mps", "camera_hz", "perception", "collision", "min_separation_m", "stops",
                "retracts", "false_alarms", "max_state"):
        assert key in det, key
    assert d["min_separation_m"] == det["min_separation_m"]
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "front" in capsys.readouterr().out


def test_format_table_lists_every_scenario_and_the_baseline():
    result = {"link": "can", "camera_hz": 30.0, "perception": "truth", "zones": {"r1_m": 4.4, "r2_m": 2.4},
              "scenarios": 2, "collisions": 0, "reaction_ms": {"median": 0.2, "p99": 0.5},
              "details": [{"name": n, "speed_mps": 1.4, "max_state": "LEVEL2", "stops": 1, "retracts": 1,
                           "false_alarms": 0, "min_separation_m": 0.4, "collision": False} for n in ("a", "b")],
              "baseline": {"collisions": 1, "details": [{"name": "a", "min_separation_m": 0.05, "collision": True}]}}
    table = hrc.format_table(result)
    assert table.count("\n") >= 4
    assert "YES" in table and "0/2" in table and "1/2" in table


@pytest.mark.parametrize("argv, needle", [
    (["--scenario", "random:0"], "random:N"),
    (["--scenario", "hard:x"], "hard:N"),
    (["--protection", "fast"], "--protection"),
    (["--scenario", "sideways"], "--scenario"),
    (["--max-speed", "3"], "--max-speed"),
    (["--link", "usb"], "--link"),
    (["--camera-hz", "-5"], "--camera-hz"),
    (["--json", "/nonexistent-dir/x.json"], "--json"),
    (["--loop", "no_such_field=1"], "--loop"),
    (["--zone", "predict_s=soon"], "--zone"),
    (["--config", "/nonexistent-dir/box.toml"], "box.toml"),
])
def test_bad_arguments_are_one_line_and_exit_2(argv, needle, capsys):
    from firmware_sim.__main__ import main

    try:
        rc = main(["hrc", "--quiet", *argv])
    except SystemExit as e:
        rc = e.code
    err = capsys.readouterr().err.strip()
    assert rc == 2
    assert len(err.splitlines()) == 1 and needle in err
    assert "Traceback" not in err


def test_the_cell_runs_the_shipped_box_configuration():
    # one source of truth: what hrc runs by default is what the box ships
    box = hrc.load_box()
    z = box.zones
    assert z == ZoneParams() and box.robot_loop == LoopParams()
    assert z.r2_m == pytest.approx(z.worker_speed_mps * (z.retract_time_s - z.predict_s) + z.margin2_m)
    shipped = tomllib.loads(EXAMPLE.read_text())
    assert shipped["zones"]["retract_time_s"] == z.retract_time_s
    assert hrc.config_dict(box, ["zones"])["zones"] == shipped["zones"]


def test_the_json_records_the_configuration_it_ran(tmp_path):
    from firmware_sim.__main__ import main

    box_toml = tmp_path / "box.toml"
    box_toml.write_text("[zones]\nretract_time_s = 1.5\n[tracker]\nwindow_s = 0.4\n")
    out = tmp_path / "hrc.json"
    assert main(["hrc", "--scenario", "front", "--perception", "truth", "--config", str(box_toml),
                 "--json", str(out), "--quiet"]) == 0
    d = json.loads(out.read_text())
    assert d["config"]["zones"]["retract_time_s"] == 1.5 and d["config"]["tracker"]["window_s"] == 0.4
    assert d["zones"]["r2_m"] == pytest.approx(1.4 * (1.5 - 0.5) + 0.3)
    assert d["safety_sha256"] != hrc.safety_sha256(hrc.load_box())
    ran = hrc.load_box(str(box_toml))
    assert d["config_sha256"] == hrc.config_sha256(ran)
    assert d["safety_sha256"] == hrc.safety_sha256(ran)
    assert d["lifter_model"] == hrc.lifter_model(ran) and len(d["lifter_model"]["sha256"]) == 64


def test_a_validation_record_is_kept_per_safety_configuration(tmp_path):
    rec_path = tmp_path / "validated.json"
    shipped = hrc.load_box()
    out = {k: 0 for k in hrc.VALIDATED_KEYS} | {"scenario": "front", "link": "can", "max_speed_mps": 2.0,
                                                "perception": "lifter", "camera_hz": 30.0,
                                                "protection": "speed_scaled",
                                                "config": hrc.config_dict(shipped),
                                                "lifter_model": hrc.lifter_model(shipped),
                                                "safety_sha256": hrc.safety_sha256(shipped)}
    hrc.record_validation(out, rec_path, "cmd a")
    rec = hrc.record_validation({**out, "link": "mavlink"}, rec_path, "cmd b")
    assert len(rec["runs"]) == 2 and rec["must_hold_met"]
    collided = hrc.record_validation({**out, "scenario": "hard:200", "collisions": 1}, rec_path, "cmd d")
    assert len(collided["runs"]) == 3 and not collided["must_hold_met"]   # one run that collided says so
    other = hrc.record_validation({**out, "safety_sha256": "0" * 64}, rec_path, "cmd c")
    assert list(other["runs"]) == ["front can 2mps lifter 30hz speed_scaled"]   # the old figures do not carry over


def test_a_new_lifter_model_voids_the_validation(tmp_path):
    """The safety hash covers the lifter the box runs (its manifest entry's sha256), not only the
    settings: a retrained lifter behind an unchanged configuration is a new cell to validate."""
    box = hrc.load_box()
    shipped = json.loads((ASSETS / "manifest.json").read_text())
    entry = next(m for m in shipped["models"] if m["name"] == hrc.lifter_model(box)["name"])
    assert entry["sha256"] == hrc.lifter_model(box)["sha256"]
    (tmp_path / "manifest.json").write_text(json.dumps(shipped))
    assert hrc.safety_sha256(box, tmp_path) == hrc.safety_sha256(box)
    entry["sha256"] = "0" * 64
    (tmp_path / "manifest.json").write_text(json.dumps(shipped))
    assert hrc.lifter_model(box, tmp_path)["sha256"] == "0" * 64
    assert hrc.safety_sha256(box, tmp_path) != hrc.safety_sha256(box)


PENDING_REVALIDATION: dict = {}
"""Shipped defaults changed (or keys added) since reports/hrc/validated.json, whose re-validation (the hrc suites
on a fresh seed) is still to run; empty when the shipped defaults are the measured ones. (Session 10 listed
``[calibration] method = "pnp"`` here; its validation on seed 11 failed and the default went back. Session 12
measured the escape turn's keys on fresh seed 17; session 13 ``pnp`` again, on fresh seed 19; session 14
``[zones] stop_time_scales = true``; session 20 ``[robot_loop] retract_max_radius_m = 0.45``, on fresh seed 25;
session 21 ``[robot_loop] radial_retract_stops = false``, on fresh seed 31. session 25 ``[zones] scaled_dwell_s = 0.5``, on fresh seed 35.)"""


VALIDATED_MODULE_CONSTANTS = {
    ("edge_runtime.robot.hazard", "MAX_MISSING_JOINTS"): 0,
    ("edge_runtime.robot.calibration", "ANCHOR_LIFTER_DEPTH_SD"): float("inf"),
    ("edge_runtime.robot.calibration", "ANCHOR_WINDOW_FRAMES"): 15,
    ("edge_runtime.robot.calibration", "ANCHOR_LEVEL_FEET_M"): 0.1,
    ("edge_runtime.robot.calibration", "ANCHOR_GATE_M"): 0.5,
    ("edge_runtime.robot.hazard", "SAWYER_J0_RANGE_RAD"): math.radians(170.0),
    ("edge_runtime.robot.hazard", "RAY_KEYPOINT_ERROR_M"): 0.25,
    ("edge_runtime.robot.calibration", "MAX_PNP_RESIDUAL_M"): 0.3,
}
"""Module constants of the robot path that change its decisions but are not [section] keys, so the safety
hash does not see them: the values reports/hrc/validated.json was measured with. Session 10's candidate
(ANCHOR_LIFTER_DEPTH_SD 0.12 with pnp) collided on its fresh seed; changing any of these needs the hrc
suites re-run on a fresh seed, as a config default does."""


@pytest.mark.parametrize("where", sorted(VALIDATED_MODULE_CONSTANTS), ids=lambda w: w[1])
def test_the_robot_paths_module_constants_are_the_validated_ones(where):
    import importlib

    module, name = where
    assert getattr(importlib.import_module(module), name) == VALIDATED_MODULE_CONSTANTS[where], (
        f"{module}.{name} changed since reports/hrc/validated.json: re-run the hrc suites on a fresh seed")


def test_the_shipped_safety_defaults_are_the_validated_ones():
    """Fails when a default the cell's safety depends on changed since reports/hrc/validated.json was
    measured: re-run the commands it lists (each with --validated reports/hrc/validated.json). Only the
    changes named in :data:`PENDING_REVALIDATION` are let through, and only while validated.json lacks them.
    The record says whether the must-hold (0 collisions in every run) held; it cannot say so while a run
    collided. Session 12 shipped a configuration whose fresh-seed runs had 1 collision (hard:200 MAVLink,
    seed 17) because the configuration before had 2 (CAN) and 3 (MAVLink) on the same seed: the README reports it as
    not met."""
    rec = json.loads(VALIDATED.read_text())
    box = hrc.load_box()
    now = hrc.safety_config(box)
    for sec, table in PENDING_REVALIDATION.items():
        for k, v in table.items():
            assert now[sec][k] == v, f"[{sec}] {k}: pending re-validation as {v!r}, shipped {now[sec][k]!r}"
            assert rec["safety_config"][sec].get(k) != v, f"[{sec}] {k} is validated: empty PENDING_REVALIDATION"
            if k in rec["safety_config"][sec]:  # a changed default: the validated value
                now[sec][k] = rec["safety_config"][sec][k]
            else:  # a key added since: not in what was validated
                del now[sec][k]
    changed = [f"[{sec}] {k}: validated {v!r}, shipped {now[sec].get(k)!r}"
               for sec, table in rec["safety_config"].items() for k, v in table.items() if now[sec].get(k) != v]
    assert rec["safety_sha256"] == hrc._json_sha256(now), changed
    runs = rec["runs"].values()
    for need in ("random:200 can", "random:200 mavlink", "dissertation can", "dissertation mavlink"):
        assert any(f"{r['scenario']} {r['link']}" == need for r in runs), need
    for link in ("can", "mavlink"):  # the hard suite too (issue 13)
        assert any(r["scenario"].startswith("hard:") and r["link"] == link for r in runs), f"hard:N {link}"
    for r in runs:
        assert isinstance(r["collisions"], int) and not r["not_run"] and r["perception"] == "lifter", r["command"]
        assert r["max_speed_mps"] == 2.0 or r["scenario"] == "dissertation", r["command"]
    assert rec["must_hold_met"] == all(r["collisions"] == 0 for r in runs)


@pytest.mark.skipif(not __import__("firmware_sim.scenarios.hrc_world", fromlist=["x"]).lifter_available(),
                    reason="no lifter in edge_runtime/assets/manifest.json")
def test_lifter_path_calibrates_per_camera_and_keeps_the_worker_clear(front):
    s = run_scenario(front, "can", runtime=True, perception="lifter").summary
    assert s["perception"] == "lifter"
    assert 0.8 < s["calibration_scale"] < 1.25          # the 3-marker fit found a plausible scale
    assert s["head_error_m"]["n"] > 50 and s["head_error_m"]["median"] < 1.0
    assert not s["collision"] and s["max_state"] == "LEVEL2"


def test_a_refused_calibration_is_reported_not_hidden(front, monkeypatch):
    from edge_runtime.robot.calibration import CalibrationError
    from firmware_sim.scenarios import hrc_world

    def refuse(*a, **k):
        raise CalibrationError("marker 1: 3 usable frames, need 10")

    monkeypatch.setattr(hrc_world, "calibrate", refuse)
    res = run_scenario(front, "can", runtime=True, perception="lifter")
    assert res.summary["not_run"].startswith("calibration failed: marker 1")
    out = hrc.summarize([res], {"link": "can", "camera_hz": 30.0, "perception": "lifter",
                                "zones": {"r1_m": 4.4, "r2_m": 2.4}})
    assert out["not_run"] == {"front": res.summary["not_run"]}
    assert out["collisions"] == 0 and out["min_separation_m"] is None
    assert "calibration failed" in hrc.format_table(out)


# -- the hard suite ------------------------------------------------------------------------------

def test_hard_scenarios_are_reproducible_and_hold_what_the_suite_promises():
    a, b = hard_scenarios(40, seed=1), hard_scenarios(40, seed=1)
    assert [s.describe() for s in a] == [s.describe() for s in b] and hard_scenarios(40, 2)[0] != a[0]
    assert hard_scenarios(10, seed=1) == a[:10]                   # a prefix: hard:40 runs hard:10's first
    workers = [w for s in a for w in s.workers()]
    assert {len(s.workers()) for s in a} == {1, 2, 3} and all(s.hard for s in a)
    assert {w.kind for w in workers} == {"approach", "pass", "walkby"}
    speeds = [v for w in workers for v in w.speeds_mps]
    assert 0.5 <= min(speeds) and max(speeds) <= 2.0 and sum(v > 1.6 for v in speeds) >= 10   # running bursts
    assert sum(len(w.waypoints_xz_m) >= 3 for w in workers) >= len(workers) // 2               # curves, turns
    assert sum(w.pause is not None for w in workers) >= 5 and sum(w.reach_s > 0 for w in workers) >= 3
    assert any(w.start_s > 0.5 for w in workers)                                                # later entries
    for w in workers:
        floor = HardParams().walkby_distance_m[0] if w.kind == "walkby" else HardParams().min_base_distance_m
        assert path_base_distance(w.waypoints_xz_m) >= floor - 1e-9
    for s in a:
        eye = np.asarray(s.camera_eye_m)
        assert 1.0 - 0.914 - 1e-6 <= eye[1] <= 3.0 - 0.914 + 1e-6
        assert 3.0 - 1e-6 <= np.hypot(eye[0], eye[2] - 0.9) <= 8.0 + 0.5


def test_coco_noise_is_the_joints_sigma_times_the_persons_pixel_size():
    from firmware_sim.devices.camera import PERFECT, Camera, detect
    from firmware_sim.people import human

    j = human.joints(human.Body.from_height(1.75), human.Posture(), pelvis_xz_m=(0.0, 1.0))
    J = np.repeat(j[None], 600, axis=0)
    sds = []
    for dist in (3.0, 6.0):
        cam = Camera.look_at((0.0, 0.6, 1.0 + dist), (0.0, 0.0, 1.0))
        clean = detect(cam, J, np.random.default_rng(0), PERFECT)
        noisy = coco_noise(cam, J, clean, 1.75, np.random.default_rng(1), HardNoise(offset_scale=0.0))
        err = noisy[..., :2] - clean[..., :2]
        s_px = cam.intrinsics.fx_px * PERSON_SCALE_OF_HEIGHT * 1.75 / cam.to_camera(j)[0, 2]
        sds.append(err[:, :, 0].std(axis=0) / s_px)
    assert sds[0] == pytest.approx(COCO_SIGMAS_H36M, rel=0.25)       # per axis: sigma x the person's scale
    assert sds[1] == pytest.approx(COCO_SIGMAS_H36M, rel=0.25)       # in pixels: half as large twice as far


def test_occlusion_hides_joints_behind_another_worker_the_arm_or_his_own_trunk():
    from firmware_sim.people import human

    body = human.Body.from_height(1.75)
    near = human.joints(body, human.Posture(), pelvis_xz_m=(0.0, 3.0), heading_rad=0.0)
    far = human.joints(body, human.Posture(), pelvis_xz_m=(0.0, 2.0), heading_rad=0.0)
    eye = np.array([0.0, 0.4, 6.0])                                  # looking at the cell along -z
    hidden, behind = occlude(eye, np.stack([near, far]), np.array([True, True]))
    assert hidden[1].sum() >= 10 and hidden[0].sum() == 0           # the far one is behind the near one
    alone, _ = occlude(eye, np.stack([near, far]), np.array([False, True]))
    assert alone[1].sum() == 0                                       # nobody in front of him: all seen
    arm = (np.array([[0.0, 0.0, 2.5]]), np.array([0.3]))
    by_arm, _ = occlude(eye, far[None], np.array([True]), arm)
    assert by_arm[0].any()
    side = human.joints(body, human.Posture(), pelvis_xz_m=(0.0, 2.0), heading_rad=np.pi / 2)
    _, own = occlude(np.array([0.0, 0.0, 6.0]), side[None], np.array([True]))      # seen from his side
    assert own[0].any() and not own[0][[0, 7, 8]].any()             # far-side limbs, never the trunk itself


def test_productivity_counts_work_and_the_stops_of_walk_by_traffic():
    d = [{"scenario_s": 10.0, "productive_s": 6.0, "false_alarms": 1, "came_within_protective": True, "halts": 2,
          "worker_s": 10.0, "kind": "stop"},
         {"scenario_s": 10.0, "productive_s": 9.0, "false_alarms": 0, "came_within_protective": False, "halts": 1,
          "worker_s": 20.0, "kind": "pass", "worker_specs": [{"kind": "walkby"}, {"kind": "walkby"}],
          "halt_reasons": {"person_unseen": 1}, "state_s": {"NORMAL": 9.0, "LEVEL1": 1.0},
          "halt_s": {"person_unseen": 1.0}}]
    d[0].update(state_s={"NORMAL": 6.0, "LEVEL2": 4.0}, halt_s={"level2_retract": 3.0, "person_unseen": 1.0})
    p = hrc.productivity(d)
    assert p["state_share"] == {"LEVEL1": 0.05, "LEVEL2": 0.2, "NORMAL": 0.75}
    assert p["halt_share"] == {"level2_retract": 0.15, "person_unseen": 0.1}
    assert p["productive_time_share"] == pytest.approx(0.75) and p["false_stops"] == 1
    assert p["walkby_scenarios"] == 1 and p["false_stops_per_worker_hour"] == pytest.approx(1 / (20 / 3600), rel=1e-3)
    assert p["worker_kinds"] == {"stop": 1, "walkby": 2}
    assert p["walkby_stops_by_reason"] == {"person_unseen": 1}                # walk-by halts only, by cause


@pytest.mark.skipif(not __import__("firmware_sim.scenarios.hrc_world", fromlist=["x"]).lifter_available(),
                    reason="no lifter in edge_runtime/assets/manifest.json")
def test_a_worker_lifted_invalidly_reaches_the_runtime_with_his_keypoints_rays():
    """The world feeds the loop as the product does (``RobotLoop.feed_people``): a worker the lifter
    cannot lift comes with the rays of the keypoints he shows, so the runtime can bound him."""
    from firmware_sim.scenarios.hrc_world import LifterPerception, _feed, make_lifter

    class Loop:
        def feed_poses(self, poses, rays=None):
            self.poses, self.rays = poses, rays

    lifter = make_lifter()
    cam = lifter.canonical_camera
    kp = np.zeros((1, 17, 3))
    kp[0, :, :2] = (cam.cx_px, cam.cy_px)
    kp[0, :, 2] = 0.9
    kp[0, 16] = (np.nan, np.nan, 0.0)                                  # his right wrist is not seen
    p = LifterPerception(lifter, kp)
    out = p.push(0, 0.0)
    assert not out.valid                                               # never seen whole: no valid lift yet
    loop = Loop()
    _feed(loop, [out], [p], 0)
    r = loop.rays[0]
    assert np.allclose(r[:16], (0.0, 0.0, 1.0)) and np.isnan(r[16]).all()
    # a validly lifted worker needs none
    _feed(loop, [replace(out, valid=True, reason=None)], [p], 0)
    assert loop.rays == {}
