"""bench.robot_cycle: the robot scenario's commands, the CAN link with its arm stand-in, the reaction rows.

Timings are never asserted: the scenario runs on a simulated clock (``RobotConfig.simulated``) that
jumps from deadline to deadline, so what is checked is what the runtime sent and how it is counted.
The scenario runs with the shipped ``[zones]`` and with ``stop_time_scales`` the other way round
(what the arm is told to do depends on it); those tests are marked ``slow``: they start no process,
but the default length through the lifter takes minutes, too long for ``make test-fast``.
"""
import os

import numpy as np
import pytest

from bench.arm_echo import HEARTBEAT_FRAME, arm_on_bus, command_sent_s
from bench.report import compare, format_markdown
from bench.robot_cycle import (
    ARM,
    ARM_POSTURE_RAD,
    KINDS,
    P99_MIN_N,
    SCENARIO,
    TICK,
    RobotConfig,
    _box,
    _LiveSchedule,
    _schedule,
    box_camera,
    command_row,
    lifter_entry,
    measure_robot,
    run_cycle,
)
from bench.robot_scenario import prepare_workers
from bench.sweep import BenchOptions
from edge_runtime.core.manifest import ASSETS_DIR, load_manifest
from edge_runtime.robot.link.base import LinkConfig

SCENE_KINDS = {"speed", "stop", "retract", "escape", "resume"}
"""What the runtime sends in reply to the two workers' frames with the full-speed stopping time."""
SCENE_MIN_N = 10
"""Each of those at least this often in the default length: else the scenario needs re-tuning."""
SHORT_S = 60.0
"""Length of the run with ``stop_time_scales`` the other way round (s)."""


def scene_kinds(stop_time_scales: bool) -> set:
    """What the frames command with this ``[zones] stop_time_scales``: when the stopping time shrinks with
    the arm's speed, the arm works slowly closer in and someone coming near it makes it retract
    (``reach_retract_m``) before it would stop, so stops become rare (seed 1, 300 s: 1 frame)."""
    return SCENE_KINDS - {"stop"} if stop_time_scales else SCENE_KINDS


def _shipped_scales() -> bool:
    return _box().zones.stop_time_scales


def _lifter():
    if not (ASSETS_DIR / "manifest.json").exists():
        return None
    return lifter_entry(load_manifest(ASSETS_DIR)["models"])


def _config(tmp_path, seconds: float, zones: dict | None = None, schedule: str = "grid") -> RobotConfig:
    lifter = _lifter()
    npz = prepare_workers(tmp_path / "workers.npz", seconds, lifter, 1, *box_camera(_box()))
    return RobotConfig(str(npz), seconds, lifter=lifter["precision"] if lifter else "", simulated=True,
                       zones=zones or {}, schedule=schedule)


@pytest.fixture(scope="module")
def default_run(tmp_path_factory):
    """The default run's length of the scenario on the simulated clock with the shipped configuration,
    through the shipped lifter when there is one (about two minutes on a loaded machine)."""
    return run_cycle(_config(tmp_path_factory.mktemp("robot"), BenchOptions().robot_s))


@pytest.fixture(scope="module")
def flipped_run(tmp_path_factory):
    """:data:`SHORT_S` of the scenario with ``[zones] stop_time_scales`` the other way round from the
    shipped one, and that value."""
    scales = not _shipped_scales()
    return run_cycle(_config(tmp_path_factory.mktemp("robot"), SHORT_S, {"stop_time_scales": scales})), scales


def _assert_all_acknowledged(run) -> None:
    st = run.loop.status()
    # every command reached the arm over the CAN codec and was acknowledged: none re-sent, no fault
    assert st["unacked"] == 0 and st["retries"] == 0 and st["fault"] == "" and st["link"] == "ok"
    assert run.echo.rejected == 0
    # the arm answered every command the loop counted (alarms, resumes and moves included)
    assert sum(run.echo.commands.values()) == st["commands"]
    assert len(run.reaction_s) == len(run.kinds) == len(run.feed_reaction_s) == len(run.due_reaction_s)
    # from the due time is never shorter than from when the loop picked the frame up
    assert all(d >= r for d, r in zip(run.due_reaction_s, run.reaction_s, strict=True))


def test_workers_file_holds_both_workers_for_the_run(tmp_path):
    lifter = _lifter()
    camera, fmt = box_camera(_box())
    data = np.load(prepare_workers(tmp_path / "w.npz", 10.0, lifter, 1, camera, fmt))
    assert data["joints_robot_m"].shape == (300, 2, 17, 3)
    if lifter is not None:
        kp = data["keypoints_px"]
        assert kp.shape == (300, 2, 17, 3) and np.all(kp[..., 2] == 1.0)
        # both workers in the box's camera's image, in the box's keypoint order
        w, h = camera.width_px, camera.height_px
        assert np.all((kp[..., 0] >= 0) & (kp[..., 0] < w) & (kp[..., 1] >= 0) & (kp[..., 1] < h))


@pytest.mark.slow
def test_scenario_makes_the_runtime_send_every_kind_of_command(default_run):
    assert scene_kinds(_shipped_scales()) <= set(default_run.kinds), "the scenario needs re-tuning"
    assert set(default_run.kinds) <= set(KINDS) and set(default_run.tick_kinds) <= set(KINDS)
    _assert_all_acknowledged(default_run)
    st = default_run.loop.status()
    assert st["escapes"] >= default_run.kinds.count("escape") + default_run.tick_kinds.count("escape")
    assert len(default_run.cycle_s) == int(BenchOptions().robot_s) * 30


@pytest.mark.slow
def test_scenario_with_the_other_stop_time(flipped_run):
    run, scales = flipped_run
    assert scene_kinds(scales) <= set(run.kinds), f"the scenario needs re-tuning for stop_time_scales={scales}"
    _assert_all_acknowledged(run)


@pytest.mark.slow
def test_reaction_rows_count_every_commanding_frame(default_run):
    row = command_row("robot_reaction", default_run.reaction_s, default_run.kinds, "what")
    assert row["n"] == len(default_run.kinds) == sum(v["n"] for v in row["by_kind"].values())
    assert set(row["by_kind"]) == set(default_run.kinds)


@pytest.mark.slow
def test_default_run_has_enough_samples_for_a_p99(default_run):
    assert RobotConfig("x").seconds == BenchOptions().robot_s
    assert len(default_run.reaction_s) >= 300
    # every kind of the scene more than once, and the speed overrides alone enough for their own p99
    counts = {k: default_run.kinds.count(k) for k in scene_kinds(_shipped_scales())}
    assert min(counts.values()) >= SCENE_MIN_N, f"the scenario needs re-tuning: {counts}"
    assert default_run.kinds.count("speed") >= P99_MIN_N


def test_the_arm_reports_its_state_between_the_ticks():
    """The arm's state arrives between two ticks, so some frames find one to decode before they command."""
    slots = _schedule(0.1)
    arm = [t for t, k in slots if k == ARM]
    ticks = [t for t, k in slots if k == TICK]
    assert len(arm) == len(ticks) == 10 and all(a - t == pytest.approx(0.005) for a, t in zip(arm, ticks, strict=True))
    after_arm = [k for (_, prev), (_, k) in zip(slots, slots[1:]) if prev == ARM and k >= 0]
    assert after_arm  # frames due right after an arm slot, before the next tick drains it


def _live_slots(seconds: float, frame_s: float, tick_s: float) -> list:
    """_LiveSchedule's slots when each frame takes ``frame_s`` and each tick ``tick_s`` (the arm none)."""
    live, slots = _LiveSchedule(seconds), []
    for due, k in live:
        slots.append((due, k))
        if k != ARM:
            live.done(due + (frame_s if k >= 0 else tick_s), k)
    return slots


def test_the_live_schedule_takes_a_frame_first_and_ticks_after_it():
    """As the robot command's camera driver: a frame when due, a tick at once after it, then one TICK_S after
    each tick's end until the next frame; the camera and the arm keep their own clocks."""
    from edge_runtime.robot.command import TICK_S

    slots = _live_slots(1.0, frame_s=0.004, tick_s=0.0005)
    frames = [(t, k) for t, k in slots if k >= 0]
    assert frames == [(pytest.approx(k / 30), k) for k in range(30)]  # never behind a tick
    arm = [t for t, k in slots if k == ARM]
    assert arm == pytest.approx([j / 100 + 0.005 for j in range(len(arm))])
    ticks = [(i, t) for i, (t, k) in enumerate(slots) if k == TICK]
    for i, t in ticks:
        prev = next((t0, k0) for t0, k0 in reversed(slots[:i]) if k0 != ARM)
        assert t == pytest.approx(prev[0] + 0.004 if prev[1] >= 0 else prev[0] + 0.0005 + TICK_S)
    # a tick right after every frame but the last
    assert all(next(k for _, k in slots[i + 1:] if k != ARM) == TICK for i, (_, k) in enumerate(slots[:-1]) if k >= 0)


def test_a_frame_due_while_a_tick_runs_comes_after_it_in_the_live_schedule():
    """A tick under way when a frame falls due keeps it waiting, as on the box (here ticks of 12 ms: the tick
    that starts 10 ms after the previous one ended, at 26 ms, still runs at 33 ms)."""
    slots = [(t, k) for t, k in _live_slots(0.1, frame_s=0.004, tick_s=0.012) if k != ARM]
    assert [k for _, k in slots[:4]] == [0, TICK, TICK, 1]
    assert slots[2][0] == pytest.approx(0.026) and slots[2][0] < 1 / 30 < slots[2][0] + 0.012


def test_compare_does_not_call_another_scenario_a_regression():
    old = {"results": [], "loops": [{"name": "robot_reaction", "p50_us": 1.0, "p99_us": 1.0, "mean_us": 1.0}]}
    new = {"results": [], "loops": [{"name": "robot_reaction", "scenario": SCENARIO, "p50_us": 9.0, "p99_us": 9.0,
                                     "mean_us": 9.0}]}
    lines, regressions = compare(new, old)
    assert regressions == 0 and any("not comparable" in line for line in lines)
    assert compare(new, {**new, "loops": [{**new["loops"][0], "p99_us": 1.0}]})[1] == 1


def test_a_p99_of_few_samples_is_labelled():
    few = command_row("robot_reaction", [0.001] * 5, ["stop"] * 5, "what")
    assert few["n"] == 5 and str(P99_MIN_N) in few["p99_note"] and "not a p99" in few["p99_note"]
    many = command_row("robot_reaction", [0.001] * P99_MIN_N, ["speed"] * P99_MIN_N, "what")
    assert "p99_note" not in many and many["by_kind"]["speed"]["n"] == P99_MIN_N
    report = {"machine": {"cpu": "c", "cores": 2, "cpus_used": [0], "load_avg_1_5_15": [0, 0, 0], "python": "3",
                          "onnxruntime": "1", "torch": None},
              "method": {"command": "python -m bench", "n": 1, "warmup": 1}, "results": [], "skipped": [],
              "loops": [few, many]}
    md = format_markdown(report)
    assert "(n 5)" in md and "not a p99" in md and "stop n 5" in md and "(p99 of < 100)" in md
    assert f"speed n {P99_MIN_N} " in md


def test_arm_echo_acknowledges_commands_sent_by_the_product_link():
    now = [0.0]
    with arm_on_bus(f"test-echo-{os.getpid()}", ARM_POSTURE_RAD, lambda: now[0],
                    LinkConfig(heartbeat_period_s=None)) as (bus, echo, link):
        echo.serve(now[0])
        link.poll()
        assert link.link_ok
        seqs = [link.resume(), link.set_speed(0.3), link.move_to((0.3, 0.1, 0.6), 0.0, 0.0), link.stop()]
        heartbeat_id = link.codec.db.get_message_by_name(HEARTBEAT_FRAME).frame_id
        now[0] = 0.01
        link.heartbeat()
        # the last command frame, not the heartbeat after it, is when the command was on the link
        assert command_sent_s(bus.sent, heartbeat_id) == 0.0 and bus.sent[-1] == (0.01, heartbeat_id)
        echo.serve(now[0])
        link.poll()
        assert [link.result(s) for s in seqs] == ["ok"] * 4
        assert echo.commands == {"resume": 1, "speed": 1, "move": 1, "stop": 1} and echo.rejected == 0
        assert echo.state.mode == "stopped" and abs(echo.speed_mps - 0.3) < 1e-3


def test_arm_echo_turns_its_links_toward_a_retraction_target():
    from edge_runtime.robot.hazard import arm_points_m

    with arm_on_bus(f"test-echo-turn-{os.getpid()}", ARM_POSTURE_RAD, lambda: 0.0,
                    LinkConfig(heartbeat_period_s=None)) as (_, echo, link):
        hand = echo.hand_m.copy()
        c, s = np.cos(0.5), np.sin(0.5)
        target = np.array([c * hand[0] + s * hand[2], hand[1], -s * hand[0] + c * hand[2]])  # turned about y
        link.retract(tuple(target), 0.0, 0.0)  # accepted while stopped, as the controller does
        for k in range(300):
            echo.serve(k * 0.01)
        assert np.allclose(echo.hand_m, target, atol=1e-3)  # the DBC's 0.1 mm
        tool = arm_points_m(echo.state.joint_positions_rad)[-2]
        bearing = lambda p: np.arctan2(p[0], p[2])  # noqa: E731
        assert abs(bearing(tool) - bearing(target)) < 1e-3


def test_measure_robot_rows(tmp_path):
    rows = {r["name"]: r for r in measure_robot(_config(tmp_path, 8.0))}
    assert set(rows) == {"robot_30hz", "robot_reaction", "robot_tick_command"}
    r = rows["robot_30hz"]
    assert r["frames"] == r["n"] == 240 and r["unacked"] == 0 and r["arm_rejected"] == 0
    assert "CAN link" in r["what"] and "virtual bus" in rows["robot_reaction"]["what"]
    reaction = rows["robot_reaction"]
    assert reaction["n"] == sum(v["n"] for v in reaction["by_kind"].values()) == reaction["from_feed"]["n"]
    assert reaction["frame_cpu"]["n"] == reaction["from_due"]["n"] == reaction["n"]
    assert reaction["judged_on"] == "from_due" and reaction["scenario"] == SCENARIO == r["scenario"]
    assert r["cpu_share_with_arm_pct"] >= r["cpu_share_pct"]


def test_the_live_schedule_is_another_scenario_with_the_same_rows(tmp_path):
    rows = {r["name"]: r for r in measure_robot(_config(tmp_path, 4.0, schedule="live"))}
    r = rows["robot_30hz"]
    assert r["frames"] == 120 and r["unacked"] == 0 and r["arm_rejected"] == 0
    assert rows["robot_reaction"]["scenario"] == r["scenario"] == SCENARIO + "_live" != SCENARIO
    with pytest.raises(ValueError, match="schedule"):
        measure_robot(_config(tmp_path, 1.0, schedule="tick_first"))
