"""The runtime's end of the robot link: commands to a Sawyer controller, its state back.

``open_link(kind, **options)`` returns a :class:`RobotLink` for ``"can"``
(:mod:`edge_runtime.robot.link.can`) or ``"mavlink"`` (:mod:`edge_runtime.robot.link.mavlink`),
a registry like python-can's interfaces. Every link has the same API, :class:`LinkInterface`::

    link = open_link("can", interface="socketcand", host="127.0.0.1", port=29536, channel="vcan0")
    link.resume()                                  # the controller boots stopped
    seq = link.move_to((0.4, 0.2, 0.7), pitch_rad=0.0, yaw_rad=0.0)
    state = link.poll()                            # never blocks; also sends the heartbeat when due
    link.result(seq)                               # "ok", "unreachable", "refused", "invalid" or None

Positions, frames and what goes on the wire: :mod:`edge_runtime.robot.link.protocol`.

Timing uses an injectable ``clock`` (seconds, default ``time.monotonic``) and the link
never sleeps, so a simulation can run it faster than real time. ``poll()`` reads what
has arrived, sends a heartbeat every ``LinkConfig.heartbeat_period_s`` and checks the
link: no state for ``state_timeout_s`` (200 ms), or a transport error, makes
``link_ok`` false (``stats.outages`` +1); a broken transport is reopened with
exponential backoff (``stats.reconnects``). Nothing here raises on a link fault.
"""
from __future__ import annotations

import importlib
import math
import threading
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Callable, ClassVar

import numpy as np

from edge_runtime.robot.link.protocol import (
    LINK_ERRORS,
    REFUSALS,
    RESULTS,
    RUNTIME_STATES,
    RobotState,
    check_alarm,
    check_speed,
    check_state,
    check_target,
    next_seq,
)

Clock = Callable[[], float]

LINK_KINDS = {"can": "edge_runtime.robot.link.can:CanRobotLink",
              "mavlink": "edge_runtime.robot.link.mavlink:MavlinkRobotLink"}
"""The registry: link kind -> its RobotLink class, imported when first opened (like
python-can's interface table)."""


@dataclass
class LinkStats:
    frames_sent: int = 0
    frames_received: int = 0
    """Frames or packets received that passed the integrity check."""
    states: int = 0
    """Complete state reports received and used."""
    states_refused: int = 0
    """Complete state reports refused by ``protocol.check_state`` (a non-finite or impossible
    value); the link treats them as not received, so the state timeout still runs."""
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


def open_link(kind: str, **options) -> RobotLink:
    """The RobotLink of ``kind`` ("can", "mavlink", see LINK_KINDS), opened with ``options``."""
    try:
        module, name = LINK_KINDS[kind].split(":")
    except KeyError:
        raise ValueError(f"robot link kind must be one of {', '.join(sorted(LINK_KINDS))}, got {kind!r}") from None
    cls = getattr(importlib.import_module(module), name)
    return cls(**options)


class LinkInterface(ABC):
    """Everything a user of a robot link (:class:`edge_runtime.robot.loop.RobotLoop`) relies on.

    :class:`RobotLink` implements it over a transport; stand-ins (tests, benchmarks)
    implement it directly. Commands return the sequence number the controller's answer
    will carry (:meth:`result`); a command the link refuses to send raises ValueError.
    """

    last_error: str | None = None
    """Why the link is down, or last went down (None or "" when it never did)."""

    @abstractmethod
    def move_to(self, position_m, pitch_rad: float, yaw_rad: float) -> int:
        """Send a target (hand position m, tool pitch/yaw rad); only carried out in mode run."""

    @abstractmethod
    def retract(self, position_m, pitch_rad: float, yaw_rad: float) -> int:
        """Send a retraction target: accepted even while stopped; an unreachable one stops the arm."""

    @abstractmethod
    def stop(self) -> int:
        """Stop: the arm decelerates to rest and refuses moves until resume()."""

    @abstractmethod
    def resume(self) -> int:
        """Leave stop/retract and clear a latched watchdog; the arm holds where it is (mode run)."""

    @abstractmethod
    def set_alarm(self, light: str, tone_hz: float, tone_db: float) -> int:
        """Warning light ("off", "green", "yellow", "red") and tone (Hz, 0 = silent; dB)."""

    @abstractmethod
    def set_speed(self, limit_mps: float) -> int:
        """Speed override: the hand's speed limit (m/s) from now on, in every mode (speed and
        separation monitoring); 0 holds the arm still. Acknowledged like a motion command."""

    @abstractmethod
    def heartbeat(self) -> bool:
        """Send the runtime heartbeat now. True if it was handed to the transport."""

    @abstractmethod
    def set_runtime_state(self, state: str) -> None:
        """What the heartbeat reports about the runtime: one of RUNTIME_STATES."""

    @abstractmethod
    def poll(self) -> RobotState | None:
        """Read what has arrived (never blocks); the newest complete state, or None if none came."""

    @abstractmethod
    def result(self, seq: int) -> str | None:
        """The controller's answer to command ``seq`` ("ok", "unreachable", "refused", "invalid"), if known."""

    def refused(self, seq: int) -> bool:
        """Did the controller answer command ``seq`` unreachable, refused or invalid?"""
        return self.result(seq) in REFUSALS

    @property
    @abstractmethod
    def state(self) -> RobotState | None:
        """The latest complete state (check ``link_ok`` for its freshness)."""

    @property
    @abstractmethod
    def link_ok(self) -> bool:
        """States arrive in time and the transport is open."""

    @property
    @abstractmethod
    def heartbeats_itself(self) -> bool:
        """True when poll() sends the heartbeat when it is due; False: the caller calls heartbeat()."""


class RobotLink(LinkInterface):
    """The runtime's end of a robot link (template methods, like python-can's BusABC).

    Subclasses implement the transport: ``_open_transport``, ``_close_transport``, ``_send_target``,
    ``_send_mode``, ``_send_speed``, ``_send_alarm``, ``_send_heartbeat`` and ``_receive``. This class does
    the sequence numbers, input checks, heartbeat timing, link supervision, reconnection
    with backoff and the statistics. Thread-safe (one lock); it never sleeps.
    """

    kind: ClassVar[str] = ""
    """The LINK_KINDS name of the implementation."""

    def __init__(self, config: LinkConfig | None = None, clock: Clock | None = None, reopenable: bool = True):
        self.config = config or LinkConfig()
        self.clock: Clock = clock or time.monotonic
        self.stats = LinkStats()
        self.last_error: str | None = None
        self.last_refused_state: str | None = None
        """Why the last refused state report was refused (``stats.states_refused``)."""
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

    # -- LinkInterface ---------------------------------------------------------------------
    def move_to(self, position_m, pitch_rad: float, yaw_rad: float) -> int:
        return self._target(position_m, pitch_rad, yaw_rad, retract=False)

    def retract(self, position_m, pitch_rad: float, yaw_rad: float) -> int:
        return self._target(position_m, pitch_rad, yaw_rad, retract=True)

    def stop(self) -> int:
        return self._command(lambda seq: self._send_mode(seq, "stop"))

    def resume(self) -> int:
        return self._command(lambda seq: self._send_mode(seq, "resume"))

    def set_alarm(self, light: str, tone_hz: float, tone_db: float) -> int:
        light, tone_hz, tone_db = check_alarm(light, tone_hz, tone_db)
        return self._command(lambda seq: self._send_alarm(seq, light, tone_hz, tone_db))

    def set_speed(self, limit_mps: float) -> int:
        limit_mps = check_speed(limit_mps)
        return self._command(lambda seq: self._send_speed(seq, limit_mps))

    def heartbeat(self) -> bool:
        """Also sent by poll() when it is due (config.heartbeat_period_s)."""
        with self._lock:
            now = self.clock()
            ok = self._transmit(lambda: self._send_heartbeat(self._runtime_state, now - self._t0), now)
            self._last_hb_t = now
            self.stats.heartbeats += ok
            return ok

    def set_runtime_state(self, state: str) -> None:
        if state not in RUNTIME_STATES:
            raise ValueError(f"runtime state must be {', '.join(RUNTIME_STATES[:-1])} or {RUNTIME_STATES[-1]}, "
                             f"got {state!r}")
        self._runtime_state = state

    def poll(self) -> RobotState | None:
        with self._lock:
            now = self.clock()
            if not self._open:
                self._maybe_reconnect(now)
            newest = None
            if self._open:
                try:
                    for st in self._receive(now):
                        refused = check_state(st)
                        if refused is not None:  # a measurement the runtime cannot decide on
                            self.stats.states_refused += 1
                            self.last_refused_state = f"{refused}: outside its range or not finite"
                            continue
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
        return self._state

    @property
    def link_ok(self) -> bool:
        """A state arrived within state_timeout_s and the transport is open."""
        return self._link_ok

    @property
    def heartbeats_itself(self) -> bool:
        return self.config.heartbeat_period_s is not None

    def result(self, seq: int) -> str | None:
        return self._results.get(seq)

    # -- the link's own API -----------------------------------------------------------------
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

    # -- transport hooks (subclasses); a _send_* hook raises a LINK_ERRORS fault on a broken transport
    @abstractmethod
    def _open_transport(self) -> None:
        """Open the transport; raise a LINK_ERRORS fault (or ValueError) if it cannot be."""

    @abstractmethod
    def _close_transport(self) -> None:
        """Close the transport (a broken one may raise anything)."""

    @abstractmethod
    def _send_target(self, seq: int, position_m: np.ndarray, pitch_rad: float, yaw_rad: float, retract: bool) -> None:
        """A move (or with ``retract``, a retraction) target, already checked."""

    @abstractmethod
    def _send_mode(self, seq: int, command: str) -> None:
        """``command``: "stop" or "resume"."""

    @abstractmethod
    def _send_speed(self, seq: int, limit_mps: float) -> None:
        """Put a speed override on the transport."""

    @abstractmethod
    def _send_alarm(self, seq: int, light: str, tone_hz: float, tone_db: float) -> None:
        """Light and tone, already checked."""

    @abstractmethod
    def _send_heartbeat(self, state: str, uptime_s: float) -> None:
        """The runtime's liveness, its state (RUNTIME_STATES) and uptime (s)."""

    @abstractmethod
    def _receive(self, now: float) -> list[RobotState]:
        """Everything waiting, decoded; complete states in order. Raise a LINK_ERRORS fault if broken."""

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
