"""The robot link on a python-can bus: ``robot_link.dbc`` frames with AUTOSAR E2E Profile 1
(the frames: :mod:`edge_runtime.robot.link.protocol`; the link's logic: :class:`RobotLink`)."""
from __future__ import annotations

import can

from edge_runtime.canbus.bus import check_interface
from edge_runtime.robot.link.base import Clock, LinkConfig, RobotLink
from edge_runtime.robot.link.protocol import CanStateAssembler, RobotCanCodec, RobotState, open_can_bus


class CanRobotLink(RobotLink):
    """The robot link on a python-can bus, frames from ``robot_link.dbc`` with E2E Profile 1.

    Options: ``interface`` (default "socketcand"), ``channel`` ("vcan0"), ``host`` and
    ``port`` (socketcand), ``bitrate``; or ``bus``: an open python-can bus (not reopened
    on faults). ``config``, ``clock`` as for :class:`RobotLink`.
    """

    kind = "can"

    def __init__(self, interface: str = "socketcand", channel: str = "vcan0", host: str | None = "127.0.0.1",
                 port: int | None = None, bitrate: int | None = None, bus: can.BusABC | None = None,
                 config: LinkConfig | None = None, clock: Clock | None = None):
        if bus is None:
            check_interface(interface)
        if bus is None and interface == "socketcand" and port is None:
            raise ValueError("the socketcand interface needs port= (and host=)")
        self.interface, self.channel, self.host, self.port, self.bitrate = interface, channel, host, port, bitrate
        self.bus = bus
        self._given_bus = bus is not None
        self.codec = RobotCanCodec()
        self._assembler = CanStateAssembler()
        super().__init__(config=config, clock=clock, reopenable=bus is None)

    def _open_transport(self) -> None:
        if not self._given_bus:
            self.bus = open_can_bus(self.interface, self.channel, self.host, self.port, self.bitrate)

    def _close_transport(self) -> None:
        bus, self.bus = self.bus, None
        if bus is not None and not self._given_bus:
            bus.shutdown()

    def _put(self, *msgs: can.Message) -> None:
        for m in msgs:
            self.bus.send(m)
            self.stats.frames_sent += 1

    def _send_target(self, seq, position_m, pitch_rad, yaw_rad, retract) -> None:
        self._put(*self.codec.target_frames(seq, position_m, pitch_rad, yaw_rad, retract))

    def _send_mode(self, seq, command) -> None:
        self._put(self.codec.mode_frame(seq, command))

    def _send_speed(self, seq, limit_mps) -> None:
        self._put(self.codec.speed_frame(seq, limit_mps))

    def _send_alarm(self, seq, light, tone_hz, tone_db) -> None:
        self._put(self.codec.alarm_frame(seq, light, tone_hz, tone_db))

    def _send_heartbeat(self, state, uptime_s) -> None:
        self._put(self.codec.heartbeat_frame(state, uptime_s))

    def _receive(self, now: float) -> list[RobotState]:
        states = []
        for _ in range(self.config.max_frames_per_poll):
            msg = self.bus.recv(timeout=0)
            if msg is None:
                break
            # the remembered decoding itself, not a copy: the assembler only reads it (7 frames every 10 ms)
            status, name, sig = self.codec.decode_shared(msg)
            if sig is None:
                if status != "unknown_id":
                    self.stats.integrity_errors += 1
                continue
            self.stats.frames_received += 1
            st = self._assembler.feed(name, sig, now)
            if st is not None:
                states.append(st)
        return states
