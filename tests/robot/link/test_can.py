"""edge_runtime.robot.link.can: the CAN link against the simulated controller, on a virtual
bus, through the socketcand hub, and against the controller process."""
from __future__ import annotations

import numpy as np
import pytest
from support.robot import TARGET, InProcessController, can_link, exercise_live_controller, pump, start_simulated

from firmware_sim.robot.controller import SawyerProcess, SimulatedRobot


def test_a_target_without_its_direction_half_is_refused_as_invalid():
    with SimulatedRobot("can") as sim:
        start_simulated(sim)
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


@pytest.mark.slow
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
