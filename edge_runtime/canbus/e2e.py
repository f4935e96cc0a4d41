"""AUTOSAR E2E Profile 1 for any DBC message, through the ``autosar-e2e`` package.

CRC-8 in byte 0, alive counter 0..14 in the low nibble of byte 1, data ID from the
DBC's ``E2E_DataID`` message attribute (mode BOTH). The sender (:class:`E2EProtector`)
and the receiver (:class:`E2EChecker`) are shared by the vehicle alerts and the robot link.

The receiver checks the frame itself before anything reads its bytes (:func:`frame_fault`):
an error or remote frame, an identifier of the wrong kind (extended where the DBC says
standard) or a length other than the DBC's is refused as ``bad_frame``, so a decoder
behind a valid check never meets a frame it cannot decode.
"""
from __future__ import annotations

import threading
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import e2e.p01 as p01

if TYPE_CHECKING:
    import can

COUNTER_MAX = 14  # AUTOSAR E2E Profile 1: 0..14, 15 is invalid


def e2e_data_id(message) -> int:
    """The E2E data ID of a DBC message (``E2E_DataID`` attribute, default: its CAN ID)."""
    attrs = message.dbc.attributes if message.dbc is not None else {}
    attr = attrs.get("E2E_DataID")
    return int(attr.value) if attr is not None else int(message.frame_id)


COUNTER_BYTE = 1
"""Profile 1's alive counter: the low nibble of this byte (the DBCs' AliveCounter, bits 8..11)."""
PAYLOAD_CACHE = 512
"""Encoded payloads kept per protector: a heartbeat repeats its signals (a replay sends 864,000
WEARABLE_STATUS frames a day, 10 per distinct Uptime_s), and cantools' checked encoding was the
largest single cost of a replay."""


def _checked_payload(message, signals: dict) -> bytes:
    """``signals`` encoded by cantools and checked by it against the DBC (strict: every signal, in range),
    with the alive counter and the CRC zero."""
    return message.encode(dict(signals, E2E_CRC=0, AliveCounter=0), strict=True)


class E2EProtector:
    """Send side of E2E Profile 1 for any DBC message: cantools encodes the signals, then
    the alive counter (one per frame ID, wrapping at COUNTER_MAX) and the CRC go in.
    Thread-safe: a heartbeat thread and the main loop may send at once.

    The signals' encoding (checked against the DBC, counter and CRC zero) is remembered for
    the last PAYLOAD_CACHE signal sets: the same signals encode to the same bytes, so only
    the counter and the CRC are computed again."""

    def __init__(self):
        self._counters: dict[int, int] = {}
        self._lock = threading.Lock()
        self._payloads: OrderedDict[tuple, bytes] = OrderedDict()
        self._data_ids: dict[int, int] = {}  # per frame ID: its DBC attribute, looked up once

    def _payload(self, message, signals: dict, remember: bool) -> bytes:
        if not remember:  # signals that will not come again: a lookup and an entry would be work for nothing
            return _checked_payload(message, signals)
        # the signals in the caller's order: the encoders build them in a fixed order, and the same
        # signals in another order only make a second entry with the same bytes (no sort per frame)
        key = (message.frame_id, *signals.items())
        with self._lock:
            data = self._payloads.get(key)
            if data is not None:
                self._payloads.move_to_end(key)
                return data
        data = _checked_payload(message, signals)
        with self._lock:
            self._payloads[key] = data
            if len(self._payloads) > PAYLOAD_CACHE:
                self._payloads.popitem(last=False)
        return data

    def skip(self, frame_id: int, n: int) -> None:
        """``n`` frames of the message ``frame_id`` that were not sent: its alive counter moves on as if they had been."""
        with self._lock:
            counter = self._counters.get(frame_id, 0)
            self._counters[frame_id] = (counter + n) % (COUNTER_MAX + 1)

    def protect(self, message, signals: dict, remember: bool = True) -> can.Message:
        """The protected frame of ``message`` with ``signals``. ``remember=False``: signals that will not come
        again (a command's new sequence number) are encoded without the payload cache."""
        frame_id = message.frame_id  # a cantools property: read once
        with self._lock:
            counter = self._counters.get(frame_id, 0)
            self._counters[frame_id] = (counter + 1) % (COUNTER_MAX + 1)
        data = bytearray(self._payload(message, signals, remember))
        data[COUNTER_BYTE] |= counter
        data_id = self._data_ids.get(frame_id)
        if data_id is None:
            data_id = self._data_ids[frame_id] = e2e_data_id(message)
        p01.e2e_p01_protect(data, data_id, length=len(data), increment_counter=False)
        import can  # here: a replay that sends nothing never loads python-can (canbus.bus.DeferredBus)

        return can.Message(arbitration_id=frame_id, data=data, is_extended_id=message.is_extended_frame)


def frame_fault(msg: can.Message, message) -> str | None:
    """Why ``msg`` cannot be the DBC ``message`` (None if it can): the frame-level check, once per frame."""
    if msg.is_error_frame:
        return "error frame"
    if msg.is_remote_frame:
        return "remote frame"
    if bool(msg.is_extended_id) != bool(message.is_extended_frame):
        return "extended identifier" if msg.is_extended_id else "standard identifier"
    if len(msg.data) != message.length:
        return f"{len(msg.data)} data bytes, the DBC says {message.length}"
    return None


@dataclass(frozen=True)
class E2EResult:
    status: str
    """'ok', 'initial' (first frame seen), 'wrong_crc', 'repeated', 'lost' (lost > 0 frames in between),
    'unknown_id', 'bad_frame' (error/remote frame, wrong identifier kind or length: see ``reason``)."""
    lost: int = 0
    reason: str = ""

    @property
    def valid(self) -> bool:
        return self.status in ("ok", "initial", "lost")


_PLAIN = {status: E2EResult(status) for status in ("ok", "initial", "repeated", "wrong_crc", "unknown_id")}
"""One shared (frozen) result per status that carries nothing else: the robot's state arrives as seven
frames every 10 ms, and a result made per frame was about 5 % of the frame's receive cost (0.75 of ~14 us)."""


@dataclass
class E2EChecker:
    """Receive side of E2E Profile 1: CRC, then the alive counter against the last good frame."""

    db: Any = field(default=None, repr=False)
    counts: dict = field(default_factory=dict)

    def __post_init__(self):
        if self.db is None:
            raise ValueError("E2EChecker needs the DBC whose messages it checks (db=...)")
        self._messages = {m.frame_id: m for m in self.db.messages}
        self._ids = {m.frame_id: e2e_data_id(m) for m in self.db.messages}
        self._last: dict[int, int] = {}

    def check(self, msg: can.Message) -> E2EResult:
        res = self._check(msg)
        self.counts[res.status] = self.counts.get(res.status, 0) + 1
        if res.lost:
            self.counts["lost_frames"] = self.counts.get("lost_frames", 0) + res.lost
        return res

    def _check(self, msg: can.Message) -> E2EResult:
        frame_id = msg.arbitration_id
        message = self._messages.get(frame_id)
        if message is None:
            return _PLAIN["unknown_id"]
        fault = frame_fault(msg, message)
        if fault is not None:
            return E2EResult("bad_frame", reason=fault)
        data = msg.data  # python-can's bytearray, checked in place (autosar-e2e only reads it): no copy per frame
        if not isinstance(data, bytearray):  # autosar-e2e refuses a read-only buffer: a frame given bytes is copied
            data = bytearray(data)
        if not p01.e2e_p01_check(data, self._ids[frame_id], length=len(data)):
            return _PLAIN["wrong_crc"]
        counter = data[COUNTER_BYTE] & 0x0F
        if counter > COUNTER_MAX:
            return _PLAIN["wrong_crc"]
        last = self._last.get(frame_id)
        self._last[frame_id] = counter
        if last is None:
            return _PLAIN["initial"]
        delta = (counter - last) % (COUNTER_MAX + 1)
        if delta == 0:
            return _PLAIN["repeated"]
        if delta == 1:
            return _PLAIN["ok"]
        return E2EResult("lost", lost=delta - 1)

    @property
    def errors(self) -> int:
        return (self.counts.get("wrong_crc", 0) + self.counts.get("repeated", 0) + self.counts.get("lost_frames", 0)
                + self.counts.get("bad_frame", 0))


