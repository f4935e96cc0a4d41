"""The runtime as a systemd service (``Type=notify``, ``WatchdogSec=``): readiness and keep-alives.

systemd's notify protocol is one datagram per message to the unix socket named in
``$NOTIFY_SOCKET`` (a path, or an abstract name written with a leading '@'); ``READY=1``
says the service is up, ``WATCHDOG=1`` that it is still alive. With ``WatchdogSec=`` set,
systemd passes the interval as ``$WATCHDOG_USEC`` (and the pid it applies to as
``$WATCHDOG_PID``) and restarts a service that stays silent for longer (``Restart=on-failure``).

:func:`keepalive` is called where each loop iterates (the wearable's and the robot's drive
loops), never from a timer thread: a loop that hangs stops calling it, the keep-alives stop
and systemd restarts the process -- a thread that kept sending on its own would hide the hang.
The first call sends ``READY=1`` (the model is loaded and the bus open by then), later calls
send ``WATCHDOG=1`` once at least half the interval has passed since the last one, which is
the rate sd_watchdog_enabled(3) recommends. Outside systemd (no ``$NOTIFY_SOCKET``) a call
is one attribute test. The protocol is small enough that a dependency (python-systemd,
sdnotify) would cost more than it saves; it needs only :mod:`socket`.

A failed send is counted and logged, never raised: the safety loop keeps running, and the
missing keep-alives are the supervisor's to act on.
"""
from __future__ import annotations

import logging
import os
import socket
import time
from typing import Callable, Mapping

log = logging.getLogger(__name__)


class Notifier:
    """The notify side of one process. ``env`` is the process environment, ``clock`` a
    monotonic clock in seconds (injected by tests)."""

    def __init__(self, env: Mapping[str, str] | None = None, clock: Callable[[], float] = time.monotonic):
        env = os.environ if env is None else env
        self.clock = clock
        self.address = _address(env.get("NOTIFY_SOCKET", ""))
        self.keepalive_interval_s = _keepalive_interval_s(env)
        self.ready_sent = False
        self.keepalives_sent = 0
        self.send_errors = 0
        self._last_s = 0.0
        self._sock: socket.socket | None = None

    @property
    def enabled(self) -> bool:
        return self.address is not None

    def alive(self) -> None:
        """One iteration of a healthy loop: READY=1 the first time, then WATCHDOG=1 every half interval."""
        if self.address is None:
            return
        now_s = self.clock()
        if not self.ready_sent:
            self.ready_sent = self._send(b"READY=1")
            self._last_s = now_s
            if self.ready_sent:
                log.info("ready; watchdog keep-alive every %s", f"{self.keepalive_interval_s:g} s"
                         if self.keepalive_interval_s else "(no watchdog)", extra={"event": "ready"})
        elif self.keepalive_interval_s is not None and now_s - self._last_s >= self.keepalive_interval_s:
            if self._send(b"WATCHDOG=1"):
                self.keepalives_sent += 1
            self._last_s = now_s

    def _send(self, message: bytes) -> bool:
        try:
            if self._sock is None:
                self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM | socket.SOCK_CLOEXEC)
            self._sock.sendto(message, self.address)
            return True
        except OSError as e:
            self.send_errors += 1
            log.warning("notify %s to %r failed: %s (%d failures)", message.decode(), self.address, e,
                        self.send_errors, extra={"event": "notify_failed"})
            return False

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None


def _address(value: str) -> str | bytes | None:
    if not value:
        return None
    if value.startswith("@"):  # an abstract socket: a NUL byte, then the name
        return b"\0" + value[1:].encode()
    if value.startswith("/"):
        return value
    log.warning("NOTIFY_SOCKET=%r is neither a path nor an abstract name; not notifying", value,
                extra={"event": "notify_disabled"})
    return None


def _keepalive_interval_s(env: Mapping[str, str]) -> float | None:
    """Half of ``$WATCHDOG_USEC`` (s), or None when there is no watchdog for this process."""
    usec = env.get("WATCHDOG_USEC", "")
    pid = env.get("WATCHDOG_PID", "")
    if not usec or (pid and pid != str(os.getpid())):
        return None
    try:
        interval_us = int(usec)
    except ValueError:
        log.warning("WATCHDOG_USEC=%r is not an integer; no keep-alives", usec, extra={"event": "notify_disabled"})
        return None
    return interval_us / 2e6 if interval_us > 0 else None


_notifier: Notifier | None = None


def notifier() -> Notifier:
    """The process's notifier, made from the environment on first use."""
    global _notifier
    if _notifier is None:
        _notifier = Notifier()
    return _notifier


def keepalive() -> None:
    """Call once per iteration of a drive loop (see the module docstring)."""
    notifier().alive()


def reset(new: Notifier | None = None) -> Notifier | None:
    """Replace the process's notifier (None: made again from the environment on next use); returns the old one."""
    global _notifier
    old, _notifier = _notifier, new
    return old
