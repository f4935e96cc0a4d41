"""Both ends of the robot link: the simulated Sawyer controller and edge_runtime.robot.link.base.

In-process on a simulated clock (SimulatedRobot: python-can's virtual bus, a socket pair),
through the socketcand hub, and against the controller process on a pseudo-terminal.
"""
from __future__ import annotations

import io
import math
import time

import numpy as np
import pytest
from support.robot import InProcessController, can_link, pump

from edge_runtime.robot.link.base import LinkConfig, open_link
from edge_runtime.robot.link.can import CanRobotLink
from edge_runtime.robot.link.mavlink import MavlinkRobotLink
from edge_runtime.robot.link.protocol import (
    CanStateAssembler,
    RobotCanCodec,
    make_mavlink,
    mav_to_robot,
    pack_status,
    robot_to_mav,
    tool_pitch_yaw,
    tool_quaternion,
    unpack_status,
)
from firmware_sim.robot.controller import (
    TEST_SIGNING_KEY,
    SawyerProcess,
    SimulatedRobot,
)

TARGET = (0.45, 0.25, 0.55)
LINKS = ("can", "mavlink")


def start(sim: SimulatedRobot) -> None:
    sim.step(0.05)
    seq = sim.link.resume()
    sim.step(0.05)
    assert sim.link.result(seq) == "ok" and sim.link.state.mode == "run"


# ----------------------------------------------------------------------------------------------
# protocol pieces

def test_codec_round_trips_a_state_through_the_dbc_with_e2e():
    tx, rx = RobotCanCodec(), RobotCanCodec()
    with SimulatedRobot("can") as sim:
        st = sim.controller.snapshot()
    asm = CanStateAssembler()
    got = None
    for frame in tx.state_frames(st):
        status, name, sig = rx.decode(frame)
        assert sig is not None, status
        got = asm.feed(name, sig, 1.0) or got
    assert got is not None
    assert np.allclose(got.ee_position_m, st.ee_position_m, atol=1e-4)
    assert np.allclose(got.joint_positions_rad, st.joint_positions_rad, atol=2e-4)
    assert got.mode == st.mode and got.light == st.light
    corrupted = tx.state_frames(st)[0]
    corrupted.data[3] ^= 0x40
    assert rx.decode(corrupted)[2] is None and rx.checker.counts["wrong_crc"] == 1


def test_mavlink_frame_and_status_conventions():
    p = np.array([0.3, -0.2, 0.9])
    assert np.allclose(mav_to_robot(*robot_to_mav(p)), p)
    assert robot_to_mav((0, 0, 1))[0] == 1 and robot_to_mav((0, 1, 0))[2] == -1  # forward is x, up is -z
    assert tool_pitch_yaw(tool_quaternion(-0.7, 2.9)) == pytest.approx((-0.7, 2.9))
    st = dict(mode="retract", watchdog=True, moving=True, at_target=False, last_result="refused",
              last_command="move", last_seq=4321)
    assert unpack_status(pack_status(**st)) == st


def test_registry_and_bad_input():
    with pytest.raises(ValueError, match="kind"):
        open_link("carrier-pigeon")
    with SimulatedRobot("can") as sim:
        assert isinstance(sim.link, CanRobotLink) and sim.link.kind == "can"
        with pytest.raises(ValueError, match="position_m"):
            sim.link.move_to((float("nan"), 0, 0), 0.0, 0.0)
        with pytest.raises(ValueError, match="light"):
            sim.link.set_alarm("purple", 100.0, 50.0)
        with pytest.raises(ValueError, match="pitch"):
            sim.link.move_to(TARGET, 2.0, 0.0)


# ----------------------------------------------------------------------------------------------
# the simulated pair (virtual CAN bus / socket pair, simulated clock)

@pytest.mark.parametrize("kind", LINKS)
def test_move_converges_and_stop_halts(kind):
    with SimulatedRobot(kind) as sim:
        start(sim)
        seq = sim.link.move_to(TARGET, 0.0, 0.3)
        sim.step(0.3)
        assert sim.link.result(seq) == "ok" and sim.link.state.moving
        sim.step(4.0)
        st = sim.link.state
        assert np.linalg.norm(st.ee_position_m - TARGET) < 1e-3
        assert st.pitch_rad == pytest.approx(0.0, abs=0.02) and st.yaw_rad == pytest.approx(0.3, abs=0.02)
        assert st.at_target and not st.moving and st.last_seq == seq

        far = sim.link.move_to((-0.3, 0.5, 0.7), 0.5, -0.5)
        sim.step(0.4)
        assert sim.link.state.ee_speed_mps > 0.1
        stop = sim.link.stop()
        sim.step(0.05)
        assert sim.link.result(stop) == "ok"
        sim.step(0.5)
        st = sim.link.state
        assert st.mode == "stopped" and not st.moving and st.ee_speed_mps == 0.0
        assert np.linalg.norm(st.ee_position_m - (-0.3, 0.5, 0.7)) > 0.05  # it did not go on to the target
        refused = sim.link.move_to(TARGET, 0.0, 0.0)
        sim.step(0.05)
        assert sim.link.result(refused) == "refused" and sim.link.stats.refused == 1
        assert sim.link.result(far) == "ok"


@pytest.mark.parametrize("kind", LINKS)
def test_unreachable_target_is_refused_and_an_unreachable_retract_stops(kind):
    with SimulatedRobot(kind) as sim:
        start(sim)
        seq = sim.link.move_to(TARGET, 0.0, 0.0)
        sim.step(0.3)
        bad = sim.link.move_to((0.0, 0.3, 1.7), 0.0, 0.0)
        sim.step(0.05)
        assert sim.link.result(bad) == "unreachable"
        sim.step(4.0)
        assert np.linalg.norm(sim.link.state.ee_position_m - TARGET) < 1e-3  # kept its previous goal
        assert sim.link.result(seq) == "ok"
        r = sim.link.retract((0.0, -0.6, 0.05), 0.0, 0.0)  # inside the pedestal
        sim.step(0.05)
        assert sim.link.result(r) == "unreachable" and sim.link.state.mode == "stopped"
        ok = sim.link.retract((0.3, 0.4, 0.3), 0.0, math.pi)  # retraction works while stopped
        sim.step(3.0)
        assert sim.link.result(ok) == "ok" and sim.link.state.mode == "retract"
        assert np.linalg.norm(sim.link.state.ee_position_m - (0.3, 0.4, 0.3)) < 1e-3


@pytest.mark.parametrize("kind", LINKS)
def test_every_command_gets_its_answer_even_several_in_one_cycle(kind):
    with SimulatedRobot(kind) as sim:
        start(sim)
        seqs = [sim.link.set_alarm("red", 2000.0, 70.0), sim.link.move_to((0.0, 0.3, 1.7), 0.0, 0.0),
                sim.link.retract(TARGET, 0.0, 0.0), sim.link.move_to(TARGET, 0.0, 0.0), sim.link.stop()]
        sim.step(0.01)
        assert [sim.link.result(s) for s in seqs] == ["ok", "unreachable", "ok", "refused", "ok"]
        assert sim.link.stats.refused == 2


def test_a_target_without_its_direction_half_is_refused_as_invalid():
    with SimulatedRobot("can") as sim:
        start(sim)
        link = sim.link
        orient, position = link.codec.target_frames(77, np.array(TARGET), 0.0, 0.0, retract=False)
        link.bus.send(position)  # the direction half was lost
        sim.step(0.05)
        assert sim.controller.last_result == "invalid" and sim.controller.port.counters["incomplete_targets"] == 1
        link.bus.send(orient)
        sim.step(0.2)  # the position half comes too late
        link.bus.send(link.codec.target_frames(78, np.array(TARGET), 0.0, 0.0, retract=False)[1])
        sim.step(0.05)
        assert sim.controller.port.counters["incomplete_targets"] == 2
        assert sim.controller.arm.goal_rad is None and not sim.link.state.moving
        ok = link.move_to(TARGET, 0.0, 0.0)  # both halves: accepted
        sim.step(0.05)
        assert link.result(ok) == "ok"


@pytest.mark.parametrize("kind", LINKS)
def test_watchdog_trips_200ms_after_silence_and_clears_only_on_resume(kind):
    quiet = LinkConfig(heartbeat_period_s=None)  # the runtime sends nothing unless told
    with SimulatedRobot(kind, link_config=quiet) as sim:
        sim.step(0.05)
        sim.link.resume()
        sim.step(0.01)
        sim.link.move_to((-0.2, 0.4, 0.6), 0.0, 0.0)
        for _ in range(10):  # a live runtime: heartbeats every 50 ms
            sim.link.heartbeat()
            sim.step(0.05)
        assert not sim.link.state.watchdog and sim.link.state.moving
        sim.step(0.18)  # 50 ms since the last heartbeat + 180 ms of silence: past the 200 ms
        trips = sim.controller.counters["watchdog_trips"]
        assert trips == 1 and sim.link.state.watchdog and sim.link.state.mode == "stopped"

    with SimulatedRobot(kind, link_config=quiet) as sim:
        sim.step(0.05)
        sim.link.resume()
        last = sim.clock()
        while sim.clock() - last < 0.19:
            sim.step(0.01)
        assert not sim.link.state.watchdog  # 190 ms of silence is tolerated
        sim.step(0.03)
        assert sim.link.state.watchdog
        sim.step(0.5)
        assert not sim.link.state.moving
        for _ in range(5):  # heartbeats alone do not restart the arm
            sim.link.heartbeat()
            sim.step(0.05)
        assert sim.link.state.watchdog
        refused = sim.link.move_to(TARGET, 0.0, 0.0)
        sim.step(0.02)
        assert sim.link.result(refused) == "refused"
        ok = sim.link.resume()
        sim.step(0.02)
        assert sim.link.result(ok) == "ok" and not sim.link.state.watchdog and sim.link.state.mode == "run"


@pytest.mark.parametrize("kind", LINKS)
def test_light_and_tone_round_trip(kind):
    with SimulatedRobot(kind) as sim:
        start(sim)
        assert sim.link.state.light == "off" and sim.link.state.tone_hz == 0
        for light, hz, db in (("red", 2000.0, 70.0), ("yellow", 4000.0, 80.5), ("green", 0.0, 0.0)):
            seq = sim.link.set_alarm(light, hz, db)
            sim.step(0.05)
            st = sim.link.state
            assert (st.light, st.tone_hz, st.tone_db) == (light, hz, db)
            assert sim.link.result(seq) == "ok" and st.last_command == "alarm"


@pytest.mark.parametrize("kind", LINKS)
def test_ten_simulated_seconds_run_without_sleeping(kind, monkeypatch):
    """The simulation needs no wall clock: sleeping or reading time.monotonic would fail here."""
    def forbidden(*_a, **_k):
        raise AssertionError("the simulated robot must not sleep or read the monotonic clock")

    with SimulatedRobot(kind) as sim:
        monkeypatch.setattr(time, "sleep", forbidden)
        monkeypatch.setattr(time, "monotonic", forbidden)
        start(sim)
        targets = [(0.45, 0.25, 0.55), (-0.2, 0.4, 0.6), (0.3, -0.1, 0.7)]
        wall = time.perf_counter()
        for i in range(10):
            if i % 3 == 0:
                sim.link.move_to(targets[(i // 3) % 3], 0.0, 0.0)
            sim.step(1.0)
        wall = time.perf_counter() - wall
        monkeypatch.undo()
        assert sim.clock() == pytest.approx(10.1, abs=1e-6)
        assert sim.link.link_ok and sim.link.stats.outages == 0 and not sim.link.state.watchdog
        assert sim.link.stats.states >= 990  # 100 Hz state reports
        print(f"{kind}: 10 simulated seconds in {wall:.2f} s of wall time")


# ----------------------------------------------------------------------------------------------
# through the socketcand hub









def test_corrupted_frames_are_counted_and_ignored(hub):
    with InProcessController(hub) as ctl:
        link = can_link(hub)
        try:
            seq = link.resume()
            assert pump(link, 2.0, lambda: link.result(seq) == "ok")
            hub.corrupt = 1.0
            errors = ctl.port.counters["integrity_errors"]
            link.set_alarm("red", 2000.0, 70.0)
            link.move_to(TARGET, 0.0, 0.0)
            pump(link, 0.3)
            assert ctl.port.counters["integrity_errors"] >= errors + 3
            assert ctl.light == "off" and ctl.arm.goal_rad is None and ctl.last_command == "resume"
            assert link.stats.integrity_errors > 0 and not link.link_ok  # its state frames are corrupted too
            hub.corrupt = 0.0
            seq = link.resume()
            assert pump(link, 2.0, lambda: link.link_ok and link.result(seq) == "ok")
        finally:
            link.close()


def exercise_live_controller(link) -> None:
    """Against a controller process in real time: move, light and tone, watchdog, stop."""
    seq = link.resume()
    assert pump(link, 3.0, lambda: link.result(seq) == "ok")
    move = link.move_to(TARGET, 0.0, 0.0)
    assert pump(link, 8.0, lambda: link.state.at_target and link.state.last_seq == move)
    assert np.linalg.norm(link.state.ee_position_m - TARGET) < 1e-3
    alarm = link.set_alarm("yellow", 4000.0, 80.0)
    alarm_state = lambda: (link.state.light, link.state.tone_hz, link.state.tone_db)  # noqa: E731
    assert pump(link, 2.0, lambda: alarm_state() == ("yellow", 4000.0, 80.0))
    assert link.result(alarm) == "ok"

    link.move_to((-0.2, 0.4, 0.6), 0.0, 0.0)
    assert pump(link, 2.0, lambda: link.state.moving)
    time.sleep(0.4)  # the runtime goes quiet: no heartbeat, no command
    assert pump(link, 1.0, lambda: link.state.watchdog and link.state.mode == "stopped")
    assert pump(link, 2.0, lambda: not link.state.moving and link.state.ee_speed_mps == 0.0)
    pump(link, 0.3)  # heartbeats again: still latched
    assert link.state.watchdog
    seq = link.resume()
    assert pump(link, 2.0, lambda: link.result(seq) == "ok" and not link.state.watchdog)

    link.move_to(TARGET, 0.3, -0.4)
    assert pump(link, 2.0, lambda: link.state.ee_speed_mps > 0.05)
    stop = link.stop()
    assert pump(link, 2.0, lambda: link.result(stop) == "ok" and link.state.mode == "stopped")
    assert pump(link, 2.0, lambda: not link.state.moving and link.state.ee_speed_mps == 0.0)
    assert np.linalg.norm(link.state.ee_position_m - TARGET) > 0.01  # halted on the way


def test_can_process_moves_and_recovers_after_the_hub_drops_everyone(hub, tmp_path):
    with SawyerProcess("can", can_port=hub.port, json_path=tmp_path / "sawyer.json") as proc:
        assert proc.endpoint == f"socketcand:127.0.0.1:{hub.port}:vcan0"
        link = can_link(hub)
        try:
            exercise_live_controller(link)

            hub.disconnect_all()
            outages = link.stats.outages
            assert pump(link, 3.0, lambda: not link.link_ok)
            assert link.stats.outages == outages + 1
            assert pump(link, 8.0, lambda: link.link_ok)
            assert link.stats.reconnects >= 1
            again = link.resume()  # the watchdog may have tripped during the outage
            assert pump(link, 3.0, lambda: link.result(again) == "ok" and not link.state.watchdog)
            stop = link.stop()
            assert pump(link, 3.0, lambda: link.result(stop) == "ok" and link.state.mode == "stopped")
        finally:
            link.close()
    result = proc.result
    assert result is not None and result["counters"]["reconnects"] >= 1
    assert result["counters"]["rx_valid"] > 10 and result["counters"]["integrity_errors"] == 0


# ----------------------------------------------------------------------------------------------
# MAVLink on a pseudo-terminal against the controller process

def test_mavlink_process_refuses_unsigned_forged_and_replayed_commands(tmp_path):
    key = bytes.fromhex("5a" * 32)
    with SawyerProcess("mavlink", signing_key=key, json_path=tmp_path / "sawyer.json") as proc:
        link = open_link("mavlink", path=proc.endpoint, signing_key=key)
        try:
            assert pump(link, 5.0, lambda: link.link_ok)
            exercise_live_controller(link)
            seq = link.resume()
            assert pump(link, 3.0, lambda: link.result(seq) == "ok")

            # a genuine alarm command, recorded on its way out
            sent = []
            write = link.stream.write
            link.stream.write = lambda data: (sent.append(bytes(data)), write(data))[1]
            red = link.set_alarm("red", 2000.0, 70.0)
            link.stream.write = write
            assert pump(link, 2.0, lambda: link.state.light == "red" and link.result(red) == "ok")
            green = link.set_alarm("green", 0.0, 0.0)
            assert pump(link, 2.0, lambda: link.state.light == "green" and link.result(green) == "ok")

            def inject(signing_key, link_id=1):
                buf = io.BytesIO()
                mav = make_mavlink(buf, 1, 191, signing_key, link_id)
                mav.command_long_send(1, 1, 193, 0, 0, 0, 0, 0, 0, 0, 999.0)  # stop
                mav.command_long_send(1, 1, 31011, 0, 3, 4000, 80, 0, 0, 0, 998.0)  # red alarm
                link.stream.write(buf.getvalue())

            inject(None)                      # unsigned
            inject(bytes.fromhex("a5" * 32))  # signed with the wrong key
            for data in sent:                 # replayed: a genuine packet again
                link.stream.write(data)
            pump(link, 0.5)
            st = link.state
            assert st.light == "green" and st.mode == "run" and link.result(999) is None and link.result(998) is None
            assert link.stats.integrity_errors == 0  # the controller's own packets all verify
        finally:
            link.close()
    c = proc.result["counters"]
    assert c["signature_unsigned"] == 2 and c["signature_forged"] == 2 and c["signature_replayed"] == len(sent) == 1
    assert c["integrity_errors"] == 5


def test_mavlink_runtime_refuses_a_controller_with_another_key():
    with SimulatedRobot("mavlink") as sim:
        start(sim)
        sim.controller.port.mav.signing.secret_key = bytes(32)  # the controller now signs with another key
        sim.step(0.3)
        assert not sim.link.link_ok and sim.link.stats.integrity_errors > 20 and sim.link.stats.outages == 1
        assert sim.link.state.t_s < sim.clock() - 0.2
        assert isinstance(sim.link, MavlinkRobotLink) and TEST_SIGNING_KEY != bytes(32)
