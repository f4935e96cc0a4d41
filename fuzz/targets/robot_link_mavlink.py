"""The runtime's robot link on MAVLink 2: bytes from the arm -> parser and signature -> RobotState.

An input is a burst of packets the arm's side would send (LOCAL_POSITION_NED, ATTITUDE,
ACTUATOR_OUTPUT_STATUS, SYS_STATUS, COMMAND_ACK, HEARTBEAT), correctly signed with the
link's key but carrying any float32 (NaN, inf, huge) and any integer of the field's width,
as a faulty controller would send them; between packets, junk bytes, and some packets with
a byte flipped. ``poll()`` is documented never to raise; a state it hands out must be
finite and in range. :func:`packets` is shared with the simulated Sawyer's target
(``sawyer_mavlink``), which gets the runtime's packets.
"""
from __future__ import annotations

import itertools

from hypothesis import strategies as st
from pymavlink.dialects.v20 import common as mavlink2

from edge_runtime.robot.link.mavlink import MavlinkRobotLink
from edge_runtime.robot.link.protocol import ROBOT_COMPID, ROBOT_SYSID, make_mavlink
from firmware_sim.robot.controller import TEST_SIGNING_KEY
from fuzz.harness import SilentAcceptance
from fuzz.targets.robot_link_can import _out_of_range

NAME = "robot_link_mavlink"
DOCUMENTED = ()  # RobotLink.poll() never raises

FLOAT32 = st.one_of(st.floats(width=32), st.sampled_from([0.0, 0.5, -0.5, 1.0, 3.0]))


def u(bits: int) -> st.SearchStrategy[int]:
    return st.integers(0, (1 << bits) - 1)


ROBOT_MESSAGES = {
    "local_position_ned": st.tuples(u(32), *[FLOAT32] * 6),
    "attitude": st.tuples(u(32), *[FLOAT32] * 6),
    "actuator_output_status": st.tuples(u(64), u(32), st.lists(FLOAT32, min_size=32, max_size=32)),
    "sys_status": st.tuples(u(32), u(32), u(32), u(16), u(16), st.integers(-32768, 32767),
                            st.integers(-128, 127), u(16), u(16), u(16), u(16), u(16), u(16)),
    "command_ack": st.tuples(u(16), u(8), u(8), st.integers(-2**31, 2**31 - 1), u(8), u(8)),
    "heartbeat": st.tuples(u(8), u(8), u(8), u(32), u(8)),
}
"""pymavlink ``<name>_encode`` argument tuples of the messages the arm sends, any value."""


class ByteSink:
    """Where a pymavlink sender writes its packets."""

    def __init__(self):
        self.data = bytearray()

    def write(self, buf: bytes) -> None:
        self.data += buf


@st.composite
def packets(draw, messages: dict, src_system: int, src_component: int, key: bytes | None) -> bytes:
    """A byte stream of ``messages`` (name -> argument tuples) sent by (system, component),
    signed with ``key``; junk between packets and now and then a flipped byte."""
    sink = ByteSink()
    mav = make_mavlink(sink, src_system, src_component, key, 0)
    names = draw(st.lists(st.sampled_from(sorted(messages)), min_size=1, max_size=24))
    for name in names:
        args = draw(messages[name])
        getattr(mav, f"{name}_send")(*args)
        roll = draw(st.integers(0, 9))
        if roll == 0:
            sink.data += draw(st.binary(min_size=1, max_size=12))
        elif roll == 1 and sink.data:
            i = draw(st.integers(0, len(sink.data) - 1))
            sink.data[i] ^= draw(st.integers(1, 255))
    return bytes(sink.data)


class ByteStream:
    """A byte stream stand-in: the input in chunks of up to 64 bytes, then nothing."""

    def __init__(self, data: bytes):
        self.chunks = [data[i:i + 64] for i in range(0, len(data), 64)]

    def read(self) -> bytes:
        return self.chunks.pop(0) if self.chunks else b""

    def write(self, data: bytes) -> None:
        pass

    def close(self) -> None:
        pass


def strategy():
    return packets(ROBOT_MESSAGES, ROBOT_SYSID, ROBOT_COMPID, TEST_SIGNING_KEY)


def run(data: bytes) -> None:
    ticks = itertools.count()
    link = MavlinkRobotLink(stream=ByteStream(data), signing_key=TEST_SIGNING_KEY, clock=lambda: 0.01 * next(ticks))
    for _ in range(len(data) // 64 + 1):
        state = link.poll()
        if state is not None and (bad := _out_of_range(state)) is not None:
            raise SilentAcceptance(f"the link handed out a state with {bad}")


__all__ = ["NAME", "DOCUMENTED", "strategy", "run", "packets", "ByteStream", "mavlink2"]
