"""edge_runtime.robot.link.base: the registry, LinkInterface, and the RobotLink template's
behaviour over both transports against the simulated Sawyer controller, in-process on a
simulated clock (SimulatedRobot: python-can's virtual bus, a socket pair)."""
from __future__ import annotations

import math
import time

import numpy as np
import pytest
from support.robot import TARGET, FakeLink, start_simulated

from edge_runtime.robot.link.base import LinkConfig, LinkInterface, RobotLink, open_link
from edge_runtime.robot.link.can import CanRobotLink
from edge_runtime.robot.link.protocol import blank_state
from firmware_sim.robot.controller import SimulatedRobot

LINKS = ("can", "mavlink")


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
        start_simulated(sim)
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
        start_simulated(sim)
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
        start_simulated(sim)
        seqs = [sim.link.set_alarm("red", 2000.0, 70.0), sim.link.move_to((0.0, 0.3, 1.7), 0.0, 0.0),
                sim.link.retract(TARGET, 0.0, 0.0), sim.link.move_to(TARGET, 0.0, 0.0), sim.link.stop()]
        sim.step(0.01)
        assert [sim.link.result(s) for s in seqs] == ["ok", "unreachable", "ok", "refused", "ok"]
        assert sim.link.stats.refused == 2





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
        start_simulated(sim)
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
        start_simulated(sim)
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


def test_robot_links_and_stand_ins_implement_the_whole_link_interface():
    abstract = set(LinkInterface.__abstractmethods__)
    assert {"move_to", "retract", "stop", "resume", "set_alarm", "heartbeat", "set_runtime_state", "poll",
            "result", "state", "link_ok", "heartbeats_itself"} <= abstract
    assert issubclass(RobotLink, LinkInterface) and isinstance(FakeLink(), LinkInterface)

    class Partial(LinkInterface):  # a stand-in that forgot members cannot be made
        def poll(self):
            return None

    with pytest.raises(TypeError, match="abstract"):
        Partial()

    fake = FakeLink()  # refused() reads result(): unreachable, refused and invalid are refusals
    fake.unreachable_retract = True
    assert fake.refused(fake.retract((0.0, 0.14, 0.5), 0.0, 0.0)) and not fake.refused(fake.stop())


def test_a_robot_link_heartbeats_itself_only_when_it_has_a_period():
    with SimulatedRobot("can") as sim:
        assert sim.link.heartbeats_itself
    with SimulatedRobot("can", link_config=LinkConfig(heartbeat_period_s=None)) as sim:
        assert not sim.link.heartbeats_itself
        with pytest.raises(ValueError, match="runtime state"):
            sim.link.set_runtime_state("asleep")


def test_a_robot_link_without_its_transport_hooks_cannot_be_made():
    class NoTransport(RobotLink):
        def _receive(self, now):
            return [blank_state(now)]

    with pytest.raises(TypeError, match="_open_transport"):
        NoTransport()
