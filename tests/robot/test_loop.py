"""RobotLoop: poses in, commands out, on a simulated clock against a fake robot link.

The fake link (support.robot.FakeLink) implements edge_runtime.robot.link.base.LinkInterface;
its arm moves toward the last target at a fixed speed when ``advance`` is called."""
import math
from dataclasses import dataclass

import numpy as np
import pytest
from support.robot import FakeLink, anchored_worker, true_calibration

from edge_runtime.core.skeleton import HEAD
from edge_runtime.robot import calibration
from edge_runtime.robot.calibration import CalibrationParams
from edge_runtime.robot.hazard import ZoneParams
from edge_runtime.robot.loop import LoopParams, RobotLoop
from firmware_sim.devices.camera import Camera

HEAD_Y = 0.75
HEAD_ZONES = ZoneParams(separation="head")
"""The dissertation's head-to-effector zones, which most of these tests' geometry uses (the
shipped default is whole-body separation: the tests at the end)."""


class Clock:
    def __init__(self):
        self.t = 0.0

    def __call__(self):
        return self.t


def worker(x, z):
    """(17, 3) robot-frame joints with the head at (x, HEAD_Y, z) (the rest is irrelevant here)."""
    j = np.zeros((17, 3))
    j[:] = (x, -0.5, z)
    j[HEAD] = (x, HEAD_Y, z)
    return j


def drive(loop, link, clock, path, fps=30.0, tick_s=0.01):
    """Feed ``path(t) -> joints or None`` at ``fps`` while ticking the loop every ``tick_s``."""
    frames = []
    t_end = path.duration
    next_frame = 0.0
    while clock.t < t_end:
        if clock.t + 1e-9 >= next_frame:
            j = path(clock.t)
            if j is not path.SKIP:
                frames.append(loop.feed_joints(j))
            next_frame += 1 / fps
        loop.tick()
        link.advance(tick_s)
        clock.t = round(clock.t + tick_s, 9)
    return frames


class Path:
    SKIP = object()

    def __init__(self, fn, duration):
        self.fn, self.duration = fn, duration

    def __call__(self, t):
        return self.fn(t)


def make(**kw):
    clock, link = Clock(), FakeLink()
    loop = RobotLoop(link, clock=clock, **{"zones": HEAD_ZONES, **kw})
    return loop, link, clock


def test_normal_work_cycles_the_waypoints_without_flooding_the_link():
    loop, link, clock = make()
    far = Path(lambda t: worker(4.0, 5.0), 12.0)
    drive(loop, link, clock, far)
    s = loop.status()
    assert s["state"] == "NORMAL" and s["reason"] == "clear" and s["frames"] == 360
    moves = [c[1] for c in link.calls if c[0] == "move_to"]
    wps = [tuple(w) for w in LoopParams().task_waypoints_m]
    assert len(moves) >= 4 and set(moves) == set(wps)
    assert all(a != b for a, b in zip(moves, moves[1:]))  # each move once, only when it changes
    # start-up: stopped (no pose yet, yellow), then green and resume() before the first move
    names = link.names()
    assert names[:2] == ["set_alarm", "stop"] and link.calls[0][1] == "yellow"
    assert names.index("resume") < names.index("move_to")
    beats = names.count("heartbeat")
    assert 12.0 / 0.05 * 0.9 <= beats <= 12.0 / 0.05 + 1  # every 50 ms, not every tick
    assert len(link.calls) - beats < 20


def test_a_worker_walking_at_the_effector_stops_then_retracts_the_arm():
    loop, link, clock = make()
    speed = 1.2
    # the arm works; a worker comes straight at the effector from +z, 6 m away, after 2 s
    path = Path(lambda t: worker(0.0, 0.8 + max(0.5, 6.0 - speed * max(0.0, t - 2.0))), 8.0)
    frames = drive(loop, link, clock, path)
    states = [f.state for f in frames]
    i1, i2 = states.index("LEVEL1"), states.index("LEVEL2")
    assert i1 < i2
    names = link.names()
    first_move = names.index("move_to")
    assert names.index("stop", first_move) < names.index("retract")  # level 1 stopped the arm first
    retract = [c for c in link.calls if c[0] == "retract"]
    # once per entry, not once per frame; again (re_retract_m) only from the first one's target,
    # once the worker has come 0.15 m closer (he slows to a stop 0.5 m out)
    assert 1 <= len(retract) <= 2 and (len(retract) == 1 or retract[1][1] != retract[0][1])
    target = np.array(retract[0][1])
    # Eq. 6 for a head-on approach from +z: 0.3 m away from the worker and 0.2 m along his
    # walk, both roughly -z, from where the effector was when level 2 began
    L = target - link.retracts_from[0]
    assert L[1] == pytest.approx(0.0) and 0.1 < np.linalg.norm(L) <= 0.5 + 1e-9 and L[2] < -0.1 and abs(L[0]) < 0.1
    # never closer to the base's axis than retract_min_radius_m (the Sawyer cannot hold its tool
    # pointed at the base there): the step is shortened instead
    assert np.hypot(target[0], target[2]) >= LoopParams().retract_min_radius_m - 1e-9
    # the tool turns toward the base, by at most retract_max_turn_deg from the task's yaw (0)
    toward = math.atan2(-target[0], -target[2])
    assert retract[0][3] == pytest.approx(math.copysign(math.radians(LoopParams().retract_max_turn_deg), toward))
    alarms = [c[1:] for c in link.calls if c[0] == "set_alarm"]
    assert ("red", 2000.0, 70.0) in alarms and ("red", 4000.0, 80.0) in alarms
    # the frame that crossed into level 2 carried the command: measurable reaction time
    rec = frames[i2]
    assert rec.command == "retract" and rec.t_command_s is not None and rec.t_command_s >= rec.t_in_s
    assert loop.status()["retracts"] == len(retract) and loop.status()["stops"] >= 2


def test_the_arm_returns_to_work_when_the_worker_leaves():
    loop, link, clock = make()
    path = Path(lambda t: worker(0.0, 2.3) if t < 3.0 else worker(4.0, 6.0), 7.0)
    frames = drive(loop, link, clock, path)
    assert "LEVEL1" in [f.state for f in frames] and frames[-1].state == "NORMAL"
    names = link.names()
    last_stop = len(names) - 1 - names[::-1].index("stop")
    assert "resume" in names[last_stop:] and "move_to" in names[last_stop:]
    assert link.calls[-1][0] in ("heartbeat", "move_to", "set_alarm")


def test_stale_pose_stops_the_arm_within_one_cycle_after_200_ms():
    loop, link, clock = make()
    path = Path(lambda t: worker(4.0, 5.0) if t < 3.0 else Path.SKIP, 4.0)
    drive(loop, link, clock, path)
    stops = [i for i, c in enumerate(link.calls) if c[0] == "stop"]
    assert loop.status()["reason"] == "pose_stale" and loop.status()["stale"] == 1
    # replay the timeline: the last frame came at t <= 3.0; find when the stop went out
    loop2, link2, clock2 = make()
    times = []
    orig = link2.stop
    link2.stop = lambda: (times.append(clock2.t), orig())
    frames = drive(loop2, link2, clock2, Path(path.fn, 4.0))
    last_frame = frames[-1].t_in_s
    late = [t for t in times if t > 2.0]
    assert len(late) == 1 and 0.2 < late[0] - last_frame <= 0.2 + 0.01 + 1e-9
    assert stops


def test_invalid_lifter_output_and_nan_joints_stop_the_arm():
    @dataclass
    class Lifted:
        joints_cam_m: np.ndarray
        valid: bool
        reason: str | None

    for bad in ("lifter", "nan", "shape"):
        loop, link, clock = make()
        drive(loop, link, clock, Path(lambda t: worker(4.0, 5.0), 3.0))
        assert loop.status()["state"] == "NORMAL"
        if bad == "lifter":
            rec = loop.feed_lifted(Lifted(np.full((17, 3), np.nan), False, "missing_joints: head"))
            assert rec.reason == "pose_invalid: missing_joints: head"
        elif bad == "nan":
            j = worker(4.0, 5.0)
            j[HEAD, 1] = np.nan
            rec = loop.feed_joints(j)
            assert rec.reason == "pose_invalid: non-finite joints"
        else:
            rec = loop.feed_joints(np.zeros((15, 3)))
            assert rec.reason == "pose_invalid: joints of shape (1, 15, 3)"
        assert rec.state == "FAULT" and rec.command == "stop" and link.calls[-1][0] == "stop"
        assert link.calls[-2][:2] == ("set_alarm", "yellow") and loop.status()["invalid"] == 1


def test_a_worker_with_a_limb_joint_not_known_is_judged_and_one_without_his_hips_stops_the_arm(monkeypatch):
    """With missing joints allowed (hazard.MAX_MISSING_JOINTS, 0 as shipped), NaN for a wrist and a knee
    (the lifter's missing joints): bounded by their bones, the far worker keeps the arm working; NaN for a
    hip (his trunk: hazard.enough_joints) is an invalid frame."""
    from edge_runtime.robot import hazard

    monkeypatch.setattr(hazard, "MAX_MISSING_JOINTS", 3)
    loop, link, clock = make_whole_body()
    drive(loop, link, clock, Path(lambda t: worker(4.0, 5.0), 3.0))
    j = worker(4.0, 5.0)
    j[[16, 2]] = np.nan
    rec = loop.feed_joints(j)
    assert rec.state == "NORMAL" and loop.status()["invalid"] == 0
    j[1] = np.nan
    rec = loop.feed_joints(j)
    assert rec.reason == "pose_invalid: non-finite joints" and rec.state == "FAULT"


def test_no_person_from_the_lifter_is_an_empty_scene_not_a_fault():
    @dataclass
    class Lifted:
        joints_cam_m: np.ndarray
        valid: bool
        reason: str | None

    loop, link, clock = make()
    drive(loop, link, clock, Path(lambda t: worker(4.0, 5.0), 3.0))
    rec = loop.feed_lifted(Lifted(np.full((17, 3), np.nan), False, "no_person: nobody detected"))
    assert rec.state == "NORMAL" and loop.status()["invalid"] == 0


def test_a_worker_the_camera_cannot_see_holds_the_arm():
    loop, link, clock = make()
    z = HEAD_ZONES
    # far away, then 2 m from the effector, then gone from view (None: nobody detected)
    path = Path(lambda t: worker(0.0, 6.0) if t < 2.0 else worker(0.0, 2.8) if t < 3.0 else None,
                3.0 + z.lost_hold_s - 0.2)
    frames = drive(loop, link, clock, path)
    assert frames[-1].state == "LEVEL1" and frames[-1].reason == "worker_lost"
    names = link.names()
    assert "move_to" in names and "move_to" not in names[names.index("stop", names.index("move_to")):]


def test_an_unreachable_retract_target_falls_back_to_stop():
    loop, link, clock = make()
    link.unreachable_retract = True
    path = Path(lambda t: worker(0.0, 0.8 + max(0.5, 4.0 - 1.2 * t)), 4.0)
    drive(loop, link, clock, path)
    s = loop.status()
    assert s["state"] == "LEVEL2" and s["reason"] == "retract_unreachable" and s["unreachable"] == 2
    names = link.names()
    r = names.index("retract")
    # Eq. 6's target, then one retraction straight toward the base, then stop
    assert [n for n in names[r:] if n in ("retract", "stop", "move_to")] == ["retract", "retract", "stop"]
    first, second = (np.array(c[1]) for c in link.calls if c[0] == "retract")
    eff = link.state.ee_position_m
    assert np.hypot(second[0], second[2]) < np.hypot(eff[0], eff[2]) - 0.1  # radially in
    assert second[0] * eff[2] - second[2] * eff[0] == pytest.approx(0.0, abs=1e-6)  # along the radius


def test_a_lost_link_is_reported_and_retried():
    loop, link, clock = make()
    drive(loop, link, clock, Path(lambda t: worker(4.0, 5.0), 2.0))
    link.fail = True
    drive(loop, link, clock, Path(lambda t: worker(4.0, 5.0), 3.0))
    s = loop.status()
    assert s["link"] == "lost" and "ConnectionError" in s["link_error"] and s["link_errors"] >= 1
    errors_while_down = s["link_errors"]
    assert errors_while_down <= 1 + 1.0 / LoopParams().link_retry_s + 1  # retried at its period, not every tick
    n = len(link.calls)
    link.fail = False
    drive(loop, link, clock, Path(lambda t: worker(4.0, 5.0), 4.0))
    s = loop.status()
    assert s["link"] == "ok" and s["link_error"] == ""
    names = [c[0] for c in link.calls[n:]]
    # after the link comes back: heartbeat, then the current motion (resume + move) and beacon again
    assert names[0] == "heartbeat" and {"resume", "move_to", "set_alarm"} <= set(names)


def test_several_workers_the_nearest_decides_and_each_keeps_a_tracker():
    loop, link, clock = make()
    both = Path(lambda t: np.stack([worker(4.0, 5.0), worker(2.5, 3.0)]), 3.0)
    frames = drive(loop, link, clock, both)
    assert frames[-1].state == "LEVEL1" and frames[-1].distance_m == pytest.approx(np.hypot(2.5, 2.2), abs=0.1)


def test_camera_frame_joints_go_through_the_calibration():
    class Shift:
        def to_robot(self, p):
            return np.asarray(p) + [0.0, 0.0, -10.0]

    clock, link = Clock(), FakeLink()
    loop = RobotLoop(link, calibration=Shift(), zones=HEAD_ZONES, clock=clock)
    frames = drive(loop, link, clock, Path(lambda t: worker(0.0, 13.8), 2.0))  # 3 m in the robot frame
    assert frames[-1].state == "LEVEL1" and frames[-1].distance_m == pytest.approx(3.0, abs=0.05)


def test_the_calibration_gets_each_persons_tracker_id():
    """The floor anchoring is filtered per person: it must get the tracker's ids, not the order."""
    seen = []

    class Recording:
        def to_robot(self, p, observed=None, ids=None):
            seen.append(ids)
            return np.asarray(p)

    clock, link = Clock(), FakeLink()
    loop = RobotLoop(link, calibration=Recording(), zones=HEAD_ZONES, clock=clock)
    loop.feed_poses([(7, lifted(worker(0.0, 4.0))), (3, lifted(worker(1.0, 5.0)))])
    assert seen and list(seen[-1]) == [7, 3]


@pytest.mark.parametrize("anchor", [True, False])
def test_the_robot_loop_anchors_camera_frame_joints_when_the_calibration_says_so(anchor, monkeypatch):
    monkeypatch.setattr(calibration, "ANCHOR_LIFTER_DEPTH_SD", np.inf)  # the floor rays alone: exact
    cam = Camera.look_at((2.0, 1.2, 6.5), (0.0, -0.2, 1.0))
    truth = anchored_worker((0.8, 2.2))
    t = iter(np.arange(0, 10, 0.05))
    seen = RobotLoop(FakeLink(), clock=lambda: next(t)).feed_joints(truth).distance_m
    loop = RobotLoop(FakeLink(), calibration=true_calibration(cam, CalibrationParams(ground_anchor=anchor)),
                     clock=lambda: next(t))
    got = loop.feed_joints(cam.to_camera(truth) * 1.25).distance_m
    assert (got == pytest.approx(seen, abs=1e-6)) == anchor


# ------------------------------------------------------------------ against the simulated Sawyer

def sim_run(kind, path, duration_s, zones=HEAD_ZONES, params=LoopParams(), fps=30.0):
    """The loop against firmware_sim's controller over a real link (CAN on a virtual bus,
    or signed MAVLink on a socket pair), all on one simulated clock."""
    from firmware_sim.robot.controller import SimulatedRobot

    sim = SimulatedRobot(kind)
    loop = RobotLoop(sim.link, zones=zones, params=params, clock=sim.clock)
    frames, states, next_frame = [], [], 0.0
    try:
        while sim.clock() < duration_s:
            t = sim.clock()
            if t + 1e-9 >= next_frame:
                j = path(t)
                if j is not Path.SKIP:
                    frames.append(loop.feed_joints(j))
                next_frame += 1 / fps
            loop.tick()
            states.append((t, loop.monitor.state.name, sim.link.state))  # as decided at t
            sim.step(0.01)
    finally:
        sim.close()
    return loop, frames, states


def body_at(x, z, heading=0.0):
    from firmware_sim.people import human

    return human.joints(human.Body.from_height(1.75), human.Posture(), pelvis_xz_m=(x, z), heading_rad=heading)


@pytest.mark.parametrize("kind", ["can", "mavlink"])
def test_closed_loop_on_the_simulated_sawyer_stop_retract_and_back_to_work(kind):
    # from 6.5 m in front, 1.4 m/s straight at the arm, a pause 0.4 m short, then away again
    def z_of(t):
        return 0.9 + max(0.4, 6.5 - 1.4 * max(0.0, t - 3.0)) if t < 9.0 else 0.9 + 0.4 + 2.0 * (t - 9.0)

    loop, frames, states = sim_run(kind, lambda t: body_at(0.1, z_of(t), math.pi), 16.0)
    seq = [f.state for i, f in enumerate(frames) if i == 0 or frames[i - 1].state != f.state]
    assert seq == ["FAULT", "NORMAL", "LEVEL1", "LEVEL2", "LEVEL1", "NORMAL"], seq
    by_state = {}
    for t, s, st in states:
        by_state.setdefault(s, []).append((t, st))
    # the controller shows what the runtime decided: red + 2000 Hz, red + 4000 Hz, green
    lv1 = [st for t, st in by_state["LEVEL1"] if st is not None][-5:]
    lv2 = [st for t, st in by_state["LEVEL2"] if st is not None]
    assert any((st.light, st.tone_hz, st.tone_db) == ("red", 4000.0, 80.0) for st in lv2)
    assert lv2[-1].mode == "retract" and not lv2[-1].moving  # the retraction is done before the worker stops
    assert all(st.mode == "stopped" and st.ee_speed_mps < 0.01 for st in lv1)
    assert (states[-1][2].light, states[-1][2].mode) == ("green", "run") and states[-1][2].moving
    # the effector moved away from the worker: Eq. 6 for a head-on approach is -z
    start = next(st.ee_position_m for t, st in by_state["LEVEL2"] if st is not None)
    assert lv2[-1].ee_position_m[2] < start[2] - 0.3
    s = loop.status()
    # once on entry, and again while the worker kept coming after the first was done
    assert 1 <= s["retracts"] <= 3 and s["link_errors"] == 0 and s["refused"] == 0 and s["link"] == "ok"


@pytest.mark.parametrize("kind", ["can", "mavlink"])
def test_closed_loop_unreachable_retract_and_stale_camera_stop_the_arm(kind):
    # a retraction 2.5 m long cannot be reached: the controller says so and the arm is stopped
    # (targets 2.5 m out and, as the fallback, on the base's axis: both refused by the IK)
    zones = ZoneParams(retract_weight_away_m=2.5)
    loop, frames, states = sim_run(kind, lambda t: body_at(0.1, 0.9 + max(0.3, 6.5 - 1.4 * max(0.0, t - 3.0)),
                                                          math.pi), 9.0, zones=zones,
                                   params=LoopParams(retract_min_radius_m=0.0, retract_max_radius_m=5.0))
    s = loop.status()
    assert s["state"] == "LEVEL2" and s["reason"] == "retract_unreachable" and s["unreachable"] == 2
    assert states[-1][2].mode == "stopped" and not states[-1][2].moving
    # the camera stalls while the arm works: stopped within one cycle after 200 ms
    loop, frames, states = sim_run(kind, lambda t: body_at(3.0, 6.0) if t < 3.0 else Path.SKIP, 4.0)
    t_last = frames[-1].t_in_s
    t_fault = next(t for t, s, st in states if t > t_last and s == "FAULT")
    assert t_fault - t_last <= 0.2 + 0.01 + 1e-6
    assert loop.status()["reason"] == "pose_stale"
    assert states[-1][2].mode == "stopped" and states[-1][2].ee_speed_mps < 0.01


def _stops(link):
    return sum(1 for c in link.calls if c[0] == "stop")


def test_an_acknowledged_arm_raises_no_command_alarm():
    loop, link, clock = make()
    drive(loop, link, clock, Path(lambda t: worker(4.0, 5.0), 2.0))
    s = loop.status()
    assert s["acked"] >= 1 and s["unacked"] == 0 and s["retries"] == 0
    assert s["command_alarm"] == "" and s["fault"] == ""


@pytest.mark.parametrize("answer, counter", [(None, "unacked"), ("refused", "refused")])
def test_an_unconfirmed_stop_alarms_is_sent_again_and_ends_in_a_fault(answer, counter):
    loop, link, clock = make()
    link.answer = answer
    p = LoopParams()
    # the start-up FAULT sends a stop; the arm never confirms it
    drive(loop, link, clock, Path(lambda t: None, p.ack_timeout_s + 0.05))
    s = loop.status()
    assert s[counter] == 1 and s["retries"] == 1 and _stops(link) == 2
    assert s["command_alarm"].startswith("stop") and s["fault"] == ""
    assert s["stops"] == 1  # a retry is not a new stop
    drive(loop, link, clock, Path(lambda t: None, clock.t + (p.ack_retries + 1) * p.ack_timeout_s + 0.1))
    s = loop.status()
    assert _stops(link) == p.ack_retries + 1 and s["retries"] == p.ack_retries
    assert s["fault"].startswith("the arm did not confirm stop") and f"{p.ack_retries + 1} commands in a row" in s["fault"]


@pytest.mark.parametrize("late", [False, True])
def test_a_late_acknowledgement_clears_the_alarm(late):
    loop, link, clock = make()
    link.answer = None
    drive(loop, link, clock, Path(lambda t: None, 0.15))
    assert loop.status()["command_alarm"] and _stops(link) == 2
    if late:  # the first stop's answer arrives after its retry went out: the arm did stop
        first = next(i for i, c in enumerate(link.calls, 1) if c[0] == "stop")
        link._answers[first] = "ok"
    else:
        link.answer = "ok"  # the retry is acknowledged
    drive(loop, link, clock, Path(lambda t: None, clock.t + 0.4))
    s = loop.status()
    assert s["command_alarm"] == "" and s["fault"] == "" and s["acked"] == 1
    assert _stops(link) == (2 if late else 3)  # once confirmed, no more retries


def test_a_link_that_never_comes_up_is_a_fault():
    class Silent(FakeLink):
        last_error = "no robot state for 200 ms"

        @property
        def link_ok(self):
            return False

    clock, link = Clock(), Silent()
    loop = RobotLoop(link, clock=clock)
    up_s = LoopParams().link_up_timeout_s
    drive(loop, link, clock, Path(lambda t: None, up_s - 0.1))
    assert loop.fault == "" and loop.status()["unacked"] == 0  # nothing answers while down: no ack alarm
    drive(loop, link, clock, Path(lambda t: None, up_s + 0.1))
    assert loop.fault.startswith(f"no state from the arm in {up_s:g} s") and "200 ms" in loop.fault


def test_an_arm_refusing_every_move_is_a_fault_too():
    loop, link, clock = make()
    drive(loop, link, clock, Path(lambda t: worker(4.0, 5.0), 1.5))  # the start-up stop acknowledged: at work
    assert loop.status()["state"] == "NORMAL" and loop.fault == ""
    link.answer = "refused"  # e.g. an arm switched to its local mode
    drive(loop, link, clock, Path(lambda t: worker(4.0, 5.0), clock.t + 1.0))
    s = loop.status()
    assert s["fault"].startswith("the arm did not confirm move: answered 'refused'") and s["refused"] >= 4


# ------------------------------------------------------------------ whole-body speed and separation

def make_whole_body(loop_params: dict | None = None, **zones):
    """A loop with the shipped whole-body separation (``loop_params``: LoopParams fields other than the
    shipped ones); the fake arm reports no joint angles, so its end effector stands for it (a tool-sized sphere)."""
    from dataclasses import replace

    loop, link, clock = make(zones=ZoneParams(**zones),
                             params=LoopParams(task_waypoints_m=((0.0, 0.14, 0.8),), **(loop_params or {})))
    link._state = replace(link._state, joint_positions_rad=np.full(7, np.nan))
    return loop, link, clock


def at_tool_height(z):
    """(17, 3) joints all at the effector's height, ``z`` out on the +z side (one point, whose
    largest body radius, the pelvis's 0.15 m, decides)."""
    j = np.zeros((17, 3))
    j[:] = (0.0, 0.14, z)
    return j


def speeds(link):
    return [c[1] for c in link.calls if c[0] == "set_speed"]


def test_whole_body_the_arm_slows_as_a_worker_comes_closer_and_speeds_up_when_he_leaves():
    # the full-speed stopping time (shipped before session 14), for which these distances were chosen: with T_s
    # scaling with the arm's speed (shipped) it slows less at 1.55 m (0.48 m/s), the same shape
    loop, link, clock = make_whole_body(stop_time_scales=False)
    # from 2.5 m out he edges closer at 0.25 m/s (slower than "keeps coming") to 1.55 m, stays, then leaves
    where = lambda t: at_tool_height(0.8 + (6.0 if t < 2 else max(1.55, 2.5 - 0.25 * (t - 2)) if t < 8 else 8.0))  # noqa: E731
    frames = drive(loop, link, clock, Path(where, 11.0))
    sent = speeds(link)
    assert sent[0] == pytest.approx(0.6)                                  # full speed at work
    k = sent.index(min(sent))
    assert 0.0 < sent[k] < 0.3 and frames[int(7.9 * 30)].state == "NORMAL"  # much slower, still working
    assert sent[:k + 1] == sorted(sent[:k + 1], reverse=True)             # only slower while he comes
    assert sent[-1] == pytest.approx(0.6) and frames[-1].state == "NORMAL"  # full speed once he left
    s = loop.status()
    assert s["speed_changes"] == len(sent) and s["command_alarm"] == "" and s["unacked"] == 0


def test_stop_only_never_scales_the_speed():
    loop, link, clock = make_whole_body(speed_scaling=False)
    frames = drive(loop, link, clock, Path(lambda t: at_tool_height(0.8 + (6.0 if t < 2 else 1.5)), 4.0))
    assert speeds(link) == [] and frames[-1].state == "LEVEL1"


def test_a_retraction_goes_at_full_speed():
    loop, link, clock = make_whole_body()
    # he stands 1.5 m out (the arm slows down), then walks at the arm
    where = lambda t: at_tool_height(0.8 + (6.0 if t < 2 else 1.5 if t < 3.5 else max(0.5, 1.5 - 1.2 * (t - 3.5))))  # noqa: E731
    drive(loop, link, clock, Path(where, 5.0))
    names = link.names()
    assert "retract" in names
    before = [c for c in link.calls[:names.index("retract")] if c[0] == "set_speed"]
    assert min(c[1] for c in before) < 0.6 and before[-1][1] == pytest.approx(0.6)


def test_an_unacknowledged_speed_override_is_counted_and_sent_again():
    loop, link, clock = make_whole_body()
    drive(loop, link, clock, Path(lambda t: at_tool_height(6.8), 2.0))
    link.answer = None                                                   # the arm stops answering
    drive(loop, link, clock, Path(lambda t: at_tool_height(2.3), 2.6))  # 1.5 m out: slower
    s = loop.status()
    assert s["unacked"] >= 1 and s["retries"] >= 1 and s["command_alarm"].startswith("speed")
    assert len(set(speeds(link)[1:])) == 1 and len(speeds(link)) >= 3   # the same limit, sent again


@dataclass
class Pose:
    """What the loop reads of a LiftedPose."""

    joints_cam_m: np.ndarray
    valid: bool
    reason: str | None
    observed: np.ndarray


def lifted(joints=None, reason=None):
    if joints is None:
        return Pose(np.full((17, 3), np.nan), False, reason, np.zeros(17, bool))
    return Pose(joints, True, None, np.ones(17, bool))


def drive_poses(loop, link, clock, frames_fn, seconds, fps=30.0, tick_s=0.01):
    """``frames_fn(t) -> [(id, pose)]`` fed through ``feed_poses`` at ``fps``; the records."""
    out, next_frame = [], 0.0
    while clock.t < seconds:
        if clock.t + 1e-9 >= next_frame:
            out.append(loop.feed_poses(frames_fn(clock.t)))
            next_frame += 1 / fps
        loop.tick()
        link.advance(tick_s)
        clock.t = round(clock.t + tick_s, 9)
    return out


def test_one_persons_invalid_lift_stops_the_arm_only_when_he_could_be_near():
    far, near = at_tool_height(0.8 + 4.0), at_tool_height(0.8 + 1.45)
    hidden = "missing_joints: left_hip"
    for where, stops in ((far, False), (near, True)):
        loop, link, clock = make_whole_body()
        # seen validly for 2 s with a colleague far off, then his lift goes invalid for 0.5 s
        frames = drive_poses(loop, link, clock, lambda t, where=where: [(1, lifted(at_tool_height(8.0)))] + [
            (0, lifted(where) if t < 2.0 else lifted(None, hidden))], 2.5)
        assert frames[int(1.9 * 30)].state == "NORMAL"
        # near: his reachable set would stop the arm, so it retracts from where he was last seen ([zones]
        # lost_reach_retracts); far: it works on
        assert (frames[-1].state == "LEVEL2" and "retract" in link.names()) == stops
        assert (frames[-1].state == "NORMAL") == (not stops) and loop.status()["unseen"] > 0


def test_a_person_never_lifted_validly_stops_the_arm_and_nobody_detected_does_not():
    loop, link, clock = make_whole_body()
    frames = drive_poses(loop, link, clock, lambda t: [(1, lifted(at_tool_height(8.0)))] + (
        [(0, lifted(None, "missing_joints: right_ankle"))] if t >= 2.0 else [(0, lifted(None, "no_person: x"))]), 2.2)
    assert frames[int(1.9 * 30)].state == "NORMAL"
    assert frames[-1].state == "FAULT" and frames[-1].reason.startswith("person_unseen: person 0")
    assert "stop" in link.names()


def test_a_retraction_that_carries_the_arm_toward_someone_is_replaced_by_one_straight_to_the_base():
    from dataclasses import replace

    from edge_runtime.robot.hazard import arm_capsules, body_spheres, separation_m

    person_at = lambda z: at_tool_height(z)  # noqa: E731
    qs = [np.array([a, -0.5, 0.0, 1.2, 0.0, 0.4, 0.0]) for a in np.linspace(-2.0, 2.0, 17)]
    sep = lambda q, z: separation_m(*body_spheres(person_at(z)), arm_capsules(q))  # noqa: E731
    q_far = max(qs, key=lambda q: sep(q, 2.0))
    q_near = min(qs, key=lambda q: sep(q, 2.0))
    # where he stands within reach_retract_m of the arm at q_far (the arm retracts), and the arm at q_near is
    # well over retract_backfire_m closer to him
    z = next(z for z in np.arange(3.0, 0.5, -0.02) if sep(q_far, z) < 0.8)
    assert sep(q_near, z) < sep(q_far, z) - 0.3
    for moves_toward_him in (False, True):
        loop, link, clock = make_whole_body()
        link._state = replace(link._state, joint_positions_rad=q_far)
        drive_poses(loop, link, clock, lambda t: [(0, lifted(person_at(8.0)))], 2.0)
        drive_poses(loop, link, clock, lambda t: [(0, lifted(person_at(z)))], 2.3)
        assert link.names()[-1] == "retract" or "retract" in link.names()
        n_retract = len(link.calls)
        if moves_toward_him:  # the controller's joint-space path swings the arm toward him
            link._state = replace(link._state, joint_positions_rad=q_near)
        hand = link.state.ee_position_m.copy()
        frames = drive_poses(loop, link, clock, lambda t: [(0, lifted(person_at(z)))], 2.5)
        assert frames[-1].state == "LEVEL2" and loop.status()["backfired"] == int(moves_toward_him)
        if moves_toward_him:  # the straight retraction toward the base instead, from where the hand is
            target = np.array(next(c for c in link.calls[n_retract:] if c[0] == "retract")[1])
            assert np.linalg.norm(target[[0, 2]]) < np.linalg.norm(hand[[0, 2]]) - 0.1
            assert abs(target[0] * hand[2] - target[2] * hand[0]) < 1e-6        # along the same bearing


def test_someone_within_reach_of_a_finished_retraction_turns_the_arm_about_its_base_away_from_him():
    import math

    loop, link, clock = make_whole_body()
    # he walks up to the tool and stays within reach of it (nothing further toward the base helps)
    where = lambda t: at_tool_height(0.8 + (6.0 if t < 2 else max(0.3, 3.0 - 1.5 * (t - 2))))  # noqa: E731
    drive_poses(loop, link, clock, lambda t: [(0, lifted(where(t)))], 9.0)
    retracts = [np.array(c[1]) for c in link.calls if c[0] == "retract"]
    assert len(retracts) >= 3
    bearing = lambda p: math.degrees(math.atan2(p[0], p[2]))  # noqa: E731
    first, turns = retracts[0], retracts[1:]
    assert abs(bearing(first)) < 1.0                                    # Eq. 6: straight back from him, toward the base
    # then round the base (the arm as a whole: the same distance from its axis) to where it is clearest of him,
    # away from him (the fake arm reports no joint angles: its hand stands for it), at most
    # escape_turn_max_deg (30) a command, each planned again from where the last one ended, all one way
    steps = np.diff([bearing(p) for p in [first, *turns]])
    assert (np.abs(steps) <= 30.0 + 1e-6).all() and (np.sign(steps) == np.sign(steps[0])).all()
    # until he is out of its reach (reach_retract_m): a quarter turn from him here
    assert abs(bearing(turns[-1]) - bearing(where(9.0)[0])) >= 89.0
    # each turn keeps the hand where the last one left it from the axis: where the retraction ended, within the
    # tolerance of a finished motion
    radius_m = np.linalg.norm(turns[0][[0, 2]])
    assert abs(radius_m - np.linalg.norm(first[[0, 2]])) <= loop.params.waypoint_tolerance_m
    for turned in turns:
        assert np.linalg.norm(turned[[0, 2]]) == pytest.approx(radius_m, abs=1e-6)
    assert loop.status()["backfired"] == 0 and loop.status()["escapes"] == len(turns)


def at_point(x, z):
    """(17, 3) joints all at one point at the effector's height (as :func:`at_tool_height`)."""
    j = np.zeros((17, 3))
    j[:] = (x, 0.14, z)
    return j


def test_the_escape_is_planned_again_while_level_2_lasts_as_he_walks_round_the_base():
    loop, link, clock = make_whole_body()

    def where(t):  # up to the tool, then round the base 0.75 m from its axis, within reach of the arm all along
        if t < 7.0:
            return at_point(0.0, 6.8 if t < 2 else max(0.75, 3.8 - 1.5 * (t - 2)))
        a = min(math.pi, 0.9 * (t - 7.0))
        return at_point(0.75 * math.sin(a), 0.75 * math.cos(a))

    drive_poses(loop, link, clock, lambda t: [(0, lifted(where(t)))], 7.0)
    before = len(link.calls)
    frames = drive_poses(loop, link, clock, lambda t: [(0, lifted(where(t)))], 12.0)
    entry = next(i for i, f in enumerate(frames) if f.state == "LEVEL2")
    assert all(f.state == "LEVEL2" for f in frames[entry:int(3.5 * 30)])   # one level 2 while he walks round
    # the turns about the base in it: retractions that keep the hand's distance from the axis and turn the tool
    # by as much as its bearing (the arm turned as a whole)
    turns = [(np.array(c[1]), c[3]) for c in link.calls[before:] if c[0] == "retract"]
    rotations = [(p, y) for (p0, y0), (p, y) in zip(turns, turns[1:])
                 if abs(np.hypot(p[0], p[2]) - np.hypot(p0[0], p0[2])) < 0.04
                 and abs(math.remainder(math.atan2(p[0], p[2]) - math.atan2(p0[0], p0[2]) - (y - y0), 2 * math.pi)) < 0.05]
    assert len(rotations) >= 2
    bearing = lambda p: math.degrees(math.atan2(p[0], p[2]))  # noqa: E731
    him = where(12.0)[0]
    assert abs(math.remainder(math.radians(bearing(turns[-1][0]) - bearing(him)), 2 * math.pi)) > math.radians(90.0)


def _backfiring_at(him, radial_retract_stops=True):
    """A whole-body loop whose Eq. 6 retraction from ``him`` the controller swings toward him: the arm's
    postures turned away from him, to his side and at him (each well nearer him than the last), a step
    that puts the fake arm in one (``to(q, yaw=None)``) and one that drives the loop on and gives the stops
    and retractions it sent (``drive(t_end)``). By default the straight retraction that replaces a backfiring
    one is stopped when it backfires too (``radial_retract_stops``), so that the stopped arm's escape turn is
    reached."""
    from dataclasses import replace

    posture = lambda j0: np.array([j0, -0.5, 0.0, 1.2, 0.0, 0.4, 0.0])  # noqa: E731
    q_away, q_side, q_at = (posture(math.radians(a)) for a in (180.0, 45.0, 0.0))
    loop, link, clock = make_whole_body({"radial_retract_stops": radial_retract_stops})

    def to(q, yaw=None):
        link._state = replace(link._state, joint_positions_rad=q, **({} if yaw is None else {"yaw_rad": yaw}))

    def drive(t_end):
        n = len(link.calls)
        drive_poses(loop, link, clock, lambda t: [(0, lifted(him))], t_end)
        return [c for c in link.calls[n:] if c[0] in ("stop", "retract")]

    to(q_away)
    drive_poses(loop, link, clock, lambda t: [(0, lifted(at_point(0.0, 8.0)))], 2.0)
    return loop, link, (q_away, q_side, q_at), to, drive


def test_a_backfired_retraction_falls_back_straight_and_a_stopped_arm_turns_clear_of_him():
    from edge_runtime.robot.hazard import arm_capsules, body_spheres, separation_m, turned_capsules

    him = at_point(0.0, 1.0)
    sep = lambda q: separation_m(*body_spheres(him), arm_capsules(q))  # noqa: E731
    loop, link, (q_away, q_side, q_at), to, drive = _backfiring_at(him)
    assert sep(q_away) < ZoneParams().reach_retract_m and sep(q_side) < sep(q_away) - 0.2 and sep(q_at) < sep(q_side) - 0.2
    eq6 = drive(2.2)[0]
    assert eq6[0] == "retract"
    # the controller's joint-space path swings the arm toward him, the tool half way through its turn
    to(q_side, eq6[3] / 2 + 0.3)
    fallback = drive(2.3)[0]
    assert loop.status()["backfired"] == 1 and fallback[0] == "retract"
    # straight toward the base, the tool kept at the given-up retraction's yaw (holding the yaw it had on the way gave
    # the controller another fold: hard:200 seed 13 hard_023)
    assert np.hypot(fallback[1][0], fallback[1][2]) < np.hypot(*link.state.ee_position_m[[0, 2]]) - 0.1
    assert abs(math.remainder(math.atan2(fallback[1][0], fallback[1][2])
                              - math.atan2(*link.state.ee_position_m[[0, 2]]), 2 * math.pi)) < 1e-6
    assert fallback[3] == pytest.approx(eq6[3])
    # the straight retraction swings it nearer still: a stop, then (planned again from where it stopped) a turn
    # about the base clear of him
    to(q_at)
    hand, yaw = link.state.ee_position_m.copy(), link.state.yaw_rad
    after = drive(2.4)
    assert loop.status()["backfired"] == 2 and after[0][0] == "stop" and after[1][0] == "retract"
    target, turned_yaw = np.array(after[1][1]), after[1][3]
    turn = math.remainder(math.atan2(target[0], target[2]) - math.atan2(hand[0], hand[2]), 2 * math.pi)
    assert np.hypot(target[0], target[2]) == pytest.approx(np.hypot(hand[0], hand[2])) and target[1] == pytest.approx(hand[1])
    assert math.remainder(turned_yaw - yaw - turn, 2 * math.pi) == pytest.approx(0.0, abs=1e-9)
    assert abs(turn) <= math.radians(30.0) + 1e-9                       # escape_turn_max_deg a command
    assert separation_m(*body_spheres(him), turned_capsules(arm_capsules(q_at), turn)) > sep(q_at) + 0.3
    assert loop.status()["escapes"] == 1


@pytest.mark.parametrize("radial_retract_stops", [True, False])
def test_the_straight_retraction_toward_the_base_is_stopped_when_it_backfires_only_if_configured(radial_retract_stops):
    him = at_point(0.0, 1.0)
    loop, link, (_, q_side, q_at), to, drive = _backfiring_at(him, radial_retract_stops)
    eq6 = drive(2.2)[0]
    to(q_side, eq6[3])  # the first retraction swings the arm toward him: the straight one instead
    assert loop.status()["backfired"] == 0 and drive(2.3)[0][0] == "retract" and loop.status()["backfired"] == 1
    to(q_at)  # and the straight one swings it nearer still
    sent = [c[0] for c in drive(2.5)]
    if radial_retract_stops:
        assert loop.status()["backfired"] == 2 and sent[:1] == ["stop"]
    else:  # it runs to its end: nothing replaces it
        assert loop.status()["backfired"] == 1 and "stop" not in sent


def _turning_from(him):
    """:func:`_backfiring_at` driven to its escape turn (sent at t = 2.4 s)."""
    loop, link, (_, q_side, q_at), to, drive = _backfiring_at(him)
    eq6 = drive(2.2)[0]
    to(q_side, eq6[3])
    drive(2.3)
    to(q_at)
    return loop, link, q_at, to, drive


def test_an_escape_turn_that_brings_the_arm_nearer_him_is_stopped_and_planned_again_from_there():
    from edge_runtime.robot.hazard import arm_capsules, body_spheres, separation_m

    him = at_point(0.0, 1.0)
    loop, link, q_at, to, drive = _turning_from(him)
    assert [c[0] for c in drive(2.4)] == ["stop", "retract"] and loop.status()["escapes"] == 1
    # on its way the controller's IK moves other joints than the base and takes the arm nearer him than where the
    # turn began, by more than retract_backfire_m
    nearer = q_at + np.array([0.0, 0.0, -0.2, -0.2, 0.0, 0.0, 0.0])
    gap = separation_m(*body_spheres(him), arm_capsules(q_at)) - separation_m(*body_spheres(him), arm_capsules(nearer))
    assert gap > LoopParams().retract_backfire_m
    to(nearer)
    link.target = None  # the fake arm stays where it is put
    assert [c[0] for c in drive(2.5)] == ["stop"] and loop.status()["escapes_stopped"] == 1
    assert loop.status()["backfired"] == 3     # counted with the retractions' backfires
    # no straight fallback with the turn's tool yaw: planned again from the stopped posture after escape_replan_s
    again = drive(3.0)
    assert again and again[0][0] == "retract" and loop.status()["escapes"] == 2


def test_a_refused_escape_turn_is_a_stop_and_the_turn_is_planned_again():
    loop, link, q_at, to, drive = _turning_from(at_point(0.0, 1.0))
    link.unreachable_retract = True  # the controller refuses the turned target
    sent = drive(2.5)
    assert [c[0] for c in sent] == ["stop", "retract", "stop"]   # no straight fallback with the turn's tool yaw
    assert loop.status()["escapes_stopped"] == 1 and loop.status()["unreachable"] == 1
    link.unreachable_retract = False  # it would take a turn again: planned once escape_replan_s has passed
    again = drive(3.0)
    assert [c[0] for c in again] == ["retract"] and loop.status()["escapes"] == 2
    assert loop.status()["reason"] != "retract_unreachable"


def test_the_loop_keeps_reaction_times_not_frame_records():
    import weakref
    logged, refs = [], []
    loop, link, clock = make_whole_body()
    loop.on_record = lambda rec: (refs.append(weakref.ref(rec)),
                                  logged.append((rec.t_in_s, rec.t_command_s, rec.command)))
    # a worker walks in from 5 m to 0.5 m: speed changes, a stop or retraction on the way
    drive_poses(loop, link, clock, lambda t: [(0, lifted(at_tool_height(max(0.5, 5.0 - 1.5 * t))))], 3.5)
    commanding = [(t_cmd - t_in) for t_in, t_cmd, _ in logged if t_cmd is not None]
    assert len(logged) > 90 and len(commanding) >= 2
    assert list(loop.reactions_s) == commanding
    assert all(r() is None for r in refs)  # the loop holds none of the records it made
