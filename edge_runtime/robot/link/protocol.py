"""The robot link's wire contract, shared by both ends: the runtime's links
(:mod:`edge_runtime.robot.link.can`, :mod:`edge_runtime.robot.link.mavlink`) and the
simulated Sawyer controller (:mod:`firmware_sim.robot.controller`).

Here: the names and constants (lights, modes, commands, results), :class:`RobotState`,
sequence numbers and angles, the checks a target and an alarm must pass, the CAN codec
and state assembler, the MAVLink conventions (frames, quaternions, the packed status,
command ids, signing) and the byte streams MAVLink runs on. Nothing here keeps link
state or timing; that is :mod:`edge_runtime.robot.link.base`.

Positions are metres in the robot frame (``edge_runtime/core/skeleton.py``: origin on top
of the Sawyer base, y up, the work side +z). The tool direction is (pitch, yaw):
``d = (cos(pitch)·sin(yaw), sin(pitch), cos(pitch)·cos(yaw))``; roll is left to the arm.

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
                                           Hz, param3 tone dB. MAV_CMD_DO_CHANGE_SPEED (speed
                                           override): param1 1, param2 the hand's speed limit
                                           (m/s), param3 -1
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

import functools
import math
import os
import socket
from dataclasses import dataclass, field

import can
import numpy as np
import serial
from pymavlink.dialects.v20 import common as mavlink2
from pymavlink.quaternion import QuaternionBase

from edge_runtime.canbus.bus import CanLinkError, open_bus
from edge_runtime.canbus.dbc import load_dbc
from edge_runtime.canbus.e2e import E2EChecker, E2EProtector
from edge_runtime.core.manifest import ASSETS_DIR
from edge_runtime.core.mavlink import (  # noqa: F401 - the MAVLink endpoint, shared with the wearable
    MAVLINK_EPOCH_UNIX_S,
    SignedMAVLink,
    make_mavlink,
    signature_failure,
)

DBC_PATH = ASSETS_DIR / "robot_link.dbc"

LIGHTS = ("off", "green", "yellow", "red")
MODES = ("stopped", "run", "retract")
COMMANDS = ("none", "move", "retract", "stop", "resume", "alarm", "speed")
RESULTS = ("none", "ok", "unreachable", "refused", "invalid")
REFUSALS = ("unreachable", "refused", "invalid")
N_JOINTS = 7
SEQ_MAX = 65535
MAX_TONE_HZ = 20000.0
MAX_TONE_DB = 127.5
MAX_SPEED_LIMIT_MPS = 1.5
"""A speed override above this is not a Sawyer's (its rated maximum hand speed is 1.5 m/s)."""
LINK_ERRORS = (OSError, can.CanError, serial.SerialException, CanLinkError)
"""Transport faults: the link is reported down and reopened, never raised to the caller."""
RUNTIME_STATES = ("starting", "running", "degraded", "fault")
"""What the runtime's heartbeat reports about itself."""


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

    @classmethod
    def from_fields(cls, fields: dict) -> RobotState:
        """``RobotState(**fields)`` for a dict of every field, in field order (the CAN assembler's): the same
        object, made without the frozen dataclass's ``object.__setattr__`` per field (17 of them: 7 of the
        ~90 us a state's seven frames cost to receive, 100 times a second). ``__init__`` does nothing else."""
        st = object.__new__(cls)
        st.__dict__.update(fields)
        return st


def blank_state(t_s: float = 0.0) -> RobotState:
    return RobotState(t_s, np.zeros(N_JOINTS), np.zeros(3), 0.0, 0.0, 0.0, "stopped", False, False, False,
                      "off", 0.0, 0.0, "none", 0, "none", 0.0, {})


def next_seq(seq: int) -> int:
    """The sequence number after ``seq``: 1..65535, wrapping to 1 (0 means none)."""
    return 1 if seq >= SEQ_MAX else seq + 1


def wrap_angle(a: float) -> float:
    """Angle in (-pi, pi]; NaN for a non-finite angle (which has no direction)."""
    if not math.isfinite(a):
        return math.nan
    a = math.remainder(float(a), 2 * math.pi)
    return math.pi if a == -math.pi else a


def check_target(position_m, pitch_rad: float, yaw_rad: float) -> tuple[np.ndarray, float, float]:
    """Validated (position (3,), pitch in [-pi/2, pi/2], yaw in (-pi, pi]); ValueError names the field."""
    p = np.asarray(position_m, dtype=float).reshape(-1)
    # the checks on the three values as Python floats (the same IEEE comparisons as numpy's, without its
    # per-call cost: every move and retraction passes here; tests/robot/link/test_link_cost_s17.py)
    xyz = p.tolist()
    if p.shape != (3,) or not all(math.isfinite(v) for v in xyz):
        raise ValueError(f"position_m must be 3 finite numbers (m), got {position_m!r}")
    if not _finite_within(xyz, POSITION_LIMIT_M):
        raise ValueError(f"position_m {tuple(np.round(p, 3))} is outside +-{POSITION_LIMIT_M} m of the robot base")
    if not math.isfinite(pitch_rad) or abs(pitch_rad) > math.pi / 2 + 1e-9:
        raise ValueError(f"pitch_rad must lie in [-pi/2, pi/2], got {pitch_rad!r}")
    if not math.isfinite(yaw_rad):
        raise ValueError(f"yaw_rad must be finite, got {yaw_rad!r}")
    return p, max(-math.pi / 2, min(math.pi / 2, float(pitch_rad))), wrap_angle(yaw_rad)


MAX_JOINT_RAD = 2 * math.pi
"""A reported joint angle beyond this is not a Sawyer's (its widest joint turns +-3.5 rad)."""
MAX_EE_SPEED_MPS = 10.0
"""A reported hand speed beyond this is not a Sawyer's (its rated maximum is 1.5 m/s)."""
POSITION_LIMIT_M = 3.2
"""Every position on the link lies within this of the robot base (the CAN encoding's range)."""


def check_state(st: RobotState) -> str | None:
    """Why a received state cannot be used (None: it can). A state is a measurement the
    runtime decides on, so a non-finite or impossible value refuses the whole state
    rather than reaching the distance check."""
    p = np.asarray(st.ee_position_m, dtype=float)
    q = np.asarray(st.joint_positions_rad, dtype=float)
    if p.shape != (3,) or not _finite_within(p.tolist(), POSITION_LIMIT_M):
        return "ee_position_m"
    if q.shape != (N_JOINTS,) or not _finite_within(q.tolist(), MAX_JOINT_RAD):
        return "joint_positions_rad"
    for name, lo, hi in _STATE_RANGES:
        v = getattr(st, name)
        if not (math.isfinite(v) and lo <= v <= hi):
            return name
    for name, allowed in _STATE_NAMES:
        if getattr(st, name) not in allowed:
            return name
    return None


_STATE_RANGES = (("pitch_rad", -math.pi / 2 - 1e-3, math.pi / 2 + 1e-3), ("yaw_rad", -math.pi, math.pi),
                 ("ee_speed_mps", 0.0, MAX_EE_SPEED_MPS), ("tone_hz", 0.0, MAX_TONE_HZ),
                 ("tone_db", 0.0, MAX_TONE_DB), ("robot_time_s", 0.0, math.inf))
"""check_state's numeric fields and their [lo, hi], made once (not per state)."""
_STATE_NAMES = (("mode", MODES), ("light", LIGHTS), ("last_command", COMMANDS), ("last_result", RESULTS))


def _finite_within(values: list[float], limit: float) -> bool:
    """Every value finite and its magnitude at most ``limit``: ``np.isfinite(a).all() and np.abs(a).max() <= limit``
    on a few floats, without numpy's per-call cost (a state is checked up to 100 times a second)."""
    return all(math.isfinite(v) and abs(v) <= limit for v in values)


def light_name(code: float) -> str:
    """The light of a numeric light code (0 off .. 3 red); a code that is not one of them
    comes back as its text, which :func:`check_state` and :func:`check_alarm` refuse."""
    if math.isfinite(code) and code == int(code) and 0 <= code < len(LIGHTS):
        return LIGHTS[int(code)]
    return f"code {code}"


def check_speed(limit_mps: float) -> float:
    """A validated hand speed limit (m/s, 0..MAX_SPEED_LIMIT_MPS); ValueError names the field."""
    if not (isinstance(limit_mps, (int, float)) and math.isfinite(limit_mps)
            and 0.0 <= limit_mps <= MAX_SPEED_LIMIT_MPS):
        raise ValueError(f"speed limit must lie in [0, {MAX_SPEED_LIMIT_MPS:g}] m/s, got {limit_mps!r}")
    return float(limit_mps)


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

@functools.lru_cache(maxsize=1)
def robot_link_db():
    """``robot_link.dbc``, parsed once per process (read-only afterwards; a link that is
    reopened, or a test that makes many, does not parse it again)."""
    return load_dbc(DBC_PATH)


class RobotCanCodec:
    """Encodes and decodes robot-link frames with cantools from ``robot_link.dbc``, with E2E.

    One alive counter per frame ID on the sending side; on the receiving side an
    :class:`E2EChecker` (CRC, then counter). Used by both ends of the link.
    """

    def __init__(self, db=None):
        self.db = db if db is not None else robot_link_db()
        self.checker = E2EChecker(db=self.db)
        self._by_name = {m.name: m for m in self.db.messages}
        self._by_id = {m.frame_id: m for m in self.db.messages}
        self._ranges = {m.frame_id: _signal_ranges(m) for m in self.db.messages}
        self._decoded: dict[tuple[int, bytes], tuple[str, dict | None]] = {}
        self._e2e = E2EProtector()

    def encode(self, name: str, **signals) -> can.Message:
        """A protected frame: signals by cantools, then alive counter and CRC (Profile 1)."""
        return self._e2e.protect(self._by_name[name], signals)

    def _command(self, name: str, **signals) -> can.Message:
        """:meth:`encode` for a command frame: its sequence number is new, so its signals never come again and
        the payload cache is neither searched nor filled (3-4 us of a 15-18 us frame, with the same bytes)."""
        return self._e2e.protect(self._by_name[name], signals, remember=False)

    def decode(self, msg: can.Message) -> tuple[str, str, dict | None]:
        """(status, message name, signals). Signals is None unless the frame is valid.

        The E2E check comes first and checks the frame's shape before its bytes are read
        (``bad_frame``: an error or remote frame, the wrong identifier kind or length; a
        short frame would make cantools raise). The decoded values are then held to the
        DBC: every enumerated signal one of its named values and every signal within its
        [min|max] (``out_of_range``). The signals are the caller's own copy."""
        status, name, sig = self.decode_shared(msg)
        return status, name, None if sig is None else dict(sig)

    def decode_shared(self, msg: can.Message) -> tuple[str, str, dict | None]:
        """:meth:`decode` without the copy: the signals are the codec's remembered decoding, which the
        caller only reads (the link's state assembler, seven frames every 10 ms)."""
        res = self.checker.check(msg)
        if not res.valid:
            return res.status, "", None
        frame_id = msg.arbitration_id
        # the same bytes decode to the same signals: the arm repeats its state (the counter and CRC
        # cycle through 15 values per signal set), so a decoded, range-checked frame is looked up,
        # with its message's name (a cantools property: read once per decoding, not per frame)
        key = (frame_id, bytes(msg.data))
        decoded = self._decoded.get(key)
        if decoded is None:
            message = self._by_id[frame_id]
            sig = message.decode(key[1], decode_choices=True)
            decoded = message.name, (sig if _in_ranges(self._ranges[frame_id], sig) else None)
            if len(self._decoded) >= DECODED_CACHE:
                del self._decoded[next(iter(self._decoded))]
            self._decoded[key] = decoded
        name, sig = decoded
        if sig is None:
            return "out_of_range", name, None
        return res.status, name, sig

    # -- runtime -> robot ------------------------------------------------------------------
    def target_frames(self, seq: int, position_m, pitch_rad: float, yaw_rad: float, retract: bool) -> list[can.Message]:
        x, y, z = (float(v) * 1000.0 for v in position_m)
        return [self._command("ROBOT_TARGET_ORIENT", Kind="retract" if retract else "move", Seq=seq,
                              Pitch=pitch_rad, Yaw=yaw_rad),
                self._command("ROBOT_TARGET_POS", SeqCheck=seq % 16, X=x, Y=y, Z=z)]

    def mode_frame(self, seq: int, command: str) -> can.Message:
        return self._command("ROBOT_MODE_CMD", Command=command, Seq=seq)

    def alarm_frame(self, seq: int, light: str, tone_hz: float, tone_db: float) -> can.Message:
        return self._command("ROBOT_ALARM_CMD", Light=light, Seq=seq, ToneFreq=round(tone_hz),
                             ToneLevel=round(tone_db * 2) / 2)

    def speed_frame(self, seq: int, limit_mps: float) -> can.Message:
        return self._command("ROBOT_SPEED_CMD", Seq=seq, SpeedLimit=round(limit_mps * 10000.0) / 10.0)

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


DECODED_CACHE = 1024
"""Decoded frames remembered per codec, by identifier and bytes (the oldest dropped first)."""


def _signal_in_range(signal, value) -> bool:
    """A decoded signal is one of its named values (when it has choices) and within its DBC range."""
    return _in_ranges(_signal_ranges_of((signal,)), {signal.name: value})


def _signal_ranges(message) -> tuple:
    """What :func:`_in_ranges` holds a decoded ``message`` to, from the DBC, made once per message."""
    return _signal_ranges_of(message.signals)


def _signal_ranges_of(signals) -> tuple:
    out = []
    for signal in signals:
        if signal.choices:
            out.append((signal.name, True, None, None))
            continue
        lo, hi = signal.minimum, signal.maximum
        slack = abs(signal.scale) / 2  # the DBC's limits are physical values; decoding rounds to a raw step
        out.append((signal.name, False, None if lo is None else lo - slack, None if hi is None else hi + slack))
    return tuple(out)


def _in_ranges(ranges: tuple, sig: dict) -> bool:
    """Every signal one of its named values (when it has choices) and within its DBC range."""
    for name, named, lo, hi in ranges:
        value = sig[name]
        if named:
            if isinstance(value, (int, float)):  # cantools leaves an unnamed raw value a number
                return False
        elif not ((lo is None or value >= lo) and (hi is None or value <= hi)):
            return False
    return True


def open_can_bus(interface: str, channel: str, host: str | None = None, port: int | None = None,
                 bitrate: int | None = None) -> can.BusABC:
    """A python-can bus for the robot link (both ends): :func:`edge_runtime.canbus.bus.open_bus`."""
    return open_bus(interface, channel, bitrate, host=host, port=port)


class CanStateAssembler:
    """Builds RobotState objects from the robot's frames; ROBOT_STATUS completes one.

    The fields gathered so far are kept in a dict and made into one RobotState when a state
    completes (a frozen dataclass ``replace`` per frame cost more than the frame's decoding)."""

    def __init__(self):
        self._fields = vars(blank_state()).copy()
        self._joints = np.zeros(N_JOINTS)
        self._joint_slots: dict[str, tuple[tuple[str, int], ...]] = {}

    def feed(self, name: str, sig: dict, t_s: float) -> RobotState | None:
        f = self._fields
        if name == "ROBOT_EE_POSITION":
            # each millimetre value / 1000.0 in Python: the IEEE division numpy's elementwise one is (no second array)
            f["ee_position_m"] = np.array([sig["X"] / 1000.0, sig["Y"] / 1000.0, sig["Z"] / 1000.0])
        elif name == "ROBOT_EE_ORIENT":
            f["pitch_rad"], f["yaw_rad"], f["ee_speed_mps"] = sig["Pitch"], sig["Yaw"], sig["Speed"] / 1000.0
        elif name.startswith("ROBOT_JOINTS_"):
            slots = self._joint_slots.get(name)
            if slots is None:  # its joint signals (J<index>) and their indices, found in its first decoding
                slots = self._joint_slots[name] = tuple((k, int(k[1:])) for k in sig
                                                        if k.startswith("J") and k[1:].isdigit())
            joints = self._joints
            for k, i in slots:
                joints[i] = sig[k]
        elif name == "ROBOT_ALARM_STATE":
            f["light"], f["tone_hz"], f["tone_db"] = str(sig["Light"]), float(sig["ToneFreq"]), float(sig["ToneLevel"])
        elif name == "ROBOT_COUNTERS":
            f["counters"] = {"watchdog_trips": sig["WatchdogTrips"], "rx_valid": sig["RxValid"],
                             "integrity_errors": sig["IntegrityErrors"], "refused": sig["Refused"]}
        elif name == "ROBOT_STATUS":
            f.update(t_s=t_s, joint_positions_rad=self._joints.copy(), mode=str(sig["Mode"]),
                     watchdog=bool(sig["Watchdog"]), moving=bool(sig["Moving"]), at_target=bool(sig["AtTarget"]),
                     last_command=str(sig["LastCommand"]), last_result=str(sig["LastResult"]),
                     last_seq=int(sig["LastSeq"]), robot_time_s=sig["RobotTime"] / 1000.0)
            return RobotState.from_fields(f)  # f holds every field, in order (made from blank_state())
        return None


# ----------------------------------------------------------------------------------------------
# MAVLink: frames, orientation and the packed status

MAV_CMD_STOP_RESUME = mavlink2.MAV_CMD_DO_PAUSE_CONTINUE
MAV_CMD_RETRACT = mavlink2.MAV_CMD_USER_1
MAV_CMD_ALARM = mavlink2.MAV_CMD_USER_2
MAV_CMD_SPEED = mavlink2.MAV_CMD_DO_CHANGE_SPEED
"""The speed override: param1 1 (ground speed), param2 the hand's speed limit (m/s), param3 -1 (throttle
unchanged)."""
MAV_CMD_MOVE_ACK = mavlink2.MAV_CMD_USER_3
"""The command id under which a move (SET_ATTITUDE_TARGET + SET_POSITION_TARGET_LOCAL_NED) is acknowledged."""
RESULT_TO_MAV = {"ok": mavlink2.MAV_RESULT_ACCEPTED, "unreachable": mavlink2.MAV_RESULT_FAILED,
                 "refused": mavlink2.MAV_RESULT_TEMPORARILY_REJECTED, "invalid": mavlink2.MAV_RESULT_DENIED}
MAV_TO_RESULT = {v: k for k, v in RESULT_TO_MAV.items()}
RUNTIME_STATE_TO_MAV = {"starting": mavlink2.MAV_STATE_BOOT, "running": mavlink2.MAV_STATE_ACTIVE,
                        "degraded": mavlink2.MAV_STATE_CRITICAL, "fault": mavlink2.MAV_STATE_EMERGENCY}
"""The runtime's HEARTBEAT.system_status for each of RUNTIME_STATES."""
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
