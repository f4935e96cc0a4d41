"""The bench's other end of the robot's CAN link: a bus that stamps when each frame was handed
over, and a minimal in-process arm that answers the runtime's commands.

The robot cycle (:mod:`bench.robot_cycle`) runs the product's own link,
:class:`edge_runtime.robot.link.can.CanRobotLink`, on python-can's in-process ``virtual`` bus
(no network): every command is encoded by the product's codec (cantools from
``robot_link.dbc``, AUTOSAR E2E Profile 1) and handed to ``bus.send()``.
:class:`StampedBus` is that bus with one addition: it records when each ``send()`` returned,
which is the time a command is "on the link" (:func:`command_sent_s`).

:class:`ArmEcho` is the arm at the far end, on a second virtual bus on the same channel. It is
not the simulated Sawyer (:mod:`firmware_sim.robot.controller`: the bench's measuring process
imports only what a box imports, so its peak memory is the runtime's) but the least that makes
the loop behave as it does against an arm:

* every command frame is decoded with the product's codec (E2E checked) and answered at once with
  a ``ROBOT_STATUS`` carrying its sequence number and ``ok``, so the loop's acknowledgement
  checks (``[robot_loop] ack_timeout_s``) are satisfied and it never re-sends;
* a full state (the seven state frames, ``ROBOT_STATUS`` last) goes out at every :meth:`serve`;
* the hand moves in a straight line toward the last move or retraction target at the commanded
  speed limit (not while stopped, except to retract), and the joint angles it reports are one
  working posture turned about the base to the hand's bearing: the loop's whole-body separation
  and its escape-turn planning (:func:`edge_runtime.robot.hazard.plan_escape_turn`) see an arm that
  turns where it is sent; its reach in and out is not modelled (the hand position is).

The driver calls :meth:`ArmEcho.serve` at 100 Hz in slots of its own, between the loop's ticks and
outside any timed frame or tick: the state and the answers reach the runtime through its own
``poll()`` in the next frame or tick, which decodes them as on a box (the frame's reaction ends
when its command's ``send()`` returned, not when the arm answered). The echo's CPU
time is kept (``cpu_s``) so the bench can report the runtime's share without it.
"""
from __future__ import annotations

import math
import time
from contextlib import contextmanager
from dataclasses import replace

import numpy as np
from can.interfaces.virtual import VirtualBus

HEARTBEAT_FRAME = "RUNTIME_HEARTBEAT"
"""The runtime's liveness frame: sent by the link's own ``poll()``, not a command."""


class StampedBus(VirtualBus):
    """python-can's in-process virtual bus that records, per frame handed to it, the
    time at which ``send()`` returned (``clock``, default ``time.perf_counter``) and the frame's
    arbitration id."""

    def __init__(self, channel: str, clock=time.perf_counter, **kwargs):
        super().__init__(channel=channel, **kwargs)
        self.clock = clock
        self.sent: list[tuple[float, int]] = []

    def send(self, msg, timeout: float | None = None) -> None:
        super().send(msg, timeout)
        self.sent.append((self.clock(), msg.arbitration_id))


@contextmanager
def arm_on_bus(channel: str, posture_rad, clock=time.perf_counter, link_config=None):
    """(bus, arm, link): a :class:`StampedBus` on ``channel``, an :class:`ArmEcho` at its far end and the
    product's ``CanRobotLink`` on the bus (``link_config``: default ``LinkConfig()``), all closed after."""
    from edge_runtime.robot.link.base import LinkConfig
    from edge_runtime.robot.link.can import CanRobotLink

    bus = StampedBus(channel, clock=clock)
    echo = ArmEcho(channel, posture_rad)
    link = CanRobotLink(bus=bus, config=link_config or LinkConfig(), clock=clock)
    try:
        yield bus, echo, link
    finally:
        link.close()
        bus.shutdown()
        echo.close()


def command_sent_s(sent: list[tuple[float, int]], heartbeat_id: int) -> float | None:
    """When the last frame of ``sent`` that is not a heartbeat was handed to the bus (None: none was)."""
    return next((t for t, fid in reversed(sent) if fid != heartbeat_id), None)


class ArmEcho:
    """See the module docstring. ``posture_rad``: the working posture (7,) whose turns about the
    base the echo reports; the hand starts where that posture puts it."""

    def __init__(self, channel: str, posture_rad):
        from edge_runtime.robot.hazard import arm_points_m
        from edge_runtime.robot.link.protocol import RobotCanCodec, blank_state

        self.bus = VirtualBus(channel=channel)
        self.codec = RobotCanCodec()
        self._arm_points = arm_points_m
        self.q0 = np.asarray(posture_rad, float).reshape(7)
        self.hand_m = arm_points_m(self.q0)[-2]
        self._bearing0 = math.atan2(self.hand_m[0], self.hand_m[2])
        # which way joint 0 turns the hand's bearing (the URDF's z axis is the robot's y)
        turned = arm_points_m(self.q0 + np.array([0.1, 0, 0, 0, 0, 0, 0]))[-2]
        self._j0_sign = math.copysign(1.0, math.atan2(turned[0], turned[2]) - self._bearing0)
        self.state = replace(blank_state(), joint_positions_rad=self.q0.copy(), ee_position_m=self.hand_m.copy())
        self.target_m: np.ndarray | None = None
        self.speed_mps = 1.0
        self._orient: dict | None = None
        self._t_last: float | None = None
        self.commands: dict[str, int] = {}
        """Commands answered, by kind (move, retract, stop, resume, alarm, speed)."""
        self.rejected = 0
        """Frames that failed the product codec's E2E or range checks (none expected)."""
        self.cpu_s = 0.0
        """Thread CPU time spent in :meth:`serve` (s)."""

    def serve(self, now_s: float) -> None:
        """Answer every command waiting, move the hand for the time since the last call, report the state."""
        cpu0 = time.thread_time()
        while (msg := self.bus.recv(timeout=0)) is not None:
            self._on_frame(msg, now_s)
        self._move(now_s)
        for frame in self.codec.state_frames(self._stamped(now_s)):
            self.bus.send(frame)
        self.cpu_s += time.thread_time() - cpu0

    def close(self) -> None:
        self.bus.shutdown()

    # -- internals ----------------------------------------------------------------------------
    def _stamped(self, now_s: float):
        self.state = replace(self.state, robot_time_s=max(now_s, 0.0))
        return self.state

    def _on_frame(self, msg, now_s: float) -> None:
        status, name, sig = self.codec.decode(msg)
        if sig is None:
            self.rejected += 1
            return
        if name == "ROBOT_TARGET_ORIENT":  # the first half of a target: the position half commits it
            self._orient = sig
            return
        if name == "ROBOT_TARGET_POS":
            o, self._orient = self._orient, None
            if o is None or int(o["Seq"]) % 16 != int(sig["SeqCheck"]):
                self.rejected += 1
                return
            kind, seq = str(o["Kind"]), int(o["Seq"])
            if kind == "retract" or self.state.mode == "run":
                self.target_m = np.array([sig["X"], sig["Y"], sig["Z"]]) / 1000.0
                self.state = replace(self.state, pitch_rad=float(o["Pitch"]), yaw_rad=float(o["Yaw"]),
                                     mode="retract" if kind == "retract" else "run")
            self._answer(kind, seq)
        elif name == "ROBOT_MODE_CMD":
            command = str(sig["Command"])
            self.state = replace(self.state, mode="stopped" if command == "stop" else "run", watchdog=False)
            if command == "stop":
                self.target_m = None
            self._answer(command, int(sig["Seq"]))
        elif name == "ROBOT_SPEED_CMD":
            self.speed_mps = float(sig["SpeedLimit"]) / 1000.0
            self._answer("speed", int(sig["Seq"]))
        elif name == "ROBOT_ALARM_CMD":
            self.state = replace(self.state, light=str(sig["Light"]), tone_hz=float(sig["ToneFreq"]),
                                 tone_db=float(sig["ToneLevel"]))
            self._answer("alarm", int(sig["Seq"]))

    def _answer(self, command: str, seq: int) -> None:
        self.commands[command] = self.commands.get(command, 0) + 1
        self.state = replace(self.state, last_command=command, last_seq=seq, last_result="ok")
        self.bus.send(self.codec.status_frame(self.state))

    def _move(self, now_s: float) -> None:
        dt = 0.0 if self._t_last is None else max(now_s - self._t_last, 0.0)
        self._t_last = now_s
        target = self.target_m
        if target is None or self.state.mode == "stopped":
            self.state = replace(self.state, moving=False, ee_speed_mps=0.0, at_target=target is None)
            return
        gap = target - self.hand_m
        dist = float(np.linalg.norm(gap))
        step = min(dist, self.speed_mps * dt)
        if dist > 1e-9:
            self.hand_m = self.hand_m + gap * (step / dist)
        q = self.q0.copy()
        q[0] += self._j0_sign * (math.atan2(self.hand_m[0], self.hand_m[2]) - self._bearing0)
        self.state = replace(self.state, ee_position_m=self.hand_m.copy(), joint_positions_rad=q,
                             moving=step > 0, at_target=dist - step < 1e-3,
                             ee_speed_mps=step / dt if dt > 0 else 0.0)
