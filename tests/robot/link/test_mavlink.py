"""edge_runtime.robot.link.mavlink: signed MAVLink 2 against the controller process on a
pseudo-terminal, and in-process on a socket pair."""
from __future__ import annotations

import io
import math
import socket

import pytest
from pymavlink.dialects.v20 import common as mavlink2
from support.robot import exercise_live_controller, pump, start_simulated

from edge_runtime.robot.link.base import open_link
from edge_runtime.robot.link.mavlink import MavlinkRobotLink
from edge_runtime.robot.link.protocol import ROBOT_COMPID, ROBOT_SYSID, SocketStream, make_mavlink
from firmware_sim.robot.controller import TEST_SIGNING_KEY, SawyerProcess, SimulatedRobot


@pytest.mark.slow
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
        start_simulated(sim)
        sim.controller.port.mav.signing.secret_key = bytes(32)  # the controller now signs with another key
        sim.step(0.3)
        assert not sim.link.link_ok and sim.link.stats.integrity_errors > 20 and sim.link.stats.outages == 1
        assert sim.link.state.t_s < sim.clock() - 0.2
        assert isinstance(sim.link, MavlinkRobotLink) and TEST_SIGNING_KEY != bytes(32)


def test_a_non_finite_arm_state_is_refused_and_counted_never_raised():
    """A controller reporting NaN/inf (a faulty arm, correctly signed) makes poll() refuse
    and count those states; the next sound state is used again."""
    a, b = socket.socketpair()
    link = MavlinkRobotLink(stream=SocketStream(b), signing_key=TEST_SIGNING_KEY, clock=lambda: 0.0)
    arm = make_mavlink(SocketStream(a), ROBOT_SYSID, ROBOT_COMPID, TEST_SIGNING_KEY, 0)
    try:
        for value in (math.nan, math.inf, 0.5):
            arm.attitude_send(0, 0.0, value, 0.0, 0.0, 0.0, 0.0)
            arm.actuator_output_status_send(0, 0, [value] * 32 if value != 0.5 else [0.0] * 32)
            arm.heartbeat_send(mavlink2.MAV_TYPE_GENERIC, mavlink2.MAV_AUTOPILOT_GENERIC, 0, 0, 0)
            state = link.poll()
            assert (state is None) == (value != 0.5)
        assert link.stats.states_refused == 2 and link.stats.states == 1
        assert link.last_refused_state.startswith("joint_positions_rad")
    finally:
        link.close()
        a.close()
