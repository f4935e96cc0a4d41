"""Vehicle CAN link: DISTRACTION_ALERT and the WEARABLE_STATUS heartbeat (DESIGN.md section 6).

Frames are laid out by ``assets/vehicle_alerts.dbc`` only: signals are encoded and
decoded with cantools, then protected with AUTOSAR E2E Profile 1 (``e2e`` package):
CRC-8 in byte 0, alive counter 0..14 in the low nibble of byte 1, data ID from the
DBC's ``E2E_DataID`` message attribute (mode BOTH).

``AlertPublisher`` sends one DISTRACTION_ALERT per alerted decision (use
``publisher.on_decision`` as the WearableLoop callback) and a heartbeat from a
background thread. A bus error never stops it: the error is counted and the
next frame is tried again (with ``bus_factory`` the bus is reopened).
"""
from __future__ import annotations

import logging
import threading
import time
from pathlib import Path
from typing import Any, Callable, Mapping

import can

from edge_runtime.canbus.dbc import load_dbc
from edge_runtime.canbus.e2e import E2EProtector
from edge_runtime.core.manifest import ASSETS_DIR

log = logging.getLogger(__name__)

DBC_PATH = ASSETS_DIR / "vehicle_alerts.dbc"
ALERT = "DISTRACTION_ALERT"
STATUS = "WEARABLE_STATUS"
NO_CLASS = "None"


def load_vehicle_dbc():
    """The vehicle DBC the box ships (DISTRACTION_ALERT, WEARABLE_STATUS)."""
    return load_dbc(DBC_PATH)


class AlertEncoder:
    """Encodes decisions and status with cantools from the DBC, then E2E-protects them.

    One alive counter per message; ``encode_*`` returns a ``can.Message``.
    """

    def __init__(self, db=None):
        self.db = db if db is not None else load_vehicle_dbc()
        self.alert_msg = self.db.get_message_by_name(ALERT)
        self.status_msg = self.db.get_message_by_name(STATUS)
        self._e2e = E2EProtector()
        self._alert_seq = 0
        self._lock = threading.Lock()

    def _protect(self, message, signals: dict) -> can.Message:
        return self._e2e.protect(message, signals)

    def encode_alert(self, decision: Any) -> can.Message:
        """A DISTRACTION_ALERT for a decision (t_trigger_s, t_alert_s, label, confidence, status, compute_us)."""
        label = decision.label
        choices = {str(v) for v in self.alert_msg.get_signal_by_name("Class").choices.values()}
        cls = label if label in choices else NO_CLASS
        status = "uncertain" if getattr(decision, "status", "alert") == "uncertain" else "alert"
        since_ms = (decision.t_alert_s - decision.t_trigger_s) * 1000.0 + getattr(decision, "compute_us", 0.0) / 1000.0
        with self._lock:
            seq = self._alert_seq
            self._alert_seq = (seq + 1) & 0xFFFF
        return self._protect(self.alert_msg, {
            "Status": status,
            "Class": cls,
            "Confidence": min(max(float(decision.confidence), 0.0), 1.0),
            "TimeSinceTrigger": int(min(max(since_ms + 0.5, 0), 65535)),
            "AlertSeq": seq,
        })

    def encode_status(self, state: str = "running", sensor_health: str = "ok", dropped_samples: int = 0,
                      model_version: int = 0, uptime_s: float = 0.0) -> can.Message:
        return self._protect(self.status_msg, {
            "State": state,
            "SensorHealth": sensor_health,
            "DroppedSamples": int(min(max(dropped_samples, 0), 65535)),
            "ModelVersion": int(min(max(model_version, 0), 255)),
            "Uptime_s": int(min(max(uptime_s, 0), 65535)),
        })

    def decode(self, msg: can.Message) -> dict:
        return self.db.decode_message(msg.arbitration_id, bytes(msg.data), decode_choices=True)


class AlertPublisher:
    """Publishes alerts and a periodic WEARABLE_STATUS heartbeat on a python-can bus."""

    def __init__(self, bus: can.BusABC | None, encoder: AlertEncoder | None = None, heartbeat_period_s: float = 0.1,
                 log_path: str | Path | None = None, bus_factory: Callable[[], can.BusABC] | None = None,
                 status_provider: Callable[[], Mapping[str, Any]] | None = None):
        if heartbeat_period_s <= 0:
            raise ValueError("heartbeat_period_s must be > 0")
        self.bus = bus
        self.encoder = encoder or AlertEncoder()
        self.period = heartbeat_period_s
        self.bus_factory = bus_factory
        self.status_provider = status_provider
        self.status: dict[str, Any] = {"state": "starting", "sensor_health": "ok", "dropped_samples": 0, "model_version": 0}
        self.frames_sent = 0
        self.alerts_sent = 0
        self.heartbeats_sent = 0
        self.send_errors = 0
        self.reconnects = 0
        self.last_error: str | None = None
        self._t0 = time.monotonic()
        self._send_lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._logger = can.Logger(str(log_path)) if log_path else None

    # -- status -----------------------------------------------------------
    def set_status(self, **fields: Any) -> None:
        """Update heartbeat fields: state, sensor_health, dropped_samples, model_version."""
        unknown = set(fields) - set(self.status)
        if unknown:
            raise KeyError(f"unknown status field(s): {sorted(unknown)}")
        self.status.update(fields)

    def _status_fields(self) -> dict:
        fields = dict(self.status)
        if self.status_provider is not None:
            try:
                fields.update(self.status_provider())
            except Exception as exc:  # noqa: BLE001 - a bad provider must not stop the heartbeat
                fields["state"] = "fault"
                self.last_error = f"status provider: {exc}"
        fields["uptime_s"] = time.monotonic() - self._t0
        return fields

    # -- sending ----------------------------------------------------------
    def send(self, msg: can.Message) -> bool:
        """Send one frame; True if the bus took it. Errors are counted, never raised."""
        with self._send_lock:
            if self.bus is None:
                self.send_errors += 1
                self.last_error = "no bus"
                return False
            msg.timestamp = time.time()
            msg.is_rx = False
            try:
                self.bus.send(msg)
            except Exception as exc:  # noqa: BLE001 - count it and try again on the next frame
                self.send_errors += 1
                self.last_error = f"{type(exc).__name__}: {exc}"
                log.warning("CAN send failed: %s", self.last_error)
                if self.bus_factory is not None:
                    self._drop_bus()
                return False
            self.frames_sent += 1
            if self._logger is not None:
                self._logger(msg)
            return True

    def _drop_bus(self) -> None:
        bus, self.bus = self.bus, None
        try:
            bus.shutdown()
        except Exception:  # noqa: BLE001
            pass

    def _reconnect(self) -> None:
        try:
            bus = self.bus_factory()
        except Exception as exc:  # noqa: BLE001
            self.last_error = f"reconnect: {exc}"
            return
        with self._send_lock:
            self.bus = bus
        self.reconnects += 1

    def on_decision(self, decision: Any) -> bool:
        """WearableLoop callback: sends a DISTRACTION_ALERT if the decision is alerted."""
        if not getattr(decision, "alerted", False):
            return False
        ok = self.send(self.encoder.encode_alert(decision))
        self.alerts_sent += ok
        return ok

    def send_heartbeat(self) -> bool:
        ok = self.send(self.encoder.encode_status(**self._status_fields()))
        self.heartbeats_sent += ok
        return ok

    # -- heartbeat thread -------------------------------------------------
    def _run(self) -> None:
        next_t = time.monotonic()
        while not self._stop.is_set():
            if self.bus is None and self.bus_factory is not None:
                self._reconnect()
            self.send_heartbeat()
            next_t += self.period
            now = time.monotonic()
            if next_t < now:  # fell behind (e.g. a slow reconnect): don't burst
                next_t = now + self.period
            self._stop.wait(next_t - now if next_t > now else self.period)

    def start(self) -> "AlertPublisher":
        if self._thread is None:
            self._stop.clear()
            self._thread = threading.Thread(target=self._run, name="can-heartbeat", daemon=True)
            self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join(timeout=max(2.0, 3 * self.period))
            self._thread = None
        if self._logger is not None:
            self._logger.stop()
            self._logger = None

    def close(self) -> None:
        """Stop and shut the bus down."""
        self.stop()
        if self.bus is not None:
            self._drop_bus()

    def __enter__(self) -> "AlertPublisher":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()

    def summary(self) -> dict:
        return {"frames_sent": self.frames_sent, "alerts_sent": self.alerts_sent,
                "heartbeats_sent": self.heartbeats_sent, "send_errors": self.send_errors,
                "reconnects": self.reconnects}
