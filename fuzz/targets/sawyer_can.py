"""The simulated Sawyer as a strict reference end, on CAN: the runtime's frames -> controller.

An input is a burst of frames the runtime's side sends (mode, target halves, alarm,
heartbeat; random payloads with a valid E2E CRC, then possibly damaged; see
:func:`fuzz.targets.robot_link_can.can_frame`). The controller must never raise, and
what it executes must be what the frame said: a move or retraction only to a finite
position within reach of the link (+-3.2 m) and a finite direction, an alarm only with a
named light and tone in range, a resume only from a frame that says resume.
:class:`Watched` holds those checks for both transports.
"""
from __future__ import annotations

import math

import numpy as np

from edge_runtime.robot.link.protocol import LIGHTS, MAX_TONE_DB, MAX_TONE_HZ
from firmware_sim.robot.controller import CanControllerPort, SawyerController, SimClock
from fuzz.harness import SilentAcceptance
from fuzz.targets.robot_link_can import FrameBus, can_frames

NAME = "sawyer_can"
DOCUMENTED = ()  # the controller refuses and counts; it never raises on what it receives


class Watched:
    """A controller whose every executed command is checked against what was on the wire.

    ``said_resume(cmd)`` answers whether the raw input behind ``cmd`` really asked to resume."""

    def __init__(self, controller: SawyerController, said_resume):
        self.controller = controller
        self.said_resume = said_resume
        self._handle = controller.handle
        controller.handle = self.handle

    def handle(self, cmd, now=None) -> str:
        before = self.controller.mode
        result = self._handle(cmd, now)
        after = self.controller.mode
        if result == "ok" and cmd.kind in ("move", "retract"):
            p = np.asarray(cmd.position_m, dtype=float)
            if not (np.isfinite(p).all() and np.abs(p).max() <= 3.2 and math.isfinite(cmd.pitch_rad)
                    and math.isfinite(cmd.yaw_rad)):
                raise SilentAcceptance(f"{cmd.kind} executed to {p.tolist()}, pitch {cmd.pitch_rad}, yaw {cmd.yaw_rad}")
        if result == "ok" and cmd.kind == "alarm" and not (
                cmd.light in LIGHTS and 0 <= cmd.tone_hz <= MAX_TONE_HZ and 0 <= cmd.tone_db <= MAX_TONE_DB):
            raise SilentAcceptance(f"alarm executed with {cmd.light!r}, {cmd.tone_hz} Hz, {cmd.tone_db} dB")
        if before != "run" and after == "run" and not self.said_resume(cmd):
            raise SilentAcceptance(f"the arm was set running by a {cmd.kind} that did not say resume")
        return result

    def step(self, n: int, dt_s: float = 0.01) -> None:
        for _ in range(n):
            self.controller.clock.advance(dt_s)
            self.controller.step(dt_s)


def strategy():
    return can_frames("RUNTIME")


def run(frames) -> None:
    bus = FrameBus(frames)
    port = CanControllerPort(bus=bus)
    decode = port._decode
    said: dict[int, bool] = {}

    def watched_decode(msg, now):
        cmd = decode(msg, now)
        if cmd is not None:  # resume: a ROBOT_MODE_CMD frame whose Command decodes to "resume"
            sig = port.codec.db.get_message_by_frame_id(msg.arbitration_id).decode(bytes(msg.data), decode_choices=True)
            said[id(cmd)] = str(sig.get("Command")) == "resume"
        return cmd

    port._decode = watched_decode
    controller = SawyerController(port, clock=SimClock())
    Watched(controller, lambda cmd: said.get(id(cmd), False)).step(len(frames) + 1)
