"""The simulated Sawyer as a strict reference end, on MAVLink 2: the runtime's packets -> controller.

An input is a burst of packets as the runtime sends them (HEARTBEAT, SET_ATTITUDE_TARGET,
SET_POSITION_TARGET_LOCAL_NED, COMMAND_LONG stop/resume, retract, alarm or another
command) with any float32 and integer values, signed with the link's key, plus packets from
a foreign system id (also signed: a second system on the same signed line), junk bytes and
flipped bytes (:func:`fuzz.targets.robot_link_mavlink.packets`). The controller is set to
take commands from the runtime's system id only. It must never raise, never execute a
command from another system, never run on a pause/continue whose param1 is not exactly 1,
and execute moves, retractions and alarms only with values in range
(:class:`fuzz.targets.sawyer_can.Watched`).
"""
from __future__ import annotations

from hypothesis import strategies as st

from edge_runtime.robot.link.protocol import (
    MAV_CMD_ALARM,
    MAV_CMD_RETRACT,
    MAV_CMD_STOP_RESUME,
    RUNTIME_COMPID,
    RUNTIME_SYSID,
)
from firmware_sim.robot.controller import TEST_SIGNING_KEY, MavlinkControllerPort, SawyerController, SimClock
from fuzz.harness import SilentAcceptance
from fuzz.targets.robot_link_mavlink import FLOAT32, ByteStream, packets, u
from fuzz.targets.sawyer_can import Watched

NAME = "sawyer_mavlink"
DOCUMENTED = ()  # the controller refuses and counts; it never raises on what it receives

PARAM1 = st.one_of(FLOAT32, st.sampled_from([0.0, 1.0]))
RUNTIME_MESSAGES = {
    "heartbeat": st.tuples(u(8), u(8), u(8), u(32), u(8)),
    "set_attitude_target": st.tuples(u(8), u(8), u(8), u(8), st.lists(FLOAT32, min_size=4, max_size=4),
                                     FLOAT32, FLOAT32, FLOAT32, FLOAT32),
    "set_position_target_local_ned": st.tuples(u(8), u(8), u(8), st.sampled_from([1, 0, 8]), u(16),
                                               *[FLOAT32] * 11),
    "command_long": st.tuples(u(8), u(8),
                              st.sampled_from([MAV_CMD_STOP_RESUME, MAV_CMD_RETRACT, MAV_CMD_ALARM, 400]), u(8),
                              PARAM1, *[FLOAT32] * 5, st.one_of(FLOAT32, st.integers(0, 70000).map(float))),
}
"""pymavlink ``<name>_encode`` argument tuples of the messages the runtime sends, any value."""


@st.composite
def streams(draw) -> bytes:
    data = draw(packets(RUNTIME_MESSAGES, RUNTIME_SYSID, RUNTIME_COMPID, TEST_SIGNING_KEY))
    if draw(st.booleans()):  # another system on the line, with the key
        data += draw(packets(RUNTIME_MESSAGES, draw(st.integers(2, 255)), RUNTIME_COMPID, TEST_SIGNING_KEY))
    return data


def strategy():
    return streams()


def run(data: bytes) -> None:
    port = MavlinkControllerPort(ByteStream(data), TEST_SIGNING_KEY, runtime_sysid=RUNTIME_SYSID)
    decode = port._decode
    raw: dict[int, object] = {}

    def watched_decode(m):
        cmd = decode(m)
        if cmd is not None:
            if m.get_srcSystem() != RUNTIME_SYSID:
                raise SilentAcceptance(f"a {m.get_type()} from system {m.get_srcSystem()} was taken as a command")
            raw[id(cmd)] = m
        return cmd

    def said_resume(cmd) -> bool:
        m = raw.get(id(cmd))
        return m is not None and m.get_type() == "COMMAND_LONG" and m.command == MAV_CMD_STOP_RESUME and m.param1 == 1.0

    port._decode = watched_decode
    controller = SawyerController(port, clock=SimClock())
    Watched(controller, said_resume).step(len(data) // 64 + 2)
