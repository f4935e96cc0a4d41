"""The simulated Sawyer controller: the arm of :mod:`firmware_sim.robot.sawyer` behind a CAN or MAVLink link.

The protocol is the runtime's (``edge_runtime/robot/link/protocol.py`` and
``edge_runtime/assets/robot_link.dbc``); this module is the other end of it.

Behaviour (the same on both links):

* The controller boots **stopped** and holds its posture; ``resume`` puts it in mode
  ``run``, where move targets are accepted. ``stop`` decelerates the arm to rest within
  its limits and refuses moves until ``resume``. A retraction is accepted in ``run``,
  ``stopped`` and ``retract``; an unreachable retraction stops the arm.
* A target is solved by inverse kinematics when it arrives; one that cannot be reached
  (or lies in the floor or pedestal) is refused as ``unreachable`` and the arm keeps
  its previous goal: never an approximation.
* **Watchdog**: no valid runtime frame (command or heartbeat) for 200 ms and the arm
  stops and the state reports ``watchdog``. It stays latched until an explicit
  ``resume`` (a heartbeat alone does not restart motion).
* Light and tone are state the runtime sets; every state report carries them.
* Integrity: frames failing E2E (CAN) or the MAVLink signature (unsigned, forged,
  replayed) or CRC are discarded and counted; they do not feed the watchdog.
* State reports go out at ``state_rate_hz`` (100 Hz), counters every 100 ms.

Three ways to run it:

``python -m firmware_sim sawyer --link can --can-port P`` / ``--link mavlink --pty``
    a real-time process (the first stdout line is the pty path, or for CAN
    ``socketcand:HOST:PORT:CHANNEL``); :class:`SawyerProcess` runs it for tests.
:class:`SawyerController` with a port
    the same logic in-process, driven by ``step(dt_s)`` on an injected clock.
:class:`SimulatedRobot`
    a connected (controller, RobotLink) pair over python-can's ``virtual`` bus or a
    socket pair, both on a :class:`SimClock`: ``step(dt_s)`` advances the arm and
    delivers the messages both ways through the real encode/decode path, faster than
    real time.
"""
from __future__ import annotations

import argparse
import itertools
import json
import math
import os
import signal
import socket
import subprocess
import sys
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

import can
import numpy as np
from pymavlink.dialects.v20 import common as mavlink2

from edge_runtime.robot.link.base import open_link
from edge_runtime.robot.link.options import add_bus_arguments
from edge_runtime.robot.link.protocol import (
    LIGHTS,
    LINK_ERRORS,
    MAV_CMD_ALARM,
    MAV_CMD_MOVE_ACK,
    MAV_CMD_RETRACT,
    MAV_CMD_SPEED,
    MAV_CMD_STOP_RESUME,
    RESULT_TO_MAV,
    ROBOT_COMPID,
    ROBOT_SYSID,
    SEQ_MAX,
    FdStream,
    RobotCanCodec,
    RobotState,
    SerialStream,
    SocketStream,
    check_alarm,
    check_speed,
    check_target,
    light_name,
    make_mavlink,
    mav_to_robot,
    open_can_bus,
    pack_status,
    robot_to_mav,
    signature_failure,
    tool_pitch_yaw,
)
from firmware_sim.devices.imu_firmware import close_pty_pair, open_pty_pair
from firmware_sim.robot.sawyer import ArmConfig, SawyerArm, Unreachable, warm_up

if TYPE_CHECKING:  # the runtime's link is only run here, through open_link
    from edge_runtime.robot.link.base import LinkConfig, RobotLink

DEFAULT_CHANNEL = "vcan0"
QUATERNION_NORM_TOLERANCE = 1e-3
"""MAVLink: an attitude quaternion whose norm is further than this from 1 is refused (a zero
or scaled quaternion describes no attitude; float32 on the wire keeps a unit one within 1e-6)."""
HALF_TARGET_TIMEOUT_S = 0.1
"""CAN: a target's position half must follow its direction half within this time."""


@dataclass(frozen=True)
class ControllerConfig:
    """Timing of the simulated controller."""

    watchdog_s: float = 0.2
    """No valid runtime frame for this long: stop the arm and latch the watchdog."""
    state_rate_hz: float = 100.0
    """State reports per second (on the controller's clock)."""
    counters_period_s: float = 0.1
    """Counter reports (ROBOT_COUNTERS / SYS_STATUS) every this many seconds."""
    reconnect_min_s: float = 0.1
    """CAN: first retry after the bus broke; doubles up to reconnect_max_s."""
    reconnect_max_s: float = 1.0
    refuse_commands: bool = False
    """Answer every command (not the heartbeat) ``refused`` and carry none out: an arm held in
    its local or teach mode, which the runtime must notice rather than report success."""
    arm: ArmConfig = field(default_factory=ArmConfig)


@dataclass
class Command:
    """One runtime command, decoded by a port."""

    kind: str
    """"move", "retract", "stop", "resume", "alarm", "speed" or "heartbeat"."""
    seq: int = 0
    speed_mps: float = 0.0
    """A speed override's hand speed limit (m/s)."""
    position_m: np.ndarray | None = None
    pitch_rad: float = 0.0
    yaw_rad: float = 0.0
    light: str = "off"
    tone_hz: float = 0.0
    tone_db: float = 0.0
    invalid: str = ""
    """Why the command cannot be executed (answered "invalid"); empty when it can."""
    reply_to: tuple = ()
    """Transport detail for the acknowledgement (MAVLink: command id, sender system and component)."""


def _count(counters: dict, key: str, n: int = 1) -> None:
    counters[key] = counters.get(key, 0) + n


# ----------------------------------------------------------------------------------------------
# ports: the controller's end of each transport

class CanControllerPort:
    """Robot-link frames on a python-can bus (reopened with backoff through ``bus_factory``)."""

    def __init__(self, bus: can.BusABC | None = None, bus_factory=None, config: ControllerConfig | None = None):
        if bus is None and bus_factory is None:
            raise ValueError("give bus= or bus_factory=")
        self.config = config or ControllerConfig()
        self.bus = bus
        self.bus_factory = bus_factory
        self.codec = RobotCanCodec()
        self.counters: dict[str, int] = {"rx_valid": 0, "integrity_errors": 0}
        self._pending: tuple[dict, float] | None = None
        """The direction half of a target and when it arrived."""
        self._retry_t = -math.inf
        self._backoff_s = self.config.reconnect_min_s

    def _ensure_bus(self, now: float) -> bool:
        if self.bus is None and self.bus_factory is not None and now >= self._retry_t:
            try:
                self.bus = self.bus_factory()
                self._backoff_s = self.config.reconnect_min_s
                _count(self.counters, "reconnects")
            except (*LINK_ERRORS, ValueError):
                self._retry_t = now + self._backoff_s
                self._backoff_s = min(2 * self._backoff_s, self.config.reconnect_max_s)
        return self.bus is not None

    def _fault(self, now: float) -> None:
        _count(self.counters, "link_faults")
        if self.bus_factory is None:
            return
        bus, self.bus = self.bus, None
        try:
            bus.shutdown()
        except Exception:  # noqa: BLE001 - a broken bus may fail to close
            pass
        self._retry_t = now + self._backoff_s

    def receive(self, now: float) -> list[Command]:
        out: list[Command] = []
        if not self._ensure_bus(now):
            return out
        try:
            while (msg := self.bus.recv(timeout=0)) is not None:
                cmd = self._decode(msg, now)
                if cmd is not None:
                    out.append(cmd)
        except LINK_ERRORS:
            self._fault(now)
        return out

    def _decode(self, msg: can.Message, now: float) -> Command | None:
        status, name, sig = self.codec.decode(msg)
        if sig is None:
            if status != "unknown_id":
                _count(self.counters, "integrity_errors")
            return None
        _count(self.counters, "rx_valid")
        if name == "RUNTIME_HEARTBEAT":
            return Command("heartbeat")
        if name == "ROBOT_MODE_CMD":
            return Command(str(sig["Command"]), seq=int(sig["Seq"]),
                           invalid="" if sig["Command"] in ("stop", "resume") else f"unknown command {sig['Command']}")
        if name == "ROBOT_ALARM_CMD":
            light = str(sig["Light"])
            return Command("alarm", seq=int(sig["Seq"]), light=light, tone_hz=float(sig["ToneFreq"]),
                           tone_db=float(sig["ToneLevel"]), invalid="" if light in LIGHTS else f"unknown light {light}")
        if name == "ROBOT_SPEED_CMD":
            return Command("speed", seq=int(sig["Seq"]), speed_mps=float(sig["SpeedLimit"]) / 1000.0)
        if name == "ROBOT_TARGET_ORIENT":
            self._pending = (sig, now)
            return None
        if name == "ROBOT_TARGET_POS":
            pending, self._pending = self._pending, None
            half = pending[0] if pending is not None and now - pending[1] <= HALF_TARGET_TIMEOUT_S else None
            if half is None or half["Seq"] % 16 != sig["SeqCheck"]:
                _count(self.counters, "incomplete_targets")
                seq = int(half["Seq"]) if half is not None else 0
                return Command("move", seq=seq, invalid="target position without its direction half")
            kind = "retract" if half["Kind"] == "retract" else "move"
            return Command(kind, seq=int(half["Seq"]), position_m=np.array([sig["X"], sig["Y"], sig["Z"]]) / 1000.0,
                           pitch_rad=float(half["Pitch"]), yaw_rad=float(half["Yaw"]))
        return None

    def acknowledge(self, cmd: Command, result: str, state: RobotState) -> None:
        """Results travel in ROBOT_STATUS (LastSeq, LastCommand, LastResult): one goes out now, so
        that the runtime sees the result of every command even when several arrive in one cycle."""
        self._send([self.codec.status_frame(state)], state.t_s)

    def publish(self, state: RobotState, counters: dict | None, now: float) -> None:
        frames = self.codec.state_frames(state)
        if counters is not None:
            frames.append(self.codec.counters_frame(counters))
        self._send(frames, now)

    def _send(self, frames: list[can.Message], now: float) -> None:
        if not self._ensure_bus(now):
            return
        try:
            for f in frames:
                self.bus.send(f)
        except LINK_ERRORS:
            self._fault(now)

    def close(self) -> None:
        if self.bus is not None and self.bus_factory is not None:
            self.bus.shutdown()
        self.bus = None


class MavlinkControllerPort:
    """MAVLink 2 on a byte stream (pty master, serial line, socket), signed when given a key."""

    def __init__(self, stream, signing_key: bytes | None = None, link_id: int = 0,
                 runtime_sysid: int | None = None):
        self.stream = stream
        self.runtime_sysid = runtime_sysid
        """When set, only packets from this MAVLink system id are taken as the runtime's
        (an unsigned link cannot otherwise tell the runtime from another system on the line)."""
        self.counters: dict[str, int] = {"rx_valid": 0, "integrity_errors": 0}
        self.mav = make_mavlink(self, ROBOT_SYSID, ROBOT_COMPID, signing_key, link_id)
        self._attitude: tuple[int, object] | None = None
        self._cycles = 0

    def write(self, buf: bytes) -> None:  # pymavlink writes through this
        try:
            self.stream.write(bytes(buf))
        except BlockingIOError:
            _count(self.counters, "tx_overflow")  # nobody reads the line: drop, like a UART
        except OSError:
            _count(self.counters, "link_faults")

    def receive(self, now: float) -> list[Command]:
        out: list[Command] = []
        for _ in range(64):
            try:
                data = self.stream.read()
            except LINK_ERRORS:
                _count(self.counters, "link_faults")
                break
            if not data:
                break
            for m in self.mav.parse_buffer(data) or ():
                cmd = self._decode(m)
                if cmd is not None:
                    out.append(cmd)
        return out

    def _decode(self, m) -> Command | None:
        mtype = m.get_type()
        if mtype == "BAD_DATA":
            why = signature_failure(self.mav, m)
            if why is not None:
                _count(self.counters, f"signature_{why}")
                _count(self.counters, "integrity_errors")
            else:  # a failed CRC, a bad header or junk bytes
                _count(self.counters, "crc_errors")
                _count(self.counters, "integrity_errors")
            return None
        src = (m.get_srcSystem(), m.get_srcComponent())
        if self.runtime_sysid is not None and src[0] != self.runtime_sysid:
            _count(self.counters, "foreign_system")
            return None
        _count(self.counters, "rx_valid")
        if mtype == "HEARTBEAT":
            return Command("heartbeat")
        if mtype == "SET_ATTITUDE_TARGET":
            self._attitude = (m.time_boot_ms, m.q)
            return None
        if mtype == "SET_POSITION_TARGET_LOCAL_NED":
            return self._move(m, src)
        if mtype == "COMMAND_LONG":
            return self._command_long(m, src)
        return None

    def _move(self, m, src) -> Command:
        att, self._attitude = self._attitude, None
        seq = int(m.time_boot_ms) & 0xFFFF
        reply = (MAV_CMD_MOVE_ACK, *src)
        if att is None or att[0] != m.time_boot_ms:
            _count(self.counters, "incomplete_targets")
            return Command("move", seq=seq, invalid="position target without its attitude half", reply_to=reply)
        if m.coordinate_frame != mavlink2.MAV_FRAME_LOCAL_NED or m.type_mask & 0b111:
            return Command("move", seq=seq, invalid="position target must be LOCAL_NED with x, y, z", reply_to=reply)
        q = np.asarray(att[1], dtype=float)
        if not (np.isfinite(q).all() and abs(np.linalg.norm(q) - 1.0) <= QUATERNION_NORM_TOLERANCE):
            return Command("move", seq=seq, invalid=f"attitude quaternion {q.tolist()} is not a unit quaternion",
                           reply_to=reply)
        pitch, yaw = tool_pitch_yaw(q)
        return Command("move", seq=seq, position_m=mav_to_robot(m.x, m.y, m.z), pitch_rad=pitch, yaw_rad=yaw,
                       reply_to=reply)

    def _command_long(self, m, src) -> Command:
        reply = (m.command, *src)
        if not (math.isfinite(m.param7) and m.param7 == int(m.param7) and 0 <= m.param7 <= SEQ_MAX):
            return Command("none", invalid=f"sequence number {m.param7!r} is not an integer in 0..{SEQ_MAX}",
                           reply_to=reply)
        seq = int(m.param7)
        if m.command == MAV_CMD_STOP_RESUME:  # param1 exactly 0 (stop) or 1 (resume): nothing else is either
            kind = {0.0: "stop", 1.0: "resume"}.get(m.param1)
            return Command(kind or "none", seq=seq, reply_to=reply,
                           invalid="" if kind else f"pause/continue param1 {m.param1!r} is neither 0 nor 1")
        if m.command == MAV_CMD_RETRACT:
            return Command("retract", seq=seq, position_m=mav_to_robot(m.param1, m.param2, m.param3),
                           pitch_rad=float(m.param4), yaw_rad=-float(m.param5), reply_to=reply)
        if m.command == MAV_CMD_SPEED:  # param1 1 (ground speed), param3 -1 (throttle unchanged) only
            ok = m.param1 == 1.0 and m.param3 == -1.0
            return Command("speed", seq=seq, speed_mps=float(m.param2), reply_to=reply,
                           invalid="" if ok else f"change-speed param1 {m.param1!r} / param3 {m.param3!r}")
        if m.command == MAV_CMD_ALARM:
            light = light_name(m.param1)
            return Command("alarm", seq=seq, light=light, tone_hz=float(m.param2), tone_db=float(m.param3),
                           invalid="" if light in LIGHTS else f"unknown light {light}", reply_to=reply)
        return Command("none", seq=seq, invalid=f"unsupported command {m.command}", reply_to=reply)

    def acknowledge(self, cmd: Command, result: str, state: RobotState) -> None:
        """COMMAND_ACK to the sender, result_param2 = the command's sequence number."""
        if not cmd.reply_to:
            return
        command, sysid, compid = cmd.reply_to
        mav_result = RESULT_TO_MAV[result] if cmd.kind != "none" else mavlink2.MAV_RESULT_UNSUPPORTED
        self.mav.command_ack_send(command, mav_result, 0, cmd.seq, sysid, compid)

    def publish(self, st: RobotState, counters: dict | None, now: float) -> None:
        t_ms = int(st.robot_time_s * 1000.0) & 0xFFFFFFFF
        x, y, z = robot_to_mav(st.ee_position_m)
        v = getattr(st, "ee_velocity_mps", None)
        vx, vy, vz = robot_to_mav(v) if v is not None else (0.0, 0.0, 0.0)
        self.mav.attitude_send(t_ms, 0.0, st.pitch_rad, -st.yaw_rad, 0.0, 0.0, 0.0)
        self.mav.local_position_ned_send(t_ms, x, y, z, vx, vy, vz)
        actuators = [0.0] * 32
        actuators[:7] = [float(a) for a in st.joint_positions_rad]
        actuators[7:14] = [float(a) for a in getattr(st, "joint_velocities_radps", np.zeros(7))]
        actuators[14:17] = [float(LIGHTS.index(st.light)), st.tone_hz, st.tone_db]
        self.mav.actuator_output_status_send(int(st.robot_time_s * 1e6), (1 << 17) - 1, actuators)
        if counters is not None:
            sat = lambda k: int(min(max(counters.get(k, 0), 0), 65535))  # noqa: E731
            self.mav.sys_status_send(0, 0, 0, 0, 0, -1, -1, 0, sat("integrity_errors"), sat("refused"),
                                     sat("watchdog_trips"), int(counters.get("rx_valid", 0)) % 65536, 0)
        system_status = (mavlink2.MAV_STATE_EMERGENCY if st.watchdog else
                         mavlink2.MAV_STATE_STANDBY if st.mode == "stopped" else mavlink2.MAV_STATE_ACTIVE)
        self.mav.heartbeat_send(mavlink2.MAV_TYPE_GENERIC, mavlink2.MAV_AUTOPILOT_GENERIC,
                                mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED,
                                pack_status(st.mode, st.watchdog, st.moving, st.at_target, st.last_result,
                                            st.last_command, st.last_seq), system_status)

    def close(self) -> None:
        try:
            self.stream.close()
        except OSError:
            pass


# ----------------------------------------------------------------------------------------------
# the controller

@dataclass(frozen=True)
class ControllerState(RobotState):
    """A RobotState with what the controller knows beyond the protocol's fields."""

    ee_velocity_mps: np.ndarray = field(default_factory=lambda: np.zeros(3))
    joint_velocities_radps: np.ndarray = field(default_factory=lambda: np.zeros(7))


class SawyerController:
    """The controller logic: commands, watchdog, arm motion, state reports. Never sleeps.

    ``step(dt_s)`` reads the port, applies the commands, checks the watchdog, moves the
    arm by ``dt_s`` and publishes a state report when one is due on ``clock``.
    """

    def __init__(self, port, clock=None, config: ControllerConfig | None = None, q0_rad=None):
        self.port = port
        self.clock = clock or time.monotonic
        self.config = config or ControllerConfig()
        warm_up()  # IK seeds: a real-time controller must not stall on its first target
        self.arm = SawyerArm(self.config.arm)
        if q0_rad is not None:
            self.arm.q_rad = np.asarray(q0_rad, dtype=float).copy()
        self.mode = "stopped"
        self.watchdog = False
        self.light, self.tone_hz, self.tone_db = "off", 0.0, 0.0
        self.last_command, self.last_seq, self.last_result = "none", 0, "none"
        self.counters: dict[str, int] = {"commands": 0, "refused": 0, "unreachable": 0, "watchdog_trips": 0,
                                         "states_sent": 0}
        now = self.clock()
        self.boot_t = now
        self._last_valid_rx = now
        self._next_state_t = now
        self._next_counters_t = now

    # -- commands ------------------------------------------------------------------------
    def handle(self, cmd: Command, now: float | None = None) -> str:
        """Apply one command (it proves the runtime alive); returns the result."""
        self._last_valid_rx = self.clock() if now is None else now
        if cmd.kind == "heartbeat":
            return "ok"
        result = self._execute(cmd)
        self.last_command = cmd.kind if cmd.kind in ("move", "retract", "stop", "resume", "alarm", "speed") else "none"
        self.last_seq, self.last_result = cmd.seq, result
        _count(self.counters, "commands")
        if result != "ok":
            _count(self.counters, "refused")
        if cmd.invalid:
            _count(self.counters, "malformed")  # refused before anything was executed
        if result == "unreachable":
            _count(self.counters, "unreachable")
        self.port.acknowledge(cmd, result, self.snapshot(self._last_valid_rx))
        return result

    def _execute(self, cmd: Command) -> str:
        if cmd.invalid:
            return "invalid"
        if self.config.refuse_commands:
            return "refused"
        try:
            if cmd.kind == "alarm":
                self.light, self.tone_hz, self.tone_db = check_alarm(cmd.light, cmd.tone_hz, cmd.tone_db)
                return "ok"
            if cmd.kind == "speed":  # a speed limit applies in every mode: slowing down is always allowed
                self.arm.set_speed_limit(check_speed(cmd.speed_mps))
                return "ok"
            if cmd.kind in ("move", "retract"):
                position, pitch, yaw = check_target(cmd.position_m, cmd.pitch_rad, cmd.yaw_rad)
        except ValueError:
            return "invalid"
        if cmd.kind == "stop":
            self.mode = "stopped"
            self.arm.clear_target()
            return "ok"
        if cmd.kind == "resume":
            self.mode, self.watchdog = "run", False
            self.arm.clear_target()
            return "ok"
        if self.watchdog or (cmd.kind == "move" and self.mode != "run"):
            return "refused"
        try:
            self.arm.set_target(position, pitch, yaw)
        except Unreachable:
            if cmd.kind == "retract":  # a retraction that cannot be done becomes a stop
                self.mode = "stopped"
                self.arm.clear_target()
            return "unreachable"
        if cmd.kind == "retract":
            self.mode = "retract"
        return "ok"

    # -- time ----------------------------------------------------------------------------
    def step(self, dt_s: float) -> None:
        now = self.clock()
        for cmd in self.port.receive(now):
            self.handle(cmd, now)
        if not self.watchdog and now - self._last_valid_rx > self.config.watchdog_s:
            self.watchdog = True
            self.mode = "stopped"
            self.arm.clear_target()
            _count(self.counters, "watchdog_trips")
        self.arm.step(dt_s)
        if now >= self._next_state_t - 1e-9:
            counters = None
            if now >= self._next_counters_t - 1e-9:
                counters = self.all_counters()
                self._next_counters_t = max(self._next_counters_t + self.config.counters_period_s, now)
            self.port.publish(self.snapshot(now), counters, now)
            _count(self.counters, "states_sent")
            period = 1.0 / self.config.state_rate_hz
            self._next_state_t = max(self._next_state_t + period, now + 0.5 * period)

    def snapshot(self, now: float | None = None) -> ControllerState:
        now = self.clock() if now is None else now
        pose = self.arm.pose()
        pitch, yaw = pose.pitch_yaw_rad
        vel = self.arm.ee_velocity_mps()
        return ControllerState(
            t_s=now, joint_positions_rad=self.arm.q_rad.copy(), ee_position_m=pose.position_m, pitch_rad=pitch,
            yaw_rad=yaw, ee_speed_mps=float(np.linalg.norm(vel)), mode=self.mode, watchdog=self.watchdog,
            moving=self.arm.moving, at_target=self.arm.at_goal, light=self.light, tone_hz=self.tone_hz,
            tone_db=self.tone_db, last_command=self.last_command, last_seq=self.last_seq,
            last_result=self.last_result, robot_time_s=now - self.boot_t, counters={},
            ee_velocity_mps=vel, joint_velocities_radps=self.arm.qd_radps.copy())

    def all_counters(self) -> dict:
        """The controller's and the port's counters together."""
        return {**self.port.counters, **self.counters}


# ----------------------------------------------------------------------------------------------
# in-process simulation

class SimClock:
    """A clock the simulation advances: ``clock()`` returns seconds, ``advance(dt_s)`` moves it."""

    def __init__(self, t0_s: float = 0.0):
        self.t_s = float(t0_s)

    def __call__(self) -> float:
        return self.t_s

    def advance(self, dt_s: float) -> float:
        self.t_s += dt_s
        return self.t_s


TEST_SIGNING_KEY = bytes(range(32))
"""The simulated pair's default MAVLink signing key (simulation only)."""

_sim_ids = itertools.count(1)


class LinkFaults:
    """Faults on the simulated link, both directions, like the CAN hub's: each CAN frame or
    MAVLink chunk is dropped with probability ``drop``, else one of its bytes is XOR-ed with
    probability ``corrupt``. Change the attributes at any time; ``stats`` counts what happened."""

    def __init__(self, drop: float = 0.0, corrupt: float = 0.0, seed: int = 0):
        self.drop, self.corrupt = drop, corrupt
        self._rng = np.random.default_rng(seed)
        self.stats = {"dropped": 0, "corrupted": 0}

    def apply(self, data: bytes) -> bytes | None:
        """The bytes as they arrive, or None when lost."""
        if self.drop > 0 and self._rng.random() < self.drop:
            self.stats["dropped"] += 1
            return None
        if data and self.corrupt > 0 and self._rng.random() < self.corrupt:
            out = bytearray(data)
            out[int(self._rng.integers(len(out)))] ^= int(self._rng.integers(1, 256))
            self.stats["corrupted"] += 1
            return bytes(out)
        return data


class _FaultyBus:
    """The controller's python-can bus seen through :class:`LinkFaults` (frames both ways)."""

    def __init__(self, bus: can.BusABC, faults: LinkFaults):
        self.bus, self.faults = bus, faults

    def send(self, msg: can.Message) -> None:
        data = self.faults.apply(bytes(msg.data))
        if data is not None:
            self.bus.send(can.Message(arbitration_id=msg.arbitration_id, data=data, is_extended_id=msg.is_extended_id))

    def recv(self, timeout: float | None = None) -> can.Message | None:
        while (msg := self.bus.recv(timeout)) is not None:
            data = self.faults.apply(bytes(msg.data))
            if data is not None:
                msg.data = bytearray(data)
                return msg
        return None

    def shutdown(self) -> None:
        self.bus.shutdown()


class _FaultyStream:
    """The controller's byte stream seen through :class:`LinkFaults` (chunks both ways)."""

    def __init__(self, stream, faults: LinkFaults):
        self.stream, self.faults = stream, faults

    def read(self) -> bytes:
        data = self.stream.read()
        return (self.faults.apply(data) or b"") if data else data

    def write(self, data: bytes) -> None:
        data = self.faults.apply(data)
        if data is not None:
            self.stream.write(data)

    def close(self) -> None:
        self.stream.close()


class SimulatedRobot:
    """A connected (controller, RobotLink) pair in one process on a simulated clock.

    ``link="can"``: both ends on python-can's ``virtual`` bus (a private channel).
    ``link="mavlink"``: both ends of a socket pair, MAVLink 2 signed with ``signing_key``.
    ``step(dt_s)`` advances the clock in controller periods; each period the controller
    reads the runtime's frames, moves the arm and reports, then the link polls (and
    sends its heartbeat when due). Commands the runtime sends through ``self.link`` are
    on the wire at once and take effect in the next period. ``self.faults``
    (:class:`LinkFaults`) drops or corrupts traffic in both directions.

        sim = SimulatedRobot("can")
        sim.link.resume(); sim.link.move_to((0.4, 0.3, 0.6), 0.0, 0.0)
        sim.step(2.0)                       # 2 s of simulated time
        sim.link.state.ee_position_m
    """

    def __init__(self, link: str = "can", clock: SimClock | None = None, signing_key: bytes | None = TEST_SIGNING_KEY,
                 controller_config: ControllerConfig | None = None, link_config: LinkConfig | None = None,
                 q0_rad=None, faults: LinkFaults | None = None):
        if link not in ("can", "mavlink"):
            raise ValueError(f"link must be 'can' or 'mavlink', got {link!r}")
        self.clock = clock or SimClock()
        self.kind = link
        self.faults = faults or LinkFaults()
        self._closers = []
        if link == "can":
            channel = f"sim-robot-{os.getpid()}-{next(_sim_ids)}"
            bus = can.Bus(interface="virtual", channel=channel)
            port = CanControllerPort(bus=_FaultyBus(bus, self.faults), config=controller_config)
            self._closers.append(bus.shutdown)
            self.link: RobotLink = open_link("can", interface="virtual", channel=channel, host=None,
                                             config=link_config, clock=self.clock)
        else:
            a, b = socket.socketpair()
            port = MavlinkControllerPort(_FaultyStream(SocketStream(a), self.faults), signing_key)
            self._closers.append(a.close)
            self.link = open_link("mavlink", stream=SocketStream(b), signing_key=signing_key,
                                  config=link_config, clock=self.clock)
        self.controller = SawyerController(port, clock=self.clock, config=controller_config, q0_rad=q0_rad)
        self.period_s = 1.0 / self.controller.config.state_rate_hz

    def step(self, dt_s: float, advance_clock: bool = True) -> RobotState | None:
        """Run ``dt_s`` seconds of simulated time; the link's newest state (or None).

        The clock is advanced here in controller periods; with ``advance_clock=False`` the
        caller has already moved its clock by ``dt_s`` and only the controller and the link run.
        """
        n = max(1, int(round(dt_s / self.period_s)))
        h = dt_s / n
        newest = None
        for _ in range(n):
            if advance_clock:
                self.clock.advance(h)
            self.controller.step(h)
            newest = self.link.poll() or newest
        return newest

    def close(self) -> None:
        self.link.close()
        for close in self._closers:
            close()

    def __enter__(self) -> "SimulatedRobot":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


# ----------------------------------------------------------------------------------------------
# the real-time process

def run_realtime(controller: SawyerController, duration_s: float | None = None,
                 stop: threading.Event | None = None) -> dict:
    """Step the controller at its state rate on absolute monotonic deadlines until duration/stop."""
    stop = stop or threading.Event()
    period = 1.0 / controller.config.state_rate_hz
    start = last = time.monotonic()
    deadline = start
    late_max = 0.0
    while not stop.is_set():
        now = time.monotonic()
        if duration_s is not None and now - start >= duration_s:
            break
        if now < deadline:
            stop.wait(deadline - now)
            continue
        late_max = max(late_max, now - deadline)
        controller.step(min(now - last, 5 * period))
        last = now
        deadline += period
        if deadline < now:  # fell behind: don't burst
            deadline = now + period
    return {"late_max_s": late_max, "duration_s": time.monotonic() - start}


def add_arguments(p: argparse.ArgumentParser) -> None:
    from edge_runtime.cli import hex_signing_key, positive_float, positive_int

    p.add_argument("--link", choices=("can", "mavlink"), required=True, help="CAN (robot_link.dbc) or MAVLink 2")
    add_bus_arguments(p, defaults={"interface": "socketcand", "host": "127.0.0.1", "channel": DEFAULT_CHANNEL},
                      channel_flag="--channel")
    p.add_argument("--pty", action="store_true", help="MAVLink: create a pseudo-terminal pair and print its path")
    p.add_argument("--serial", default=None, metavar="PATH", help="MAVLink: use this existing serial line")
    p.add_argument("--baud", type=positive_int, default=921600, help="MAVLink --serial: baud rate")
    p.add_argument("--signing-key", type=hex_signing_key("--signing-key"), default=None, help="MAVLink 2 signing key, 64 hex digits")
    p.add_argument("--runtime-sysid", type=int, choices=range(1, 256), default=None, metavar="ID",
                   help="MAVLink: take commands only from this system id (default: any)")
    p.add_argument("--rate-hz", type=positive_float, default=100.0, help="state reports per second (default 100)")
    p.add_argument("--watchdog-ms", type=positive_float, default=200.0, help="runtime silence that stops the arm")
    p.add_argument("--duration", type=positive_float, default=None, metavar="S", help="stop after S seconds")
    p.add_argument("--json", default=None, metavar="OUT", help="write the counters here at exit")
    p.add_argument("--refuse-commands", action="store_true",
                   help="answer every command refused and carry none out (an arm in its local/teach mode)")


def _open_port(args, config: ControllerConfig):
    """(port, endpoint line, cleanup) for the command line's link."""
    if args.link == "can":
        if args.can_interface == "socketcand" and args.can_port is None:
            raise ValueError("--link can with socketcand needs --can-port")
        factory = lambda: open_can_bus(args.can_interface, args.channel, args.can_host, args.can_port)  # noqa: E731
        try:
            bus = factory()
        except OSError as e:
            where = f"{args.can_host}:{args.can_port}"
            raise ValueError(f"cannot reach the CAN hub at {where}: {e.strerror or e}") from None
        port = CanControllerPort(bus=bus, bus_factory=factory, config=config)
        where = (f"socketcand:{args.can_host}:{args.can_port}:{args.channel}" if args.can_interface == "socketcand"
                 else f"{args.can_interface}:{args.channel}")
        return port, where, port.close
    if args.pty == bool(args.serial):
        raise ValueError("--link mavlink needs exactly one of --pty or --serial PATH")
    if args.pty:
        master, path = open_pty_pair()
        port = MavlinkControllerPort(FdStream(master), args.signing_key, runtime_sysid=args.runtime_sysid)
        return port, path, lambda: close_pty_pair(master)
    try:
        stream = SerialStream(args.serial, args.baud)
    except (OSError, ValueError) as e:
        raise ValueError(f"cannot open serial line {args.serial!r}: {e}") from None
    port = MavlinkControllerPort(stream, args.signing_key, runtime_sysid=args.runtime_sysid)
    return port, args.serial, port.close


def cmd(args) -> int:
    from edge_runtime.canbus.bus import CanLinkError

    config = ControllerConfig(watchdog_s=args.watchdog_ms / 1000.0, state_rate_hz=args.rate_hz,
                              refuse_commands=args.refuse_commands)
    try:
        port, where, cleanup = _open_port(args, config)
    except CanLinkError as e:
        raise ValueError(str(e)) from None
    controller = SawyerController(port, config=config)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    print(where, flush=True)
    print(f"sawyer: {args.link} link on {where}, state at {args.rate_hz:g} Hz, watchdog {args.watchdog_ms:g} ms"
          f"{', signed' if args.signing_key else ''}"
          f"{', refusing every command' if args.refuse_commands else '; booted stopped (send resume)'}",
          file=sys.stderr, flush=True)
    try:
        timing = run_realtime(controller, args.duration, stop)
    finally:
        cleanup()
    counters = controller.all_counters()
    summary = {"link": args.link, "endpoint": where, "counters": counters, "mode": controller.mode,
               "watchdog": controller.watchdog, "light": controller.light, "tone_hz": controller.tone_hz,
               "tone_db": controller.tone_db, **timing}
    if args.json:
        Path(args.json).write_text(json.dumps(summary, indent=1))
    print("sawyer: " + ", ".join(f"{k}={v}" for k, v in sorted(counters.items())), file=sys.stderr, flush=True)
    return 0


class SawyerProcess:
    """``python -m firmware_sim sawyer ...`` as a subprocess (for tests and demos).

        with SawyerProcess("mavlink", signing_key=KEY) as proc:
            link = open_link("mavlink", path=proc.endpoint, signing_key=KEY)
        proc.result   # the --json counters, after exit
    """

    def __init__(self, link: str, can_port: int | None = None, can_host: str = "127.0.0.1",
                 channel: str = DEFAULT_CHANNEL, signing_key: bytes | None = None, rate_hz: float = 100.0,
                 duration_s: float | None = None, json_path: str | os.PathLike | None = None, extra_args=()):
        self.args = [sys.executable, "-m", "firmware_sim", "sawyer", "--link", link, "--rate-hz", str(rate_hz)]
        if link == "can":
            self.args += ["--can-host", can_host, "--can-port", str(can_port), "--channel", channel]
        else:
            self.args += ["--pty"]
        if signing_key is not None:
            self.args += ["--signing-key", signing_key.hex()]
        if duration_s is not None:
            self.args += ["--duration", str(duration_s)]
        self.json_path = Path(json_path) if json_path is not None else None
        if self.json_path is not None:
            self.args += ["--json", str(self.json_path)]
        self.args += list(extra_args)
        self.proc: subprocess.Popen | None = None
        self.endpoint: str | None = None
        self.result: dict | None = None

    def start(self, timeout_s: float = 20.0) -> "SawyerProcess":
        root = Path(__file__).resolve().parents[2]
        env = dict(os.environ, PYTHONPATH=str(root) + os.pathsep + os.environ.get("PYTHONPATH", ""))
        self.proc = subprocess.Popen(self.args, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                                     cwd=str(root))
        line: list[str] = []
        reader = threading.Thread(target=lambda: line.append(self.proc.stdout.readline()), daemon=True)
        reader.start()
        reader.join(timeout_s)
        if not line or not line[0].strip():
            self.stop()
            raise RuntimeError(f"sawyer process did not start: {self.proc.stderr.read() if self.proc.stderr else ''}")
        self.endpoint = line[0].strip()
        return self

    def stop(self, timeout_s: float = 10.0) -> dict | None:
        if self.proc is not None and self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout_s)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        if self.json_path is not None and self.json_path.exists():
            self.result = json.loads(self.json_path.read_text())
        return self.result

    def __enter__(self) -> "SawyerProcess":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()


def main(argv: list[str] | None = None) -> int:
    from edge_runtime.cli import OneLineParser, run

    p = OneLineParser(prog="python -m firmware_sim sawyer", description="Simulated Sawyer controller.")
    add_arguments(p)
    args = p.parse_args(argv)
    return run(lambda: cmd(args), bad_input=BAD_INPUT)


BAD_INPUT = (ValueError,)

if __name__ == "__main__":
    sys.exit(main())
