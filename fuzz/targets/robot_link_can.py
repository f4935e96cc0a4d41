"""The runtime's robot link on CAN: frames from the arm -> E2E check -> decode -> RobotState.

An input is a burst of frames as the arm's side of the bus would carry them: each of a
``robot_link.dbc`` message (or an unknown id), with random payload bytes whose E2E CRC is
usually made valid (so faulty values get past the CRC and reach decoding, as a faulty
controller's would), then possibly damaged: shortened, lengthened, extended-id, remote or
error frame. ``poll()`` is documented never to raise; a state it hands out must be finite
and inside the DBC's ranges. :func:`can_frames` is shared with the simulated Sawyer's
target (``sawyer_can``), which gets the runtime's frames.
"""
from __future__ import annotations

import itertools
import math

import can
import e2e.p01 as p01
import numpy as np
from hypothesis import strategies as st

from edge_runtime.canbus.dbc import load_dbc
from edge_runtime.canbus.e2e import e2e_data_id
from edge_runtime.robot.link.can import CanRobotLink
from edge_runtime.robot.link.protocol import COMMANDS, DBC_PATH, LIGHTS, MODES, RESULTS
from fuzz.harness import SilentAcceptance

NAME = "robot_link_can"
DOCUMENTED = ()  # RobotLink.poll() never raises
DB = load_dbc(DBC_PATH)
DAMAGE = ("none", "none", "none", "none", "short", "long", "extended", "remote", "error", "unknown_id", "no_crc")


@st.composite
def can_frame(draw, sender: str) -> can.Message:
    """One frame of a message ``sender`` sends in robot_link.dbc, payload random, CRC usually valid."""
    msg = draw(st.sampled_from([m for m in DB.messages if sender in m.senders]))
    data = bytearray(draw(st.binary(min_size=msg.length, max_size=msg.length)))
    damage = draw(st.sampled_from(DAMAGE))
    data[1] = (data[1] & 0xF0) | draw(st.integers(0, 14))  # a counter the E2E profile allows
    if damage == "short":
        data = data[:draw(st.integers(0, msg.length - 1))]
    elif damage == "long":
        data = data + bytearray(draw(st.binary(min_size=1, max_size=56)))
    if damage != "no_crc" and len(data) >= 2:  # the CRC over the bytes sent, whatever their number
        p01.e2e_p01_protect(data, e2e_data_id(msg), length=len(data), increment_counter=False)
    frame_id = msg.frame_id
    if damage == "unknown_id":
        frame_id = draw(st.integers(0, 0x7FF).filter(lambda i: i not in {m.frame_id for m in DB.messages}))
    return can.Message(arbitration_id=frame_id, data=bytes(data), is_extended_id=damage == "extended",
                       is_remote_frame=damage == "remote", is_error_frame=damage == "error",
                       is_fd=len(data) > 8, check=False)


def can_frames(sender: str) -> st.SearchStrategy[list[can.Message]]:
    return st.lists(can_frame(sender), min_size=1, max_size=40)


class FrameBus:
    """A python-can bus stand-in that hands out the given frames, then nothing; sends are kept."""

    def __init__(self, frames):
        self.frames = list(frames)
        self.sent: list[can.Message] = []

    def recv(self, timeout=None):
        return self.frames.pop(0) if self.frames else None

    def send(self, msg, timeout=None):
        self.sent.append(msg)

    def shutdown(self):
        pass


def strategy():
    return can_frames("SAWYER")


def _out_of_range(state) -> str | None:
    """What of a state the runtime used lies outside the DBC's ranges (None: nothing)."""
    values = {"ee_position_m": state.ee_position_m, "joint_positions_rad": state.joint_positions_rad,
              "pitch_rad": state.pitch_rad, "yaw_rad": state.yaw_rad, "ee_speed_mps": state.ee_speed_mps,
              "tone_hz": state.tone_hz, "tone_db": state.tone_db}
    for name, v in values.items():
        if not np.isfinite(np.asarray(v, dtype=float)).all():
            return f"{name} = {v!r}"
    if np.abs(state.ee_position_m).max() > 3.28 or abs(state.pitch_rad) > math.pi / 2 + 1e-3:
        return f"position {state.ee_position_m!r} / pitch {state.pitch_rad!r}"
    for name, allowed in (("mode", MODES), ("light", LIGHTS), ("last_result", RESULTS),
                          ("last_command", COMMANDS)):
        if getattr(state, name) not in allowed:
            return f"{name} = {getattr(state, name)!r}"
    return None


def run(frames) -> None:
    ticks = itertools.count()
    link = CanRobotLink(bus=FrameBus(frames), clock=lambda: 0.01 * next(ticks))
    for _ in range(len(frames)):
        state = link.poll()
        if state is not None and (bad := _out_of_range(state)) is not None:
            raise SilentAcceptance(f"the link handed out a state with {bad}")
