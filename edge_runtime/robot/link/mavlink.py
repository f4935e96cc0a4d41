"""The robot link over MAVLink 2 on a serial line, signed (the messages and their
conventions: :mod:`edge_runtime.robot.link.protocol`; the link's logic: :class:`RobotLink`)."""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
from pymavlink.dialects.v20 import common as mavlink2

from edge_runtime.core.serial_line import parse_serial_spec
from edge_runtime.robot.link.base import Clock, LinkConfig, RobotLink
from edge_runtime.robot.link.protocol import (
    ATTITUDE_ONLY_MASK,
    LIGHTS,
    MAV_CMD_ALARM,
    MAV_CMD_RETRACT,
    MAV_CMD_SPEED,
    MAV_CMD_STOP_RESUME,
    MAV_TO_RESULT,
    N_JOINTS,
    POSITION_ONLY_MASK,
    ROBOT_COMPID,
    ROBOT_SYSID,
    RUNTIME_COMPID,
    RUNTIME_STATE_TO_MAV,
    RUNTIME_SYSID,
    RobotState,
    SerialStream,
    blank_state,
    light_name,
    make_mavlink,
    mav_to_robot,
    robot_to_mav,
    signature_failure,
    tool_quaternion,
    unpack_status,
    wrap_angle,
)


class MavlinkRobotLink(RobotLink):
    """The robot link over MAVLink 2 on a serial line (``path``, or ``serial="serial:PATH[?key=HEX]"``)
    or a given byte ``stream``.

    ``signing_key`` (32 bytes): sign everything sent and refuse unsigned, forged and
    replayed packets (counted in ``stats.integrity_errors`` and ``signature_failures``).
    """

    kind = "mavlink"

    def __init__(self, path: str | None = None, stream=None, baud: int = 921600, signing_key: bytes | None = None,
                 link_id: int = 1, serial: str | None = None, config: LinkConfig | None = None,
                 clock: Clock | None = None):
        if serial is not None:
            path, signing_key = parse_serial_spec(serial, signing_key)
        if (path is None) == (stream is None):
            raise ValueError("give either path= (a serial line) or stream= (a byte stream)")
        self.path, self.baud, self.stream = path, baud, stream
        self._given_stream = stream is not None
        self.signing_key = signing_key
        self.signature_failures: dict[str, int] = {}
        self.mav = make_mavlink(self, RUNTIME_SYSID, RUNTIME_COMPID, signing_key, link_id)
        self._partial = blank_state()
        self._boot_ms = 0
        super().__init__(config=config, clock=clock, reopenable=stream is None)

    # pymavlink writes through this object
    def write(self, buf: bytes) -> None:
        if self.stream is None:
            raise ConnectionError("serial line not open")
        self.stream.write(bytes(buf))
        self.stats.frames_sent += 1

    def _open_transport(self) -> None:
        if not self._given_stream:
            self.stream = SerialStream(self.path, self.baud)

    def _close_transport(self) -> None:
        stream, self.stream = self.stream, None
        if stream is not None and not self._given_stream:
            stream.close()

    def _send_target(self, seq, position_m, pitch_rad, yaw_rad, retract) -> None:
        x, y, z = robot_to_mav(position_m)
        if retract:
            self._command_long(MAV_CMD_RETRACT, seq, x, y, z, pitch_rad, -yaw_rad)
            return
        self.mav.set_attitude_target_send(seq, ROBOT_SYSID, ROBOT_COMPID, ATTITUDE_ONLY_MASK,
                                          tool_quaternion(pitch_rad, yaw_rad), 0.0, 0.0, 0.0, 0.0)
        self.mav.set_position_target_local_ned_send(seq, ROBOT_SYSID, ROBOT_COMPID, mavlink2.MAV_FRAME_LOCAL_NED,
                                                    POSITION_ONLY_MASK, x, y, z, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0,
                                                    wrap_angle(-yaw_rad), 0.0)

    def _command_long(self, command: int, seq: int, *params: float) -> None:
        p = list(params) + [0.0] * (6 - len(params))
        self.mav.command_long_send(ROBOT_SYSID, ROBOT_COMPID, command, 0, *p, float(seq))

    def _send_mode(self, seq, command) -> None:
        self._command_long(MAV_CMD_STOP_RESUME, seq, 0.0 if command == "stop" else 1.0)

    def _send_speed(self, seq, limit_mps) -> None:
        self._command_long(MAV_CMD_SPEED, seq, 1.0, limit_mps, -1.0)

    def _send_alarm(self, seq, light, tone_hz, tone_db) -> None:
        self._command_long(MAV_CMD_ALARM, seq, float(LIGHTS.index(light)), tone_hz, tone_db)

    def _send_heartbeat(self, state, uptime_s) -> None:
        self.mav.heartbeat_send(mavlink2.MAV_TYPE_ONBOARD_CONTROLLER, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0,
                                RUNTIME_STATE_TO_MAV[state])

    def _receive(self, now: float) -> list[RobotState]:
        states = []
        for _ in range(64):
            data = self.stream.read()
            if not data:
                break
            for m in self.mav.parse_buffer(data) or ():
                st = self._handle(m, now)
                if st is not None:
                    states.append(st)
        return states

    def _handle(self, m, now: float) -> RobotState | None:
        mtype = m.get_type()
        if mtype == "BAD_DATA":
            why = signature_failure(self.mav, m)
            if why is not None:
                self.signature_failures[why] = self.signature_failures.get(why, 0) + 1
            self.stats.integrity_errors += 1  # a refused signature, a failed CRC or junk bytes
            return None
        if m.get_srcSystem() != ROBOT_SYSID or m.get_srcComponent() != ROBOT_COMPID:
            return None
        self.stats.frames_received += 1
        s = self._partial
        if mtype == "LOCAL_POSITION_NED":
            self._partial = replace(s, ee_position_m=mav_to_robot(m.x, m.y, m.z),
                                    ee_speed_mps=math.sqrt(m.vx ** 2 + m.vy ** 2 + m.vz ** 2),
                                    robot_time_s=m.time_boot_ms / 1000.0)
        elif mtype == "ATTITUDE":
            self._partial = replace(s, pitch_rad=float(m.pitch), yaw_rad=wrap_angle(-m.yaw))
        elif mtype == "ACTUATOR_OUTPUT_STATUS":
            a = m.actuator
            self._partial = replace(s, joint_positions_rad=np.array(a[:N_JOINTS], dtype=float),
                                    light=light_name(a[14]), tone_hz=float(a[15]),
                                    tone_db=float(a[16]))
        elif mtype == "SYS_STATUS":
            self._partial = replace(s, counters={"integrity_errors": m.errors_comm, "refused": m.errors_count1,
                                                 "watchdog_trips": m.errors_count2, "rx_valid": m.errors_count3})
        elif mtype == "COMMAND_ACK":
            self._record_result(int(m.result_param2), MAV_TO_RESULT.get(m.result, "invalid"))
        elif mtype == "HEARTBEAT":
            self._partial = replace(s, t_s=now, **unpack_status(m.custom_mode))
            return self._partial
        return None
