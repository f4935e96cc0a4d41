"""Vehicle CAN link: DISTRACTION_ALERT, and WEARABLE_STATUS with the health behind it (docs/design.md section 6).

Frames are laid out by ``assets/vehicle_alerts.dbc`` only: signals are encoded and
decoded with cantools, then protected with AUTOSAR E2E Profile 1 (``e2e`` package):
CRC-8 in byte 0, alive counter 0..14 in the low nibble of byte 1, data ID from the
DBC's ``E2E_DataID`` message attribute (mode BOTH).

:class:`WearableStatus` is the one place for what the heartbeat says: the sensor state
and the health counters (samples, non-finite samples, detector restarts, the live
source's saturated and dropped samples, alert latencies). The loop and the command
write them while the heartbeat thread reads them, so they live behind one lock.

:class:`AlertPublisher` sends each alert it is handed (:meth:`AlertPublisher.publish_alert`:
the loop hands it a would-alert verdict and learns the AlertSeq its frames carry, or that
no frame went out) as a DISTRACTION_ALERT followed by the copies the DBC asks for
(``GenMsgNrOfRepetition`` frames ``GenMsgCycleTimeFast`` ms apart, same AlertSeq), so a
listener that loses a frame still gets the alert a copy later and counts it once. It also
sends the WEARABLE_STATUS of its :class:`WearableStatus` every heartbeat period. A bus
error never stops it: the error is counted and the next frame is tried again (with
``bus_factory`` the bus is reopened).

Two clocks (:class:`Clock`). A live source runs on the wall clock: a background thread
sends the heartbeats and the copies when they are due, and frames are stamped with
``time.time()``. A replay runs on the data clock: nothing happens between samples, the
command moves the clock with :meth:`AlertPublisher.advance_to` as the recording is read,
and every frame is sent and stamped (``--can-log``) at the recording's time at which it
would have been sent: an alert at its decision's ``t_alert_s``, its copies after it, a
heartbeat every ``heartbeat_period_s`` of data. ``python -m can.player`` then replays
the log at the data's pace.
"""
from __future__ import annotations

import enum
import heapq
import itertools
import json
import logging
import threading
import time
from dataclasses import dataclass
from functools import cached_property
from pathlib import Path
from typing import TYPE_CHECKING, Any, Callable, NamedTuple

from edge_runtime import config
from edge_runtime.canbus.bus import BUS_INTERFACES, CanLinkError, reaches_anyone
from edge_runtime.canbus.dbc import load_dbc
from edge_runtime.canbus.e2e import E2EProtector
from edge_runtime.core.manifest import ASSETS_DIR, sha256_file
from edge_runtime.errors import ModelIntegrityError
from edge_runtime.wearable.backlog import AlertBacklog

if TYPE_CHECKING:
    import can

log = logging.getLogger(__name__)

DBC_PATH = ASSETS_DIR / "vehicle_alerts.dbc"
DBC_SCHEDULE_PATH = ASSETS_DIR / "vehicle_alerts.schedule.json"
"""What the publisher needs of :data:`DBC_PATH` before it encodes a frame (:class:`FrameSchedule`), with the
DBC's sha256: written by :func:`write_frame_schedule` (``python -m export schedule``, ``export assets``), held to the
DBC when the DBC is parsed (:meth:`FrameSchedule.check_against`), by ``export bundle`` and by tests/wearable/test_alerts.py."""
SCHEDULE_HINT = "write it from the DBC with python -m export schedule"
ALERT = "DISTRACTION_ALERT"
STATUS = "WEARABLE_STATUS"
NO_CLASS = "None"
DROPPED_SAMPLES_MAX = 65535
"""WEARABLE_STATUS DroppedSamples is 16 bits: the count saturates there."""


def load_vehicle_dbc():
    """The vehicle DBC the box ships (DISTRACTION_ALERT, WEARABLE_STATUS)."""
    return load_dbc(DBC_PATH)


@config.section("can")
@dataclass(frozen=True)
class CanParams:
    """The vehicle CAN bus the alerts and the WEARABLE_STATUS heartbeat go out on."""

    interface: str = config.setting("virtual", config.one_of(*BUS_INTERFACES))
    """python-can interface: virtual (in-process), socketcand (the simulated hub), socketcan, slcan, ..."""
    channel: str = "vcan0"
    bitrate: int = config.setting(500_000, ("a positive integer", lambda v: v > 0))
    host: str = "127.0.0.1"
    """socketcand only: the hub's address."""
    port: int = config.setting(29536, config.TCP_PORT)
    """socketcand only: the hub's TCP port."""
    heartbeat_period_s: float = config.setting(0.1, config.within(0.01, 0.1, "s"))
    """WEARABLE_STATUS period (s): 10 Hz. At most 0.1 s: vehicle_alerts.dbc promises a heartbeat
    every 100 ms and a listener treats 300 ms without one as the wearable gone."""


@dataclass(frozen=True)
class HealthCounts:
    """The health counters at one moment (a snapshot of :class:`WearableStatus`)."""

    sensor: str = "ok"
    """The live source's state: "ok", "silent" (no sample for the silence timeout) or "disconnected"."""
    samples: int = 0
    """Samples fed to the loop."""
    non_finite: int = 0
    """Samples with a NaN or infinite axis (never classified)."""
    detector_restarts: int = 0
    """Gaps and runs of non-finite samples: each restarts the detector."""
    saturated: int = 0
    """Samples of the live source with an axis at the sensor's range limit."""
    source_dropped: int = 0
    """Samples missing from the live source's stream (timestamp gaps)."""
    alerts_undelivered: int = 0
    """Alerts the bus did not take when they were made: sent late or lost (:mod:`~edge_runtime.wearable.backlog`)."""

    @property
    def dropped_samples(self) -> int:
        """WEARABLE_STATUS DroppedSamples: samples the classifier never saw, saturating at 16 bits."""
        return min(self.non_finite + self.source_dropped, DROPPED_SAMPLES_MAX)


RIDE_LATE_S = 0.1
"""Once the loop's thread sends the heartbeats (:meth:`AlertPublisher.beat_if_due`), the heartbeat thread
sends one only when the loop left it this long overdue (a loop stuck in a call): a listener still hears one
at least every heartbeat period + this (200 ms at 10 Hz), within the 300 ms after which it treats the
wearable as gone (vehicle_alerts.dbc)."""
UNDELIVERED_HEARTBEATS = 5
"""Heartbeats that say degraded after alerts were sent late or lost: 0.5 s at 10 Hz, longer than
the 300 ms a receiver waits for a heartbeat (docs/integrator.md), so a receiver either sees one
of them or has declared the wearable unavailable meanwhile."""


def heartbeat_state(now: HealthCounts, before: HealthCounts) -> tuple[str, str]:
    """(State, SensorHealth) of WEARABLE_STATUS from the counters ``now`` and at the previous
    heartbeat: a counter that grew since then marks the sensor degraded for this period."""
    if now.sensor != "ok":
        return "sensor_silent", "silent"
    if now.samples == 0:
        return "starting", "ok"  # no sample yet: nothing to vouch for
    if now.non_finite > before.non_finite:
        return "degraded", "nan_samples"
    if now.saturated > before.saturated:
        return "degraded", "saturated"
    if now.detector_restarts > before.detector_restarts:
        return "degraded", "gaps"
    if now.alerts_undelivered > before.alerts_undelivered:
        return "degraded", "ok"  # the sensor is fine; alerts were late or lost while the bus was down
    return "running", "ok"


class WearableStatus:
    """WEARABLE_STATUS content and the health counters it is made from, behind one lock.

    Written by the loop (samples, non-finite samples, detector restarts, alert latencies)
    and the command (the live source's state and counters); read by the heartbeat thread
    (:meth:`heartbeat`) and the summary (:meth:`counts`, :meth:`alert_latencies_ms`)."""

    def __init__(self, model_version: int = 0):
        self.model_version = model_version  # the classifier in use (ModelVersion, 8 bits)
        self._t0 = time.monotonic()
        self._lock = threading.Lock()
        self._sensor = "ok"
        self._samples = self._non_finite = self._restarts = self._saturated = self._source_dropped = 0
        self._alerts_undelivered = 0
        self._undelivered_beats = 0  # heartbeats still to say degraded for undelivered alerts
        self._latencies_ms: list[float] = []
        self._reported = HealthCounts()  # as of the previous heartbeat

    # -- writers ----------------------------------------------------------
    def count_samples(self, n: int, non_finite: int = 0) -> None:
        with self._lock:
            self._samples += n
            self._non_finite += non_finite

    def count_detector_restart(self) -> None:
        with self._lock:
            self._restarts += 1

    def set_sensor(self, state: str) -> bool:
        """The live source's state; True if it changed."""
        with self._lock:
            changed, self._sensor = state != self._sensor, state
        return changed

    def set_source_counts(self, saturated: int, dropped: int) -> None:
        """The live source's own running totals of saturated and dropped samples."""
        with self._lock:
            self._saturated, self._source_dropped = saturated, dropped

    def set_alerts_undelivered(self, n: int) -> None:
        """The publisher's running total of alerts sent late or lost while the bus was down."""
        with self._lock:
            self._alerts_undelivered = n

    def add_alert_latency(self, latency_ms: float) -> None:
        """Arrival of a capture's last sample -> its DISTRACTION_ALERT handed to the bus."""
        with self._lock:
            self._latencies_ms.append(latency_ms)

    # -- readers ----------------------------------------------------------
    def counts(self) -> HealthCounts:
        with self._lock:
            return self._counts()

    def _counts(self) -> HealthCounts:
        return HealthCounts(self._sensor, self._samples, self._non_finite, self._restarts, self._saturated,
                            self._source_dropped, self._alerts_undelivered)

    def skip_heartbeats(self, n: int) -> None:
        """What ``n`` calls of :meth:`heartbeat` in a row leave behind, without making their
        signals: the baseline is now, and the degraded period for undelivered alerts is used up."""
        with self._lock:
            now, before = self._counts(), self._reported
            self._reported = now
            if now.alerts_undelivered > before.alerts_undelivered:
                self._undelivered_beats = UNDELIVERED_HEARTBEATS
            self._undelivered_beats = max(0, self._undelivered_beats - n)

    def alert_latencies_ms(self) -> list[float]:
        with self._lock:
            return list(self._latencies_ms)

    def heartbeat(self, uptime_s: float | None = None) -> dict[str, Any]:
        """The WEARABLE_STATUS signals now (:meth:`AlertEncoder.encode_status`'s arguments);
        what is reported becomes the baseline of the next heartbeat. ``uptime_s``: on the data
        clock, the data time since the first sample (default: wall time since this object).

        Alerts the bus did not take keep State degraded for ``UNDELIVERED_HEARTBEATS``
        heartbeats, not one: they are reported right after the bus comes back, when a receiver
        may itself still be reconnecting, and a single frame is easily missed."""
        with self._lock:
            now, before = self._counts(), self._reported
            self._reported = now
            if now.alerts_undelivered > before.alerts_undelivered:
                self._undelivered_beats = UNDELIVERED_HEARTBEATS
            held, self._undelivered_beats = self._undelivered_beats > 0, max(0, self._undelivered_beats - 1)
        state, health = heartbeat_state(now, before)
        if held and state == "running":
            state = "degraded"  # the sensor is fine; alerts were late or lost while the bus was down
        return {"state": state, "sensor_health": health, "dropped_samples": now.dropped_samples,
                "model_version": self.model_version,
                "uptime_s": time.monotonic() - self._t0 if uptime_s is None else uptime_s}


def _message_attribute(message, name: str) -> int:
    attr = message.dbc.attributes.get(name) if message.dbc is not None else None
    return int(attr.value) if attr is not None else 0


@dataclass(frozen=True)
class Repetition:
    """How each alert is repeated, from the DBC's DISTRACTION_ALERT attributes."""

    copies: int
    """Frames after the first (``GenMsgNrOfRepetition``)."""
    period_s: float
    """Time between two frames of one alert (``GenMsgCycleTimeFast``, ms in the DBC)."""

    @classmethod
    def of(cls, message) -> "Repetition":
        return cls(_message_attribute(message, "GenMsgNrOfRepetition"),
                   _message_attribute(message, "GenMsgCycleTimeFast") / 1000.0)

    def delays_s(self) -> list[float]:
        """When the copies go out, after the first frame."""
        return [k * self.period_s for k in range(1, self.copies + 1)]


@dataclass(frozen=True)
class FrameSchedule:
    """What the publisher needs of the vehicle DBC before it encodes a frame: the two messages' frame IDs (their
    alive counters) and the alert's repetition (when its copies are due).

    Why apart from the DBC: a replay whose frames nobody hears encodes none (:meth:`AlertPublisher._heard`), and
    parsing the DBC means importing cantools, and with it python-can: about a tenth of a day's replay. The shipped
    DBC's schedule is kept beside it with the DBC's sha256 (:data:`DBC_SCHEDULE_PATH`); a DBC whose sha256 differs,
    or a schedule file that cannot be read, is parsed at once, as before. The DBC is the single source of truth:
    when it is parsed, a kept schedule that differs from it is a ModelIntegrityError (:meth:`AlertEncoder.db`).
    ``python -m export schedule`` (and ``export assets``) writes it from the DBC."""

    dbc_sha256: str
    alert_frame_id: int
    status_frame_id: int
    repetition: Repetition

    @classmethod
    def of(cls, db, dbc_sha256: str = "") -> "FrameSchedule":
        alert = db.get_message_by_name(ALERT)
        return cls(dbc_sha256, int(alert.frame_id), int(db.get_message_by_name(STATUS).frame_id), Repetition.of(alert))

    def to_json(self) -> dict:
        return {"dbc_sha256": self.dbc_sha256, "alert_frame_id": self.alert_frame_id,
                "status_frame_id": self.status_frame_id, "repetition_copies": self.repetition.copies,
                "repetition_period_s": self.repetition.period_s}

    @classmethod
    def kept(cls, dbc_path: Path = DBC_PATH, path: Path = DBC_SCHEDULE_PATH) -> "FrameSchedule | None":
        """The schedule kept at ``path`` if it is ``dbc_path``'s (the same sha256), else None (parse the DBC)."""
        try:
            d = json.loads(path.read_text(encoding="utf-8"))
            kept = cls(str(d["dbc_sha256"]), int(d["alert_frame_id"]), int(d["status_frame_id"]),
                       Repetition(int(d["repetition_copies"]), float(d["repetition_period_s"])))
            return kept if kept.dbc_sha256 == sha256_file(dbc_path) else None
        except (OSError, ValueError, KeyError, TypeError, AttributeError):  # none, unreadable or another layout:
            return None  # parse the DBC at start

    def check_against(self, db, where: Path = DBC_SCHEDULE_PATH) -> None:
        """ModelIntegrityError (one line) unless this kept schedule is what the parsed DBC ``db`` gives."""
        parsed = FrameSchedule.of(db, self.dbc_sha256)
        if parsed != self:
            raise ModelIntegrityError(f"{where}: differs from {DBC_PATH.name} ({self.to_json()} against "
                                      f"{parsed.to_json()}); {SCHEDULE_HINT}")


def frame_schedule_text(dbc_path: Path = DBC_PATH) -> str:
    """The text :data:`DBC_SCHEDULE_PATH` must hold for the DBC at ``dbc_path``."""
    schedule = FrameSchedule.of(load_dbc(dbc_path), sha256_file(dbc_path))
    return json.dumps(schedule.to_json(), indent=1, sort_keys=True) + "\n"


def write_frame_schedule(dbc_path: Path = DBC_PATH, path: Path = DBC_SCHEDULE_PATH) -> Path:
    """Keep ``dbc_path``'s :class:`FrameSchedule` at ``path`` (after a change of the DBC)."""
    path.write_text(frame_schedule_text(dbc_path), encoding="utf-8")
    return path


def check_frame_schedule(dbc_path: Path = DBC_PATH, path: Path = DBC_SCHEDULE_PATH) -> None:
    """ModelIntegrityError (one line) unless ``path`` holds ``dbc_path``'s :class:`FrameSchedule` (what
    ``export bundle`` checks: a schedule that is not the DBC's never ships)."""
    kept = FrameSchedule.kept(dbc_path, path)
    if kept is None:
        raise ModelIntegrityError(f"{path}: missing, unreadable or not {dbc_path.name}'s (another sha256); "
                                  f"{SCHEDULE_HINT}")
    kept.check_against(load_dbc(dbc_path), path)


class AlertEncoder:
    """Encodes decisions and status with cantools from the DBC, then E2E-protects them.

    One alive counter per message; ``encode_*`` returns a ``can.Message``. Without ``db`` the shipped DBC is
    parsed at once, or with ``lazy`` (a replay, whose frames nobody may hear) when a frame is first encoded or
    decoded: until then its kept :class:`FrameSchedule` serves (parsed at once if there is none for this DBC),
    and the parse holds the kept schedule to the DBC."""

    def __init__(self, db=None, lazy: bool = False):
        self._db = db
        self._db_lock = threading.Lock()
        self._kept = FrameSchedule.kept(DBC_PATH, DBC_SCHEDULE_PATH) if db is None and lazy else None
        """The kept schedule in use until the DBC is parsed (then checked against it)."""
        schedule = self._kept if self._kept is not None else FrameSchedule.of(self.db)
        self._alert_id, self._status_id = schedule.alert_frame_id, schedule.status_frame_id
        self.repetition = schedule.repetition
        self._e2e = E2EProtector()
        self._alert_seq = 0
        self._lock = threading.Lock()

    @property
    def db(self):
        with self._db_lock:  # the heartbeat thread and the loop may encode the first frames at once
            if self._db is None:
                db = load_vehicle_dbc()
                if self._kept is not None:  # frames were scheduled and counted by it: it must be the DBC's
                    self._kept.check_against(db, DBC_SCHEDULE_PATH)
                self._db = db
            return self._db

    @cached_property
    def alert_msg(self):
        return self.db.get_message_by_name(ALERT)

    @cached_property
    def status_msg(self):
        return self.db.get_message_by_name(STATUS)

    @cached_property
    def _classes(self) -> set[str]:
        return {str(v) for v in self.alert_msg.get_signal_by_name("Class").choices.values()}

    @cached_property
    def _statuses(self) -> set[str]:
        return {str(v) for v in self.alert_msg.get_signal_by_name("Status").choices.values()}

    def _protect(self, message, signals: dict) -> can.Message:
        return self._e2e.protect(message, signals)

    def next_alert_seq(self) -> int:
        """A new AlertSeq (16 bits, wrapping): one per alert, shared by all its frames."""
        with self._lock:
            seq = self._alert_seq
            self._alert_seq = (seq + 1) & 0xFFFF
        return seq

    def encode_alert(self, decision: Any, seq: int | None = None, delay_s: float = 0.0) -> can.Message:
        """A DISTRACTION_ALERT for a decision (t_trigger_s, t_alert_s, label, confidence, status, compute_us):
        the first frame of a new alert, or with ``seq`` an update of that alert or the copy ``delay_s``
        after the first frame. Status is the decision's (preliminary, confirmed, revised, withdrawn,
        uncertain) when the DBC lists it, else alert."""
        label = decision.label
        cls = label if label in self._classes else NO_CLASS
        status = getattr(decision, "status", "alert")
        status = status if status in self._statuses else "alert"  # e.g. a held verdict sent late
        since_ms = ((decision.t_alert_s - decision.t_trigger_s + delay_s) * 1000.0
                    + getattr(decision, "compute_us", 0.0) / 1000.0)
        if seq is None:
            seq = self.next_alert_seq()
        return self._protect(self.alert_msg, {
            "Status": status,
            "Class": cls,
            "Confidence": min(max(float(decision.confidence), 0.0), 1.0),
            "TimeSinceTrigger": int(min(max(since_ms + 0.5, 0), 65535)),
            "AlertSeq": seq,
        })

    def skip_status(self, n: int) -> None:
        """``n`` WEARABLE_STATUS frames that are not sent (nobody hears them): the alive counter moves on."""
        self._e2e.skip(self._status_id, n)

    def skip_alert(self, n: int) -> None:
        """``n`` DISTRACTION_ALERT frames that are not sent (nobody hears them): the alive counter moves on."""
        self._e2e.skip(self._alert_id, n)

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


class Clock(enum.Enum):
    """What drives the publisher's schedule and stamps its frames."""

    WALL = "wall"
    """A live source: a background thread, ``time.monotonic()`` for the schedule, ``time.time()`` stamps."""
    DATA = "data"
    """A replay: the recording's time, moved by :meth:`AlertPublisher.advance_to`; frames stamped with it."""


class _Copy(NamedTuple):
    """A DISTRACTION_ALERT copy waiting for its time (on the publisher's clock). A tuple, ordered by
    (due_s, order) alone (order is unique): the heap compares them in C (a replay makes 17,540 a day)."""

    due_s: float
    order: int
    alert: Any
    seq: int
    delay_s: float


class AlertPublisher:
    """Publishes alerts (each with its copies) and the periodic WEARABLE_STATUS heartbeat of
    ``status`` on a python-can bus, on the wall clock or on the data clock (:class:`Clock`)."""

    def __init__(self, bus: can.BusABC | None, encoder: AlertEncoder | None = None, heartbeat_period_s: float = 0.1,
                 log_path: str | Path | None = None, bus_factory: Callable[[], can.BusABC] | None = None,
                 status: WearableStatus | None = None, clock: Clock = Clock.WALL):
        if heartbeat_period_s <= 0:
            raise ValueError("heartbeat_period_s must be > 0")
        self.bus = bus
        # a live box parses the DBC here, so a broken DBC or install is one line at start, not a dead heartbeat
        # thread; a replay parses it when it first encodes a frame (with nobody listening, never)
        self.encoder = encoder or AlertEncoder(lazy=clock is Clock.DATA)
        self.period = heartbeat_period_s
        self.bus_factory = bus_factory
        self.status = status if status is not None else WearableStatus()
        self.clock = clock
        self.frames_sent = 0
        self.alerts_sent = 0
        self.alert_copies_sent = 0
        self.heartbeats_sent = 0
        self.frames_unheard = 0  # of the frames sent, those not encoded: nobody could hear them (data clock)
        self.send_errors = 0
        self.reconnects = 0
        self.last_error: str | None = None
        self.thread_error: str | None = None  # why the heartbeat thread died, if it did (:meth:`_run`)
        self._send_lock = threading.Lock()
        self._copies: list[_Copy] = []  # a heap, by due time
        self._copies_lock = threading.Lock()
        self._order = itertools.count()
        self._stop = threading.Event()
        self._wake = threading.Event()  # a copy was scheduled, or stop: the thread re-plans
        self._thread: threading.Thread | None = None
        self._beat_lock = threading.Lock()  # one sender per periodic heartbeat: the loop's thread or the heartbeat thread
        self._next_wall_beat_s = 0.0  # wall clock: when the next periodic heartbeat is due (time.monotonic())
        self._ridden = False  # the loop's thread sends the periodic heartbeats (beat_if_due); the thread backs it up
        self._data_t0_s: float | None = None  # data clock: the first sample's time ...
        self._data_now_s: float | None = None  # ... the clock now ...
        self._next_beat_s: float | None = None  # ... and when the next heartbeat is due
        self._logger = None
        if log_path:
            import can  # here: a replay that sends nothing never loads python-can (canbus.bus.DeferredBus)

            self._logger = can.Logger(str(log_path))
        self.backlog = AlertBacklog()

    # -- sending ----------------------------------------------------------
    def send(self, msg: can.Message, stamp_s: float | None = None) -> bool:
        """Send one frame; True if the bus took it. Errors are counted, never raised.
        ``stamp_s``: the frame's time on the data clock (default: now, wall clock)."""
        with self._send_lock:
            if self.bus is None:
                self.send_errors += 1
                self.last_error = "no bus"
                return False
            msg.timestamp = time.time() if stamp_s is None else stamp_s
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

    def publish_alert(self, alert: Any) -> int | None:
        """A DISTRACTION_ALERT for an alert the policy made (the loop's would-alert verdict:
        t_trigger_s, t_alert_s, label, confidence, status, compute_us): its first frame now
        (on the data clock: at ``t_alert_s``) and its copies scheduled after it.

        An update of an alert (the alert's ``event_seq``: confirmed, revised, withdrawn) goes out under
        that AlertSeq with copies of its own; a new alert gets a new AlertSeq.

        Returns the AlertSeq its frames carry, or None if the first frame did not go out:
        then no copy is sent either, so an alert is on the bus exactly when its decision says so."""
        self._send_backlog()
        seq = self._publish(alert, self._now_for(alert))
        if seq is None:
            self.backlog.hold(alert)  # sent late when the bus is back, or counted lost
        return seq

    def _publish(self, alert: Any, now_s: float) -> int | None:
        """An alert's first frame now and its copies scheduled after it, on time or late alike (a
        late alert goes out just after the bus came back, when a receiver may still be
        reconnecting: one frame alone is easily lost). Its AlertSeq (an update's is its
        alert's, see :meth:`_seq_of`), or None if the first frame did not go out."""
        seq = self._seq_of(alert)
        if not self._send_alert_frame(alert, seq, 0.0, now_s):
            return None
        self.alerts_sent += 1
        with self._copies_lock:
            for delay_s in self.encoder.repetition.delays_s():
                heapq.heappush(self._copies, _Copy(now_s + delay_s, next(self._order), alert, seq, delay_s))
        if self._thread is not None:  # only the wall clock's thread waits for it
            self._wake.set()
        return seq

    def _seq_of(self, alert: Any) -> int:
        seq = getattr(alert, "event_seq", None)
        return self.encoder.next_alert_seq() if seq is None else int(seq)

    def send_alert(self, alert: Any) -> bool:
        """:meth:`publish_alert`, answering only whether the alert went out."""
        return self.publish_alert(alert) is not None

    def _send_backlog(self) -> None:
        """Alerts held while the bus was down, sent late now that it may be back (or counted
        lost when too old); the total goes to the status, so the next heartbeat says degraded."""
        if self.bus is None or not len(self.backlog):
            return
        late, _ = self.backlog.take()
        now_s = time.monotonic() if self.clock is Clock.WALL else (self._data_now_s or 0.0)
        for k, (alert, _) in enumerate(late):
            if self._publish(alert, now_s) is None:
                for again, since in late[k:]:
                    self.backlog.hold(again.alert, since_s=since)
                break
            self.backlog.sent()
        c = self.backlog.counts()
        self.status.set_alerts_undelivered(c.sent_late + c.lost)

    def on_decision(self, decision: Any) -> bool:
        """For a decision made elsewhere (a recording's, a test's): its DISTRACTION_ALERT if it is alerted."""
        return self.send_alert(decision) if getattr(decision, "alerted", False) else False

    def send_heartbeat(self) -> bool:
        """WEARABLE_STATUS now: the heartbeat thread's, or at once on a change of the sensor's state."""
        return self._beat(self.status.heartbeat())

    def beat_if_due(self) -> None:
        """The loop's thread, between its blocks (a live box): the periodic heartbeat if it is due.

        That thread wakes 20 times a second for its samples anyway; on this machine a wake-up costs
        about as much CPU as the heartbeat's own work (a bare 10 Hz wake-up 0.11-0.17 % of a core, the
        heartbeat thread with its work about 0.4-0.5 %, against a 1 % budget for the whole 100 Hz loop).
        From the first call on the heartbeat thread only backs it up (a heartbeat overdue by
        :data:`RIDE_LATE_S`), and a heartbeat is due a period after the one before, not on a fixed grid
        (the loop's wake-ups do not fall on one), up to a fifth of a period early counting as due. Nothing
        before :meth:`start` (wall clock only: a replay's heartbeats go out at data times, :meth:`advance_to`)."""
        if self._thread is None:
            return
        self._ridden = True
        # a fifth of a period early is on time: wake-ups two read periods apart must not miss it by a hair
        # and send it a read period late
        self._beat_if_due(time.monotonic(), -self.period / 5)

    def _beat_if_due(self, now_s: float, late_s: float) -> None:
        """The periodic heartbeat, if it is ``late_s`` overdue at ``now_s`` (wall clock), and the next one scheduled."""
        with self._beat_lock:
            if now_s < self._next_wall_beat_s + late_s:
                return
            self.send_heartbeat()
            if self._ridden:  # on the loop's wake-ups: a period after this one
                self._next_wall_beat_s = now_s + self.period
            else:  # the heartbeat thread's own grid; after a stall (a slow reconnect) a period from now, no burst
                self._next_wall_beat_s += self.period
                if self._next_wall_beat_s < now_s:
                    self._next_wall_beat_s = now_s + self.period

    def _late_s(self) -> float:
        """How overdue the heartbeat thread lets a periodic heartbeat get before sending it itself."""
        return min(RIDE_LATE_S, self.period) if self._ridden else 0.0

    def _beat(self, signals: dict, stamp_s: float | None = None) -> bool:
        ok = self.send(self.encoder.encode_status(**signals), stamp_s=stamp_s)
        self.heartbeats_sent += ok
        return ok

    def _send_copies_due(self, now_s: float) -> None:
        """Every copy due by ``now_s`` on the publisher's clock, in time order. On the data clock with
        nobody to hear them, they are counted together (:meth:`_send_alert_frame`'s way, one call)."""
        if self.clock is Clock.DATA and not self._heard():
            with self._copies_lock:
                n_due = 0
                while self._copies and self._copies[0].due_s <= now_s:
                    heapq.heappop(self._copies)
                    n_due += 1
            if n_due:
                self._count_unheard_alerts(n_due)
                self.alert_copies_sent += n_due
            return
        while True:
            with self._copies_lock:
                if not self._copies or self._copies[0].due_s > now_s:
                    return
                c = heapq.heappop(self._copies)
            self.alert_copies_sent += self._send_alert_frame(c.alert, c.seq, c.delay_s, c.due_s)

    def _send_alert_frame(self, alert: Any, seq: int, delay_s: float, t_s: float) -> bool:
        """One DISTRACTION_ALERT frame at ``t_s`` on the publisher's clock. On the data clock a frame
        nobody can hear is counted and its alive counter moved on, not encoded (see :meth:`_skip_beats`);
        a live box always sends, so what the bench measures is what a vehicle's bus costs."""
        if self.clock is Clock.DATA and not self._heard():
            self._count_unheard_alerts(1)
            return True
        return self.send(self.encoder.encode_alert(alert, seq, delay_s), stamp_s=self._stamp(t_s))

    def _count_unheard_alerts(self, n: int) -> None:
        """``n`` DISTRACTION_ALERT frames sent where nobody can hear them: counted, their alive counter moved on."""
        self.encoder.skip_alert(n)
        self.frames_sent += n
        self.frames_unheard += n

    def _next_copy_s(self) -> float:
        with self._copies_lock:
            return self._copies[0].due_s if self._copies else float("inf")

    # -- clocks -----------------------------------------------------------
    def _now_for(self, alert: Any) -> float:
        """The alert's time on the publisher's clock; on the data clock everything due before it goes first."""
        if self.clock is Clock.WALL:
            return time.monotonic()
        self.advance_to(alert.t_alert_s)
        return alert.t_alert_s

    def _stamp(self, t_s: float) -> float | None:
        return t_s if self.clock is Clock.DATA else None

    def advance_to(self, t_s: float) -> None:
        """Data clock: the recording has reached ``t_s``; send what was due by then, in time order
        (a heartbeat every ``heartbeat_period_s`` of data from the first sample, and the copies)."""
        if self.clock is not Clock.DATA:
            raise RuntimeError("advance_to is for the data clock (a replay)")
        if self._data_t0_s is None:
            self._data_t0_s = self._next_beat_s = t_s
        self._data_now_s = max(t_s, self._data_now_s if self._data_now_s is not None else t_s)
        if self._next_beat_s <= self._data_now_s and not self._heard():
            self._skip_beats(self._data_now_s)
        while self._next_beat_s <= self._data_now_s:
            beat_s = self._next_beat_s
            self._send_copies_due(beat_s)
            self._beat(self.status.heartbeat(uptime_s=beat_s - self._data_t0_s), stamp_s=beat_s)
            self._next_beat_s = self._data_t0_s + round((beat_s - self._data_t0_s) / self.period + 1) * self.period
        self._send_copies_due(self._data_now_s)

    def _heard(self) -> bool:
        """Whether a frame sent now reaches anyone: a log, or a bus other than a python-can
        virtual bus with nobody else on its channel (which drops what it is sent)."""
        return self._logger is not None or self.bus is None or reaches_anyone(self.bus)

    def _skip_beats(self, until_s: float) -> None:
        """Data clock, nobody to hear them: the heartbeats due by ``until_s`` are counted, not
        encoded. A replay on the in-process bus sends 864,000 a day into the void, and encoding
        them was most of its time. What a heard heartbeat would carry on is carried on: the
        status's baseline (:meth:`WearableStatus.skip_heartbeats`) and the alive counter, so
        that a frame sent once someone listens is the one it would have been."""
        t0, period = self._data_t0_s, self.period
        first = round((self._next_beat_s - t0) / period)
        last = int((until_s - t0) // period) + 2
        while t0 + last * period > until_s:  # the schedule's own float comparison decides
            last -= 1
        n = last - first + 1
        if n <= 0:
            return
        self.status.skip_heartbeats(n)
        self.encoder.skip_status(n)
        self.heartbeats_sent += n
        self.frames_unheard += n
        self.frames_sent += n
        self._next_beat_s = t0 + (last + 1) * period

    # -- heartbeat thread (wall clock) --------------------------------------
    def _run(self) -> None:
        """The heartbeat thread. An exception it did not expect ends it (a bug, or an install that broke under it):
        it is kept in :attr:`thread_error` and logged in one line, and :meth:`check_running` fails the command
        (so the loop stops feeding the service watchdog) rather than leaving a box that looks healthy but sends
        no heartbeat."""
        try:
            self._beat_until_stopped()
        except BaseException as exc:  # noqa: BLE001 - any of them leaves the vehicle without heartbeats
            self.thread_error = f"{type(exc).__name__}: {exc}".replace("\n", " ")
            log.error("CAN heartbeat thread stopped: %s", self.thread_error, extra={"event": "heartbeat_thread_died"})

    def check_running(self) -> None:
        """CanLinkError (one line, exit 2) if the heartbeat thread died (:meth:`_run`)."""
        if self.thread_error is not None:
            raise CanLinkError(f"CAN heartbeat thread stopped: {self.thread_error}")

    def _beat_until_stopped(self) -> None:
        self._next_wall_beat_s = time.monotonic()
        while not self._stop.is_set():
            self._wake.clear()
            if self.bus is None and self.bus_factory is not None:
                self._reconnect()
            self._send_backlog()
            now = time.monotonic()
            self._send_copies_due(now)
            self._beat_if_due(now, self._late_s())
            wait_s = min(self._next_wall_beat_s + self._late_s(), self._next_copy_s()) - time.monotonic()
            self._wake.wait(max(wait_s, 0.0))

    def start(self) -> "AlertPublisher":
        """Wall clock: start the heartbeat thread. Data clock: nothing runs between samples."""
        if self._thread is None and self.clock is Clock.WALL:
            self._stop.clear()
            self._ridden = False
            self._thread = threading.Thread(target=self._run, name="can-heartbeat", daemon=True)
            self._thread.start()
        return self

    def stop(self) -> None:
        """Stop after the copies still due: on the wall clock the thread sends them on time (they
        are due within the repetition's span); on the data clock at their data time, after the
        recording's end. Then the heartbeat stops and the log is closed."""
        if self._thread is not None:
            span_s = self.encoder.repetition.copies * self.encoder.repetition.period_s
            deadline = time.monotonic() + span_s + 1.0
            while self._next_copy_s() < float("inf") and time.monotonic() < deadline and self._thread.is_alive():
                self._stop.wait(self.encoder.repetition.period_s / 2)
            self._stop.set()
            self._wake.set()
            self._thread.join(timeout=max(2.0, 3 * self.period))
            self._thread = None
        # copies still waiting (the data clock after the recording's end, a publisher never started,
        # a thread that could not finish): sent now, at their data time on the data clock, not dropped
        self._send_copies_due(float("inf"))
        if self._logger is not None:
            self._logger.stop()
            self._logger = None

    def close(self) -> None:
        """Stop and shut the bus down; alerts still held are lost (counted in the summary)."""
        self.stop()
        self.backlog.abandon()
        if self.bus is not None:
            self._drop_bus()

    def __enter__(self) -> "AlertPublisher":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.close()

    def summary(self) -> dict:
        b = self.backlog.counts()
        return {"frames_sent": self.frames_sent, "alerts_sent": self.alerts_sent,
                "alert_copies_sent": self.alert_copies_sent, "alerts_held": b.held,
                "alerts_sent_late": b.sent_late, "alerts_lost": b.lost + b.pending,
                "heartbeats_sent": self.heartbeats_sent, "frames_unheard": self.frames_unheard,
                "send_errors": self.send_errors,
                "reconnects": self.reconnects}
