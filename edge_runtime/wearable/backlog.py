"""Alerts decided while the CAN bus is down: held, sent late, or reported lost; never dropped silently.

:class:`~edge_runtime.wearable.alerts.AlertPublisher` hands an alert whose frame the bus
did not take to an :class:`AlertBacklog`. When the bus is back (the heartbeat thread
reopened it, or the next alert went out) the backlog gives back what is still worth
sending, oldest first, each with the time it waited, so that its TimeSinceTrigger says
how old it really is. An alert that waited longer than ``max_age_s``, or that did not fit
(``max_alerts``), is counted lost. Both outcomes reach WEARABLE_STATUS (``degraded``) and
the summary.
"""
from __future__ import annotations

import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Any, Callable

MAX_PENDING_ALERTS = 8
"""Alerts held at most; on overflow the oldest is lost (a newer alert says more about the driver now)."""
MAX_ALERT_AGE_S = 5.0
"""An alert older than this is reported lost instead of sent: a distraction seconds ago is history, not a warning."""


@dataclass(frozen=True)
class LateAlert:
    """An alert sent after waiting ``waited_s`` for the bus: the decision's fields, with the wait
    added to ``compute_us`` so that the frame's TimeSinceTrigger counts it."""

    alert: Any
    waited_s: float

    def __getattr__(self, name: str) -> Any:
        if name == "compute_us":
            return getattr(self.alert, "compute_us", 0.0) + self.waited_s * 1e6
        return getattr(self.alert, name)


@dataclass(frozen=True)
class BacklogCounts:
    held: int = 0
    """Alerts the bus did not take at first."""
    sent_late: int = 0
    lost: int = 0
    """Too old when the bus came back, pushed out by newer ones, or still held at the end."""
    pending: int = 0


class AlertBacklog:
    """A bounded, thread-safe queue of alerts waiting for the bus (see the module docstring)."""

    def __init__(self, max_alerts: int = MAX_PENDING_ALERTS, max_age_s: float = MAX_ALERT_AGE_S,
                 clock: Callable[[], float] = time.monotonic):
        self.max_alerts, self.max_age_s, self.clock = max_alerts, max_age_s, clock
        self._queue: deque[tuple[Any, float]] = deque()
        self._lock = threading.Lock()
        self._held = self._sent_late = self._lost = 0

    def hold(self, alert: Any, since_s: float | None = None) -> None:
        """Keep ``alert`` (waiting since ``since_s``, default now) until the bus is back."""
        with self._lock:
            if since_s is None:
                self._held += 1
                since_s = self.clock()
            self._queue.append((alert, since_s))
            while len(self._queue) > self.max_alerts:
                self._queue.popleft()
                self._lost += 1

    def take(self) -> tuple[list[tuple[LateAlert, float]], int]:
        """What is still worth sending (each with the time it has waited since), oldest first, and
        how many were too old (counted lost). The caller sends them and calls :meth:`sent` or
        :meth:`hold` (with the same ``since_s``) for each."""
        now = self.clock()
        with self._lock:
            items, self._queue = list(self._queue), deque()
            fresh = [(LateAlert(a, now - t), t) for a, t in items if now - t <= self.max_age_s]
            too_old = len(items) - len(fresh)
            self._lost += too_old
        return fresh, too_old

    def sent(self) -> None:
        with self._lock:
            self._sent_late += 1

    def abandon(self) -> int:
        """At the end: what is still held is lost; returns how many."""
        with self._lock:
            n, self._queue = len(self._queue), deque()
            self._lost += n
        return n

    def __len__(self) -> int:
        with self._lock:
            return len(self._queue)

    def counts(self) -> BacklogCounts:
        with self._lock:
            return BacklogCounts(self._held, self._sent_late, self._lost, len(self._queue))
