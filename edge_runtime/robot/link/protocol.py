"""The runtime's end of the robot link: commands to a Sawyer controller, its state back.

``open_link(kind, **options)`` returns a :class:`RobotLink` for ``"can"`` or ``"mavlink"``
(a registry, like python-can's interfaces). Every link has the same API::

    link = open_link("can", interface="socketcand", host="127.0.0.1", port=29536, channel="vcan0")
    link.resume()                                  # the controller boots stopped
    seq = link.move_to((0.4, 0.2, 0.7), pitch_rad=0.0, yaw_rad=0.0)
    state = link.poll()                            # never blocks; also sends the heartbeat when due
    link.result(seq)                               # "ok", "unreachable", "refused", "invalid" or None

Positions are metres in the robot frame (``edge_runtime/skeleton.py``: origin on top of
the Sawyer base, y up, the work side +z). The tool direction is (pitch, yaw):
``d = (cos(pitch)·sin(yaw), sin(pitch), cos(pitch)·cos(yaw))``; roll is left to the arm.

Timing uses an injectable ``clock`` (seconds, default ``time.monotonic``) and the link
never sleeps, so a simulation can run it faster than real time. ``poll()`` reads what
has arrived, sends a heartbeat every ``LinkConfig.heartbeat_period_s`` and checks the
link: no state for ``state_timeout_s`` (200 ms), or a transport error, makes
``link_ok`` false (``stats.outages`` +1); a broken transport is reopened with
exponential backoff (``stats.reconnects``). Nothing here raises on a link fault.

**CAN** (``assets/robot_link.dbc``, the single source of truth; cantools encodes and
decodes, AUTOSAR E2E Profile 1 protects every frame through ``autosar-e2e``, checked
with :class:`edge_runtime.canbus.e2e.E2EChecker`). A target is two frames, the direction
half (with the 16-bit sequence number) then the position half (with ``Seq mod 16``).
The robot's state is seven frames every 10 ms; ``ROBOT_STATUS`` comes last and
completes a state.

**MAVLink 2** (pymavlink ``common``, signed when a key is given; unsigned, forged and
replayed packets are refused and counted). Coordinates on the wire are NED-like,
the URDF base's forward-right-down frame: ``(x, y, z)_mav = (z, -x, -y)_robot``.
Orientation: MAVLink pitch = tool pitch, MAVLink yaw = -tool yaw (NED yaw turns about
"down"). Messages:

==========================  =============  ==================================================
message                     direction      meaning
==========================  =============  ==================================================
HEARTBEAT                   both           runtime: liveness (feeds the watchdog). Robot: sent
                                           last in every state cycle; ``custom_mode`` packs the
                                           status (:func:`pack_status`), ``system_status`` is
                                           STANDBY (stopped), ACTIVE (run, retract) or
                                           EMERGENCY (watchdog latched)
SET_ATTITUDE_TARGET         runtime→robot  move, first half: tool quaternion (roll 0, pitch,
                                           yaw); ``time_boot_ms`` carries the sequence number
SET_POSITION_TARGET_LOCAL_  runtime→robot  move, second half: x, y, z (m, frame LOCAL_NED,
NED                                        velocities/accelerations ignored) and yaw; commits
                                           the target if ``time_boot_ms`` matches the first half
COMMAND_LONG                runtime→robot  param7 = sequence number. MAV_CMD_DO_PAUSE_CONTINUE:
                                           param1 0 stop, 1 resume. MAV_CMD_USER_1 (retract):
                                           param1-3 x, y, z (m), param4 pitch, param5 yaw (rad,
                                           MAVLink convention). MAV_CMD_USER_2 (alarm): param1
                                           light (0 off, 1 green, 2 yellow, 3 red), param2 tone
                                           Hz, param3 tone dB
COMMAND_ACK                 robot→runtime  every command, ``result_param2`` = sequence number;
                                           moves are acknowledged as MAV_CMD_USER_3. ACCEPTED ok,
                                           FAILED unreachable, TEMPORARILY_REJECTED refused,
                                           DENIED invalid
LOCAL_POSITION_NED          robot→runtime  hand position (m) and velocity (m/s), every cycle
ATTITUDE                    robot→runtime  tool pitch and yaw (rad), every cycle
ACTUATOR_OUTPUT_STATUS      robot→runtime  actuator[0..6] joint angles (rad), [7..13] joint
                                           velocities (rad/s), [14] light code, [15] tone Hz,
                                           [16] tone dB; every cycle
SYS_STATUS                  robot→runtime  counters every 100 ms: errors_comm integrity errors,
                                           errors_count1 refused, errors_count2 watchdog trips,
                                           errors_count3 valid runtime packets (mod 65536)
==========================  =============  ==================================================
"""
from __future__ import annotations

import math
import os
import socket
import threading
import time
from dataclasses import dataclass, field, replace
from typing import Callable, ClassVar

import can
import numpy as np
import serial
from pymavlink.dialects.v20 import common as mavlink2
from pymavlink.quaternion import QuaternionBase

from edge_runtime.canbus.bus import CanLinkError, check_interface, open_bus
from edge_runtime.canbus.dbc import load_dbc
from edge_runtime.canbus.e2e import E2EChecker, E2EProtector
from edge_runtime.core.manifest import ASSETS_DIR
from edge_runtime.core.serial_line import parse_serial_spec

DBC_PATH = ASSETS_DIR / "robot_link.dbc"

LIGHTS = ("off", "green", "yellow", "red")
MODES = ("stopped", "run", "retract")
COMMANDS = ("none", "move", "retract", "stop", "resume", "alarm")
RESULTS = ("none", "ok", "unreachable", "refused", "invalid")
REFUSALS = ("unreachable", "refused", "invalid")
N_JOINTS = 7
SEQ_MAX = 65535
MAX_TONE_HZ = 20000.0
MAX_TONE_DB = 127.5
LINK_ERRORS = (OSError, can.CanError, serial.SerialException, CanLinkError)
"""Transport faults: the link is reported down and reopened, never raised to the caller."""

Clock = Callable[[], float]


# ----------------------------------------------------------------------------------------------
# data

@dataclass(frozen=True)
class RobotState:
    """One state report of the controller (robot frame, SI units)."""

    t_s: float
    """When it was received (runtime) or made (controller), on that side's clock (s)."""
    joint_positions_rad: np.ndarray
    """right_j0..right_j6 (7,), rad."""
    ee_position_m: np.ndarray
    """Hand position (3,), m, robot frame."""
    pitch_rad: float
    yaw_rad: float
    ee_speed_mps: float
    mode: str
    """"stopped", "run" or "retract"."""
    watchdog: bool
    """The runtime went quiet for 200 ms and the arm was stopped; latched until resume()."""
    moving: bool
    at_target: bool
    light: str
    tone_hz: float
    tone_db: float
    last_command: str
    last_seq: int
    last_result: str
    robot_time_s: float
    """Controller clock (s); over CAN it wraps every 65.536 s."""
    counters: dict = field(default_factory=dict)
    """Controller counters (rx_valid, integrity_errors, refused, watchdog_trips), as last reported."""


def blank_state(t_s: float = 0.0) -> RobotState:
    return RobotState(t_s, np.zeros(N_JOINTS), np.zeros(3), 0.0, 0.0, 0.0, "stopped", False, False, False,
                      "off", 0.0, 0.0, "none", 0, "none", 0.0, {})


@dataclass
class LinkStats:
    frames_sent: int = 0
    frames_received: int = 0
    """Frames or packets received that passed the integrity check."""
    states: int = 0
    """Complete state reports received."""
    integrity_errors: int = 0
    """Received frames discarded: E2E (CRC, repeated counter) or MAVLink signature/CRC failures."""
    refused: int = 0
    """Commands the controller reported as unreachable, refused or invalid."""
    send_errors: int = 0
    """Commands or heartbeats that could not be handed to the transport."""
    outages: int = 0
    """Times the link went from ok to lost (no state for state_timeout_s, or a transport error)."""
    reconnects: int = 0
    """Successful reopenings of the transport after a fault."""
    heartbeats: int = 0


@dataclass(frozen=True)
class LinkConfig:
    """Timing of the runtime's end of the link."""

    state_timeout_s: float = 0.2
    """No complete state for this long: the link is reported lost."""
    heartbeat_period_s: float | None = 0.05
    """poll() sends a heartbeat when this much time has passed since the last (None: only heartbeat())."""
    reconnect_min_s: float = 0.1
    """First retry delay after a transport fault; doubles per failure up to reconnect_max_s."""
    reconnect_max_s: float = 2.0
    stale_reopen_s: float = 1.0
    """A reopenable transport silent for this long is closed and reopened."""
    max_frames_per_poll: int = 2000
    """poll() returns after this many frames even if more are waiting (keeps the loop live)."""


def next_seq(seq: int) -> int:
    """The sequence number after ``seq``: 1..65535, wrapping to 1 (0 means none)."""
    return 1 if seq >= SEQ_MAX else seq + 1


def wrap_angle(a: float) -> float:
    """Angle in (-pi, pi]."""
    a = math.remainder(float(a), 2 * math.pi)
    return math.pi if a == -math.pi else a


def check_target(position_m, pitch_rad: float, yaw_rad: float) -> tuple[np.ndarray, float, float]:
    """Validated (position (3,), pitch in [-pi/2, pi/2], yaw in (-pi, pi]); ValueError names the field."""
    p = np.asarray(position_m, dtype=float).reshape(-1)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise ValueError(f"position_m must be 3 finite numbers (m), got {position_m!r}")
    if np.any(np.abs(p) > 3.2):
        raise ValueError(f"position_m {tuple(np.round(p, 3))} is outside +-3.2 m of the robot base")
    if not math.isfinite(pitch_rad) or abs(pitch_rad) > math.pi / 2 + 1e-9:
        raise ValueError(f"pitch_rad must lie in [-pi/2, pi/2], got {pitch_rad!r}")
    if not math.isfinite(yaw_rad):
        raise ValueError(f"yaw_rad must be finite, got {yaw_rad!r}")
    return p, max(-math.pi / 2, min(math.pi / 2, float(pitch_rad))), wrap_angle(yaw_rad)


def check_alarm(light: str, tone_hz: float, tone_db: float) -> tuple[str, float, float]:
    if light not in LIGHTS:
        raise ValueError(f"light must be one of {', '.join(LIGHTS)}, got {light!r}")
    if not (math.isfinite(tone_hz) and 0.0 <= tone_hz <= MAX_TONE_HZ):
        raise ValueError(f"tone_hz must lie in [0, {MAX_TONE_HZ:g}] Hz, got {tone_hz!r}")
    if not (math.isfinite(tone_db) and 0.0 <= tone_db <= MAX_TONE_DB):
        raise ValueError(f"tone_db must lie in [0, {MAX_TONE_DB:g}] dB, got {tone_db!r}")
    return light, float(tone_hz), float(tone_db)


# ----------------------------------------------------------------------------------------------
# byte streams for MAVLink: a serial line, a pseudo-terminal master, a socket

class SerialStream:
    """A serial line (or pty slave) through pyserial, non-blocking."""

    def __init__(self, path: str, baud: int = 921600):
        self.path = path
        self.ser = serial.Serial(path, baudrate=baud, timeout=0, write_timeout=0)

    def read(self) -> bytes:
        return self.ser.read(max(1, self.ser.in_waiting))

    def write(self, data: bytes) -> None:
        try:
            self.ser.write(data)
        except serial.SerialTimeoutException as e:  # output buffer full: nobody reads the line
            raise BlockingIOError(str(e)) from None

    def close(self) -> None:
        self.ser.close()


class FdStream:
    """A non-blocking file descriptor (a pty master). EOF and EIO raise OSError."""

    def __init__(self, fd: int, own: bool = False):
        self.fd = fd
        self.own = own
        os.set_blocking(fd, False)

    def read(self) -> bytes:
        try:
            data = os.read(self.fd, 65536)
        except BlockingIOError:
            return b""
        if not data:
            raise ConnectionAbortedError("end of stream")
        return data

    def write(self, data: bytes) -> None:
        view = memoryview(data)
        while view:
            view = view[os.write(self.fd, view):]

    def close(self) -> None:
        if self.own:
            os.close(self.fd)


class SocketStream(FdStream):
    """One end of a socket pair (the in-process simulation's serial line)."""

    def __init__(self, sock: socket.socket):
        self.sock = sock
        super().__init__(sock.fileno())

    def close(self) -> None:
        self.sock.close()


# ----------------------------------------------------------------------------------------------
# CAN: the DBC with E2E protection

class RobotCanCodec:
    """Encodes and decodes robot-link frames with cantools from ``robot_link.dbc``, with E2E.

    One alive counter per frame ID on the sending side; on the receiving side an
    :class:`E2EChecker` (CRC, then counter). Used by both ends of the link.
    """

    def __init__(self, db=None):
        self.db = db if db is not None else load_dbc(DBC_PATH)
        self.checker = E2EChecker(db=self.db)
        self._by_name = {m.name: m for m in self.db.messages}
        self._e2e = E2EProtector()

    def encode(self, name: str, **signals) -> can.Message:
        """A protected frame: signals by cantools, then alive counter and CRC (Profile 1)."""
        return self._e2e.protect(self._by_name[name], signals)

    def decode(self, msg: can.Message) -> tuple[str, str, dict | None]:
        """(E2E status, message name, signals). Signals is None unless the frame is valid."""
        res = self.checker.check(msg)
        if not res.valid:
            return res.status, "", None
        message = self.db.get_message_by_frame_id(msg.arbitration_id)
        return res.status, message.name, message.decode(bytes(msg.data), decode_choices=True)

    # -- runtime -> robot ------------------------------------------------------------------
    def target_frames(self, seq: int, position_m, pitch_rad: float, yaw_rad: float, retract: bool) -> list[can.Message]:
        x, y, z = (float(v) * 1000.0 for v in position_m)
        return [self.encode("ROBOT_TARGET_ORIENT", Kind="retract" if retract else "move", Seq=seq,
                            Pitch=pitch_rad, Yaw=yaw_rad),
                self.encode("ROBOT_TARGET_POS", SeqCheck=seq % 16, X=x, Y=y, Z=z)]

    def mode_frame(self, seq: int, command: str) -> can.Message:
        return self.encode("ROBOT_MODE_CMD", Command=command, Seq=seq)

    def alarm_frame(self, seq: int, light: str, tone_hz: float, tone_db: float) -> can.Message:
        return self.encode("ROBOT_ALARM_CMD", Light=light, Seq=seq, ToneFreq=round(tone_hz),
                           ToneLevel=round(tone_db * 2) / 2)

    def heartbeat_frame(self, state: str, uptime_s: float) -> can.Message:
        return self.encode("RUNTIME_HEARTBEAT", State=state, Uptime_s=int(min(max(uptime_s, 0), 65535)))

    # -- robot -> runtime ------------------------------------------------------------------
    def state_frames(self, st: RobotState) -> list[can.Message]:
        """The frames of one state cycle, ROBOT_STATUS last."""
        x, y, z = (float(v) * 1000.0 for v in st.ee_position_m)
        j = [float(v) for v in st.joint_positions_rad]
        return [
            self.encode("ROBOT_EE_POSITION", X=x, Y=y, Z=z),
            self.encode("ROBOT_EE_ORIENT", Pitch=st.pitch_rad, Yaw=wrap_angle(st.yaw_rad),
                        Speed=min(st.ee_speed_mps * 1000.0, 6553.5)),
            self.encode("ROBOT_JOINTS_A", J0=j[0], J1=j[1], J2=j[2]),
            self.encode("ROBOT_JOINTS_B", J3=j[3], J4=j[4], J5=j[5]),
            self.encode("ROBOT_JOINTS_C", J6=j[6]),
            self.encode("ROBOT_ALARM_STATE", Light=st.light, ToneFreq=round(st.tone_hz),
                        ToneLevel=round(st.tone_db * 2) / 2),
            self.status_frame(st),
        ]

    def status_frame(self, st: RobotState) -> can.Message:
        """ROBOT_STATUS: it completes a state, and answers a command at once."""
        return self.encode("ROBOT_STATUS", Mode=st.mode, Watchdog=int(st.watchdog), Moving=int(st.moving),
                           AtTarget=int(st.at_target), LastCommand=st.last_command, LastResult=st.last_result,
                           LastSeq=st.last_seq, RobotTime=int(st.robot_time_s * 1000.0) % 65536)

    def counters_frame(self, counters: dict) -> can.Message:
        sat = lambda k, hi: int(min(max(counters.get(k, 0), 0), hi))  # noqa: E731
        return self.encode("ROBOT_COUNTERS", WatchdogTrips=sat("watchdog_trips", 15),
                           RxValid=int(counters.get("rx_valid", 0)) % 65536,
                           IntegrityErrors=sat("integrity_errors", 65535), Refused=sat("refused", 65535))


def open_can_bus(interface: str, channel: str, host: str | None = None, port: int | None = None,
                 bitrate: int | None = None) -> can.BusABC:
    """A python-can bus for the robot link (both ends): :func:`edge_runtime.canbus.bus.open_bus`."""
    return open_bus(interface, channel, bitrate, host=host, port=port)


class CanStateAssembler:
    """Builds RobotState objects from the robot's frames; ROBOT_STATUS completes one."""

    def __init__(self):
        self._s = blank_state()
        self._joints = np.zeros(N_JOINTS)

    def feed(self, name: str, sig: dict, t_s: float) -> RobotState | None:
        s = self._s
        if name == "ROBOT_EE_POSITION":
            self._s = replace(s, ee_position_m=np.array([sig["X"], sig["Y"], sig["Z"]]) / 1000.0)
        elif name == "ROBOT_EE_ORIENT":
            self._s = replace(s, pitch_rad=sig["Pitch"], yaw_rad=sig["Yaw"], ee_speed_mps=sig["Speed"] / 1000.0)
        elif name.startswith("ROBOT_JOINTS_"):
            for k, v in sig.items():
                if k.startswith("J") and k[1:].isdigit():
                    self._joints[int(k[1:])] = v
        elif name == "ROBOT_ALARM_STATE":
            self._s = replace(s, light=str(sig["Light"]), tone_hz=float(sig["ToneFreq"]),
                              tone_db=float(sig["ToneLevel"]))
        elif name == "ROBOT_COUNTERS":
            self._s = replace(s, counters={"watchdog_trips": sig["WatchdogTrips"], "rx_valid": sig["RxValid"],
                                           "integrity_errors": sig["IntegrityErrors"], "refused": sig["Refused"]})
        elif name == "ROBOT_STATUS":
            self._s = replace(s, t_s=t_s, joint_positions_rad=self._joints.copy(), mode=str(sig["Mode"]),
                              watchdog=bool(sig["Watchdog"]), moving=bool(sig["Moving"]),
                              at_target=bool(sig["AtTarget"]), last_command=str(sig["LastCommand"]),
                              last_result=str(sig["LastResult"]), last_seq=int(sig["LastSeq"]),
                              robot_time_s=sig["RobotTime"] / 1000.0)
            return self._s
        return None


# ----------------------------------------------------------------------------------------------
# MAVLink: frames, orientation and the packed status

MAV_CMD_STOP_RESUME = mavlink2.MAV_CMD_DO_PAUSE_CONTINUE
MAV_CMD_RETRACT = mavlink2.MAV_CMD_USER_1
MAV_CMD_ALARM = mavlink2.MAV_CMD_USER_2
MAV_CMD_MOVE_ACK = mavlink2.MAV_CMD_USER_3
"""The command id under which a move (SET_ATTITUDE_TARGET + SET_POSITION_TARGET_LOCAL_NED) is acknowledged."""
RESULT_TO_MAV = {"ok": mavlink2.MAV_RESULT_ACCEPTED, "unreachable": mavlink2.MAV_RESULT_FAILED,
                 "refused": mavlink2.MAV_RESULT_TEMPORARILY_REJECTED, "invalid": mavlink2.MAV_RESULT_DENIED}
MAV_TO_RESULT = {v: k for k, v in RESULT_TO_MAV.items()}
ROBOT_SYSID, ROBOT_COMPID = 1, mavlink2.MAV_COMP_ID_AUTOPILOT1
RUNTIME_SYSID, RUNTIME_COMPID = 1, mavlink2.MAV_COMP_ID_ONBOARD_COMPUTER
POSITION_ONLY_MASK = (mavlink2.POSITION_TARGET_TYPEMASK_VX_IGNORE | mavlink2.POSITION_TARGET_TYPEMASK_VY_IGNORE
                      | mavlink2.POSITION_TARGET_TYPEMASK_VZ_IGNORE | mavlink2.POSITION_TARGET_TYPEMASK_AX_IGNORE
                      | mavlink2.POSITION_TARGET_TYPEMASK_AY_IGNORE | mavlink2.POSITION_TARGET_TYPEMASK_AZ_IGNORE
                      | mavlink2.POSITION_TARGET_TYPEMASK_YAW_RATE_IGNORE)
ATTITUDE_ONLY_MASK = (mavlink2.ATTITUDE_TARGET_TYPEMASK_BODY_ROLL_RATE_IGNORE
                      | mavlink2.ATTITUDE_TARGET_TYPEMASK_BODY_PITCH_RATE_IGNORE
                      | mavlink2.ATTITUDE_TARGET_TYPEMASK_BODY_YAW_RATE_IGNORE
                      | mavlink2.ATTITUDE_TARGET_TYPEMASK_THROTTLE_IGNORE)
MAVLINK_EPOCH_UNIX_S = 1420070400
"""MAVLink signing timestamps count 10 us since 2015-01-01 00:00 UTC."""


def robot_to_mav(p) -> tuple[float, float, float]:
    """Robot-frame (x, y, z) -> MAVLink local (x fwd, y right, z down) = (z, -x, -y)."""
    x, y, z = (float(v) for v in p)
    return z, -x, -y


def mav_to_robot(x: float, y: float, z: float) -> np.ndarray:
    return np.array([-y, -z, x], dtype=float)


def tool_quaternion(pitch_rad: float, yaw_rad: float) -> list[float]:
    """MAVLink attitude quaternion (w, x, y, z) of a tool with robot-frame (pitch, yaw), roll 0."""
    return [float(v) for v in QuaternionBase([0.0, pitch_rad, -yaw_rad]).q]


def tool_pitch_yaw(q) -> tuple[float, float]:
    """(pitch, yaw) in the robot frame from a MAVLink attitude quaternion."""
    _, pitch, yaw = QuaternionBase([float(v) for v in q]).euler
    return float(pitch), wrap_angle(-float(yaw))


def pack_status(mode: str, watchdog: bool, moving: bool, at_target: bool, last_result: str, last_command: str,
                last_seq: int) -> int:
    """HEARTBEAT.custom_mode of the robot: bits 0-1 mode, 2 watchdog, 3 moving, 4 at_target,
    5-7 last result, 8-10 last command, 16-31 last sequence number."""
    return (MODES.index(mode) | watchdog << 2 | moving << 3 | at_target << 4 | RESULTS.index(last_result) << 5
            | COMMANDS.index(last_command) << 8 | (last_seq & 0xFFFF) << 16)


def unpack_status(custom_mode: int) -> dict:
    c = int(custom_mode)
    return {"mode": MODES[min(c & 3, len(MODES) - 1)], "watchdog": bool(c >> 2 & 1), "moving": bool(c >> 3 & 1),
            "at_target": bool(c >> 4 & 1), "last_result": RESULTS[min(c >> 5 & 7, len(RESULTS) - 1)],
            "last_command": COMMANDS[min(c >> 8 & 7, len(COMMANDS) - 1)], "last_seq": c >> 16 & 0xFFFF}


class SignedMAVLink(mavlink2.MAVLink):
    """pymavlink's MAVLink with a stricter signature check.

    pymavlink records a stream's timestamp before it compares the signature, so one forged
    packet with a future timestamp would make every genuine packet look replayed. Here the
    signature is checked first; the timestamp only advances on a genuine packet. The reason
    of the last failure ("forged", "replayed", "stale") is kept for the counters.
    """

    last_signature_failure = ""

    def parse_char(self, c):
        """pymavlink's parser, resynchronising after a stray start byte.

        pymavlink takes any 0xFD as the start of a packet and waits for the length its
        header claims (up to 280 bytes, several heartbeats' worth on a quiet line), then
        drops all of it when the CRC fails. Here a start byte whose header has unknown
        incompat flags is skipped at once, and the bytes behind the start byte of a
        rejected frame are scanned again.
        """
        self.buf.extend(c)
        self.total_bytes_received += len(c)
        while (self.buf_len() >= 3 and self.buf[self.buf_index] == mavlink2.PROTOCOL_MARKER_V2
               and self.buf[self.buf_index + 2] & ~mavlink2.MAVLINK_IFLAG_SIGNED):
            self.buf_index += 1
        m = super().parse_char(b"")
        if m is not None and m.get_type() == "BAD_DATA":
            data = bytes(getattr(m, "data", b""))
            reason = str(getattr(m, "reason", "")).lower()
            if (len(data) > 1 and data[0] in (mavlink2.PROTOCOL_MARKER_V1, mavlink2.PROTOCOL_MARKER_V2)
                    and "signature" not in reason):
                self.buf = bytearray(data[1:]) + self.buf[self.buf_index:]
                self.buf_index = 0
        return m

    def check_signature(self, msgbuf, srcSystem, srcComponent) -> bool:  # noqa: N803 - pymavlink's names
        import hashlib

        h = hashlib.new("sha256")
        h.update(self.signing.secret_key)
        h.update(msgbuf[:-6])
        if h.digest()[:6] != bytes(msgbuf[-6:]):
            self.last_signature_failure = "forged"
            return False
        tlow, thigh = self.mav_sign_unpacker.unpack(msgbuf[-12:-6])
        timestamp = tlow + (thigh << 32)
        stream = (msgbuf[-13], srcSystem, srcComponent)
        last = self.signing.stream_timestamps.get(stream)
        if last is not None and timestamp <= last:
            self.last_signature_failure = "replayed"
            return False
        if last is None and timestamp + 6000 * 1000 < self.signing.timestamp:
            self.last_signature_failure = "stale"
            return False
        self.signing.stream_timestamps[stream] = timestamp
        self.signing.timestamp = max(self.signing.timestamp, timestamp)
        return True


def make_mavlink(writer, src_system: int, src_component: int, signing_key: bytes | None, link_id: int) -> SignedMAVLink:
    """A MAVLink 2 endpoint that signs what it sends and refuses unsigned packets when given a key."""
    mav = SignedMAVLink(writer, srcSystem=src_system, srcComponent=src_component)
    mav.robust_parsing = True
    if signing_key is not None:
        if len(signing_key) != 32:
            raise ValueError(f"MAVLink signing key must be 32 bytes, got {len(signing_key)}")
        mav.signing.secret_key = bytes(signing_key)
        mav.signing.link_id = link_id
        mav.signing.timestamp = int((time.time() - MAVLINK_EPOCH_UNIX_S) * 100_000)
        mav.signing.sign_outgoing = True  # allow_unsigned_callback stays None: unsigned packets are refused
    return mav


def signature_failure(mav: SignedMAVLink, bad) -> str | None:
    """For a BAD_DATA packet: "unsigned", "forged", "replayed" or "stale"; None if not a signature problem."""
    if "signature" not in str(getattr(bad, "reason", "")).lower():
        return None
    data = bytes(getattr(bad, "data", b""))
    signed = len(data) > 2 and data[0] == mavlink2.PROTOCOL_MARKER_V2 and data[2] & mavlink2.MAVLINK_IFLAG_SIGNED
    if not signed:
        return "unsigned"
    why, mav.last_signature_failure = mav.last_signature_failure or "forged", ""
    return why


# ----------------------------------------------------------------------------------------------
# the link

_REGISTRY: dict[str, type["RobotLink"]] = {}


def register_link(name: str):
    """Class decorator: make a RobotLink implementation available to open_link(name)."""
    def deco(cls):
        cls.kind = name
        _REGISTRY[name] = cls
        return cls
    return deco


def open_link(kind: str, **options) -> "RobotLink":
    """The RobotLink implementation registered as ``kind`` ("can", "mavlink"), opened with ``options``."""
    try:
        cls = _REGISTRY[kind]
    except KeyError:
        raise ValueError(f"robot link kind must be one of {', '.join(sorted(_REGISTRY))}, got {kind!r}") from None
    return cls(**options)


class RobotLink:
    """The runtime's end of a robot link (template methods, like python-can's BusABC).

    Subclasses implement the transport: ``_open_transport``, ``_close_transport``, ``_send_target``,
    ``_send_mode``, ``_send_alarm``, ``_send_heartbeat`` and ``_receive``. This class does
    the sequence numbers, input checks, heartbeat timing, link supervision, reconnection
    with backoff and the statistics. Thread-safe (one lock); it never sleeps.
    """

    kind: ClassVar[str] = ""

    def __init__(self, config: LinkConfig | None = None, clock: Clock | None = None, reopenable: bool = True):
        self.config = config or LinkConfig()
        self.clock: Clock = clock or time.monotonic
        self.stats = LinkStats()
        self.last_error: str | None = None
        self.reopenable = reopenable
        self._lock = threading.RLock()
        self._seq = 0
        self._state: RobotState | None = None
        self._results: dict[int, str] = {}
        now = self.clock()
        self._t0 = now
        self._last_state_t: float | None = None
        self._waiting_since_t = now
        self._last_hb_t = -math.inf
        self._link_ok = False
        self._open = False
        self._backoff_s = self.config.reconnect_min_s
        self._retry_t = now
        self._runtime_state = "running"
        self._connect(now, first=True)

    # -- public API ------------------------------------------------------------------------
    def move_to(self, position_m, pitch_rad: float, yaw_rad: float) -> int:
        """Send a target (hand position m, tool pitch/yaw rad); returns its sequence number."""
        return self._target(position_m, pitch_rad, yaw_rad, retract=False)

    def retract(self, position_m, pitch_rad: float, yaw_rad: float) -> int:
        """Send a retraction target: accepted even while stopped; an unreachable one stops the arm."""
        return self._target(position_m, pitch_rad, yaw_rad, retract=True)

    def stop(self) -> int:
        """Stop: the arm decelerates to rest and refuses moves until resume()."""
        return self._command(lambda seq: self._send_mode(seq, "stop"))

    def resume(self) -> int:
        """Leave stop/retract and clear a latched watchdog; the arm holds where it is (mode run)."""
        return self._command(lambda seq: self._send_mode(seq, "resume"))

    def set_alarm(self, light: str, tone_hz: float, tone_db: float) -> int:
        """Warning light ("off", "green", "yellow", "red") and tone (Hz, 0 = silent; dB)."""
        light, tone_hz, tone_db = check_alarm(light, tone_hz, tone_db)
        return self._command(lambda seq: self._send_alarm(seq, light, tone_hz, tone_db))

    def heartbeat(self) -> bool:
        """Send the runtime heartbeat now (poll() also does when it is due). True if sent."""
        with self._lock:
            now = self.clock()
            ok = self._transmit(lambda: self._send_heartbeat(self._runtime_state, now - self._t0), now)
            self._last_hb_t = now
            self.stats.heartbeats += ok
            return ok

    def set_runtime_state(self, state: str) -> None:
        """What the heartbeat reports: "starting", "running", "degraded" or "fault"."""
        if state not in ("starting", "running", "degraded", "fault"):
            raise ValueError(f"runtime state must be starting, running, degraded or fault, got {state!r}")
        self._runtime_state = state

    def poll(self) -> RobotState | None:
        """Read what has arrived (never blocks); the newest complete state, or None if none came."""
        with self._lock:
            now = self.clock()
            if not self._open:
                self._maybe_reconnect(now)
            newest = None
            if self._open:
                try:
                    for st in self._receive(now):
                        newest = self._on_state(st)
                except LINK_ERRORS as exc:
                    self._fault(now, f"receive: {type(exc).__name__}: {exc}")
            period = self.config.heartbeat_period_s
            if period is not None and now - self._last_hb_t >= period:
                self.heartbeat()
            self._supervise(now)
            return newest

    @property
    def state(self) -> RobotState | None:
        """The latest complete state (check ``link_ok`` for its freshness)."""
        return self._state

    @property
    def link_ok(self) -> bool:
        """A state arrived within state_timeout_s and the transport is open."""
        return self._link_ok

    def result(self, seq: int) -> str | None:
        """What the controller answered to command ``seq`` ("ok", "unreachable", "refused", "invalid"), if known."""
        return self._results.get(seq)

    def close(self) -> None:
        with self._lock:
            if self._open:
                self._open = False
                self._safe_close()
            self._link_ok = False

    def __enter__(self) -> "RobotLink":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def summary(self) -> dict:
        return {"kind": self.kind, "link_ok": self._link_ok, **vars(self.stats)}

    # -- transport hooks (subclasses) -------------------------------------------------------
    def _open_transport(self) -> None:
        raise NotImplementedError

    def _close_transport(self) -> None:
        raise NotImplementedError

    def _send_target(self, seq: int, position_m: np.ndarray, pitch_rad: float, yaw_rad: float, retract: bool) -> None:
        raise NotImplementedError

    def _send_mode(self, seq: int, command: str) -> None:
        raise NotImplementedError

    def _send_alarm(self, seq: int, light: str, tone_hz: float, tone_db: float) -> None:
        raise NotImplementedError

    def _send_heartbeat(self, state: str, uptime_s: float) -> None:
        raise NotImplementedError

    def _receive(self, now: float) -> list[RobotState]:
        """Everything waiting, decoded; complete states in order. Raise a LINK_ERRORS fault if broken."""
        raise NotImplementedError

    # -- helpers for subclasses -------------------------------------------------------------
    def _record_result(self, seq: int, result: str) -> None:
        if seq == 0 or result not in RESULTS[1:] or self._results.get(seq) == result:
            return
        self._results[seq] = result
        if len(self._results) > 512:
            for k in list(self._results)[:256]:
                del self._results[k]
        if result in REFUSALS:
            self.stats.refused += 1

    # -- internals --------------------------------------------------------------------------
    def _target(self, position_m, pitch_rad: float, yaw_rad: float, retract: bool) -> int:
        p, pitch, yaw = check_target(position_m, pitch_rad, yaw_rad)
        return self._command(lambda seq: self._send_target(seq, p, pitch, yaw, retract))

    def _command(self, send: Callable[[int], None]) -> int:
        with self._lock:
            self._seq = next_seq(self._seq)
            seq = self._seq
            self._transmit(lambda: send(seq), self.clock())
            return seq

    def _transmit(self, send: Callable[[], None], now: float) -> bool:
        if not self._open:
            self._maybe_reconnect(now)
        if not self._open:
            self.stats.send_errors += 1
            return False
        try:
            send()
        except LINK_ERRORS as exc:
            self.stats.send_errors += 1
            self._fault(now, f"send: {type(exc).__name__}: {exc}")
            return False
        return True

    def _on_state(self, st: RobotState) -> RobotState:
        self._state = st
        self._last_state_t = st.t_s
        self.stats.states += 1
        self._record_result(st.last_seq, st.last_result)
        if not self._link_ok:
            self._link_ok = True
        return st

    def _supervise(self, now: float) -> None:
        fresh = self._last_state_t is not None and now - self._last_state_t <= self.config.state_timeout_s
        if self._link_ok and not fresh:
            self._link_ok = False
            self.stats.outages += 1
            self.last_error = f"no robot state for {self.config.state_timeout_s * 1000:.0f} ms"
        silent_since = max(self._waiting_since_t, self._last_state_t if self._last_state_t is not None else -math.inf)
        if self._open and self.reopenable and now - silent_since > self.config.stale_reopen_s:
            self._fault(now, f"no robot state for {now - silent_since:.1f} s: reopening")

    def _fault(self, now: float, why: str) -> None:
        self.last_error = why
        if self._link_ok:
            self._link_ok = False
            self.stats.outages += 1
        if self.reopenable:
            self._open = False
            self._safe_close()
            self._retry_t = now + self._backoff_s
            self._backoff_s = min(self._backoff_s * 2, self.config.reconnect_max_s)
        self._waiting_since_t = now

    def _safe_close(self) -> None:
        try:
            self._close_transport()
        except Exception:  # noqa: BLE001 - closing a broken transport may fail too
            pass

    def _maybe_reconnect(self, now: float) -> None:
        if self.reopenable and now >= self._retry_t:
            self._connect(now)

    def _connect(self, now: float, first: bool = False) -> None:
        try:
            self._open_transport()
        except (*LINK_ERRORS, ValueError) as exc:
            self.last_error = f"open: {type(exc).__name__}: {exc}"
            self._retry_t = now + self._backoff_s
            self._backoff_s = min(self._backoff_s * 2, self.config.reconnect_max_s)
            return
        self._open = True
        self._waiting_since_t = now
        self._backoff_s = self.config.reconnect_min_s
        if not first:
            self.stats.reconnects += 1


@register_link("can")
class CanRobotLink(RobotLink):
    """The robot link on a python-can bus, frames from ``robot_link.dbc`` with E2E Profile 1.

    Options: ``interface`` (default "socketcand"), ``channel`` ("vcan0"), ``host`` and
    ``port`` (socketcand), ``bitrate``; or ``bus``: an open python-can bus (not reopened
    on faults). ``config``, ``clock`` as for :class:`RobotLink`.
    """

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
            status, name, sig = self.codec.decode(msg)
            if sig is None:
                if status != "unknown_id":
                    self.stats.integrity_errors += 1
                continue
            self.stats.frames_received += 1
            st = self._assembler.feed(name, sig, now)
            if st is not None:
                states.append(st)
        return states


@register_link("mavlink")
class MavlinkRobotLink(RobotLink):
    """The robot link over MAVLink 2 on a serial line (``path``, or ``serial="serial:PATH[?key=HEX]"``)
    or a given byte ``stream``.

    ``signing_key`` (32 bytes): sign everything sent and refuse unsigned, forged and
    replayed packets (counted in ``stats.integrity_errors`` and ``signature_failures``).
    """

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

    def _send_alarm(self, seq, light, tone_hz, tone_db) -> None:
        self._command_long(MAV_CMD_ALARM, seq, float(LIGHTS.index(light)), tone_hz, tone_db)

    def _send_heartbeat(self, state, uptime_s) -> None:
        status = {"starting": mavlink2.MAV_STATE_BOOT, "running": mavlink2.MAV_STATE_ACTIVE,
                  "degraded": mavlink2.MAV_STATE_CRITICAL, "fault": mavlink2.MAV_STATE_EMERGENCY}[state]
        self.mav.heartbeat_send(mavlink2.MAV_TYPE_ONBOARD_CONTROLLER, mavlink2.MAV_AUTOPILOT_INVALID, 0, 0, status)

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
                                    light=LIGHTS[int(round(a[14])) % len(LIGHTS)], tone_hz=float(a[15]),
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
