"""A vehicle integrator's listener, written with stock tools only.

It imports python-can, cantools and autosar-e2e, never this project's code: it is
what an ECU-side integration looks like, given our DBC (edge_runtime/assets/vehicle_alerts.dbc).

    python docs/examples/listen_alerts.py --dbc edge_runtime/assets/vehicle_alerts.dbc \\
        --interface socketcand --channel vcan0 --host 127.0.0.1 --port 29536

On a real box: ``--interface socketcan --channel can0``, or ``--interface slcan --channel /dev/ttyACM0``.
It prints one line per alert and per heartbeat state change, warns when the
heartbeat is missing for more than 300 ms, reopens its bus then and after 1 s without any
frame (an adapter unplugged, a hub restarted), and on exit (SIGINT/SIGTERM or
--duration) prints a JSON summary: alerts, their updates (withdrawn among them), expired
preliminary alerts, alert copies skipped, heartbeats, E2E errors, largest heartbeat gap, how often the bus was opened.

Each message comes as several DISTRACTION_ALERT frames (the DBC's GenMsgNrOfRepetition copies,
GenMsgCycleTimeFast ms apart, all alike), so a lost frame costs nothing but the wait for the
next copy. One AlertSeq is one alert event: its first message is the alert (Status alert, or
preliminary when the capture path decides early), later messages with the same AlertSeq are updates
(confirmed, revised: a new Class, withdrawn: the alert is void). As shipped (the DBC's decision stream)
every alert is one message of Status alert and no update follows; the listener handles both the same way. A frame whose (AlertSeq, Status, Class) was
accepted within the last COPY_WINDOW_S is a copy; an alert counts once, each update once.
"""
import argparse
import json
import signal
import socket
import sys
import time

import can
import cantools
import e2e.p01 as p01

COUNTER_MAX = 14  # AUTOSAR E2E Profile 1: alive counter 0..14
HEARTBEAT_TIMEOUT_S = 0.3
COPY_WINDOW_S = 1.0  # the DBC: copies span 200 ms; the same (AlertSeq, Status, Class) later is a new message
UPDATE_WINDOW_S = 10.0  # the DBC: an alert's updates come by the end of its capture (~6 s); an older AlertSeq is new
PRELIMINARY_EXPIRY_S = 7.0  # the DBC: a preliminary alert with no update for 7 s has expired (sensor stream cut)
ACTION = {"alert": "warn", "preliminary": "warn (preliminary)", "confirmed": "keep warning", "revised": "warn, class changed",
          "withdrawn": "stop warning: alert void", "uncertain": "ignore"}


def data_id(message):
    attr = message.dbc.attributes.get("E2E_DataID") if message.dbc is not None else None
    return int(attr.value) if attr is not None else message.frame_id


class AlertListener:
    """What the listener does with one frame (``frame``) and with the passing of time (``tick``),
    without a bus: the main loop below feeds it, and so can a test or a fuzzer.
    ``emit`` receives each line the listener prints."""

    def __init__(self, db, json_lines=False, emit=lambda line: print(line, flush=True)):
        self.db, self.json_lines, self.emit = db, json_lines, emit
        self.alert = db.get_message_by_name("DISTRACTION_ALERT")
        self.status = db.get_message_by_name("WEARABLE_STATUS")
        self.messages = {m.frame_id: m for m in (self.alert, self.status)}
        self.ids = {m.frame_id: data_id(m) for m in (self.alert, self.status)}
        self.counts = {"alerts": 0, "updates": 0, "withdrawn": 0, "expired": 0, "alert_copies": 0, "heartbeats": 0,
                       "e2e_wrong_crc": 0, "e2e_repeated": 0, "e2e_lost": 0, "bad_frames": 0, "heartbeat_timeouts": 0}
        self.last_counter, self.last_beat, self.max_gap, self.state = {}, None, 0.0, None
        self.accepted = {}  # (AlertSeq, Status, Class) -> when that message was accepted (monotonic s)
        self.events = {}  # AlertSeq -> [time of its latest message, its latest Status]

    def tick(self, now):
        """The heartbeat watchdog and the expiry of preliminary alerts, at monotonic time ``now``."""
        for seq, (t, status) in list(self.events.items()):
            if status == "preliminary" and now - t > PRELIMINARY_EXPIRY_S:
                self.events[seq][1] = "expired"
                self.counts["expired"] += 1
                self.emit(f"EXPIRED {seq:>5} preliminary alert without an update for {PRELIMINARY_EXPIRY_S:g} s: stop warning")
        if self.last_beat is not None and now - self.last_beat > HEARTBEAT_TIMEOUT_S and self.state != "missing":
            self.counts["heartbeat_timeouts"] += 1
            self.state = "missing"
            self.emit(f"WEARABLE_STATUS missing for {now - self.last_beat:.2f} s: treat the wearable as unavailable")

    def frame(self, msg, now):
        """One received frame at monotonic time ``now``: checked as a frame (kind, identifier, length
        against the DBC), then E2E (CRC, alive counter), and only then decoded."""
        message = self.messages.get(msg.arbitration_id)
        if message is None:
            return
        if (msg.is_error_frame or msg.is_remote_frame or bool(msg.is_extended_id) != message.is_extended_frame
                or len(msg.data) != message.length):
            self.counts["bad_frames"] += 1  # cantools cannot decode it; the E2E check would not catch all of it
            return
        data = bytearray(msg.data)
        if not p01.e2e_p01_check(data, self.ids[msg.arbitration_id], length=len(data)):
            self.counts["e2e_wrong_crc"] += 1
            return
        counter, prev = data[1] & 0x0F, self.last_counter.get(msg.arbitration_id)
        self.last_counter[msg.arbitration_id] = counter
        if prev is not None:
            delta = (counter - prev) % (COUNTER_MAX + 1)
            if delta == 0:
                self.counts["e2e_repeated"] += 1
                return
            self.counts["e2e_lost"] += delta - 1
        sig = self.db.decode_message(msg.arbitration_id, msg.data)
        if msg.arbitration_id == self.status.frame_id:
            self.counts["heartbeats"] += 1
            if self.last_beat is not None:
                self.max_gap = max(self.max_gap, now - self.last_beat)
            self.last_beat = now
            if str(sig["State"]) != self.state:
                self.state = str(sig["State"])
                self.emit(f"WEARABLE_STATUS {self.state}, sensor {sig['SensorHealth']}, dropped {sig['DroppedSamples']}")
        else:
            self._alert(sig, now)

    def _alert(self, sig, now):
        """One valid DISTRACTION_ALERT frame: a copy, a new alert or an update of one."""
        seq, status, cls = sig["AlertSeq"], str(sig["Status"]), str(sig["Class"])
        key = (seq, status, cls)
        if now - self.accepted.get(key, float("-inf")) < COPY_WINDOW_S:
            self.counts["alert_copies"] += 1  # the message is already counted: this is a copy
            return
        self.accepted = {k: t for k, t in self.accepted.items() if now - t < COPY_WINDOW_S}
        self.accepted[key] = now
        self.events = {s: v for s, v in self.events.items() if now - v[0] < UPDATE_WINDOW_S}
        update = seq in self.events
        self.events[seq] = [now, status]
        self.counts["updates" if update else "alerts"] += 1
        self.counts["withdrawn"] += status == "withdrawn"
        rec = {k: (v if isinstance(v, (int, float)) else str(v)) for k, v in sig.items()}
        if self.json_lines:
            self.emit(json.dumps({**rec, "update": update, "action": ACTION.get(status, "ignore")}))
        else:
            self.emit(f"{'UPDATE' if update else 'ALERT'} {seq:>5} {cls:<12} {status:<11} confidence "
                      f"{rec['Confidence']:.2f}, {rec['TimeSinceTrigger']} ms after the trigger: "
                      f"{ACTION.get(status, 'ignore')}")

    def summary(self):
        counts = dict(self.counts)
        counts["e2e_errors"] = (counts["e2e_wrong_crc"] + counts["e2e_repeated"] + counts["e2e_lost"]
                                + counts["bad_frames"])
        counts["max_heartbeat_gap_ms"] = round(self.max_gap * 1000, 1)
        return counts


def open_bus(a):
    """The bus, or None while it cannot be opened. For socketcand the server is checked first:
    python-can retries a refused connect for 10 s on one socket, which then never succeeds."""
    extra = {}
    if a.interface == "socketcand":
        try:
            socket.create_connection((a.host, a.port), timeout=0.5).close()
        except OSError:
            return None
        extra = {"host": a.host, "port": a.port}
    try:
        return can.Bus(interface=a.interface, channel=a.channel, **extra)
    except (can.CanError, OSError):
        return None


def run(a, listener, stop):
    """Receive until ``stop["now"]`` or --duration; returns how many times the bus was opened.

    The bus is reopened when the heartbeat goes missing, or nothing at all arrived for
    --reconnect-after seconds since the bus was opened: a CAN adapter unplugged or a socketcand hub
    restarted shows up as silence (a closed socketcand socket just reads nothing), and a receive
    error is the same case."""
    t_end = None if a.duration is None else time.monotonic() + a.duration
    bus, connects, last_rx = None, 0, 0.0
    while not stop["now"] and (t_end is None or time.monotonic() < t_end):
        if bus is None:
            bus = open_bus(a)
            if bus is None:
                time.sleep(a.retry_after)
                continue
            connects += 1
            listener.last_beat, last_rx = None, time.monotonic()  # the gap while away is not the wearable's
            print(f"connected {connects}", flush=True)
        try:
            msg = bus.recv(0.05)
        except (can.CanError, OSError):
            msg, last_rx = None, float("-inf")
        now = time.monotonic()
        listener.tick(now)
        if msg is not None:
            listener.frame(msg, now)
            last_rx = now
        if listener.state == "missing" or now - last_rx > a.reconnect_after:
            bus.shutdown()
            bus = None
            listener.state = None  # a new bus: report the first heartbeat's state again
    if bus is not None:
        bus.shutdown()
    return connects


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dbc", required=True)
    ap.add_argument("--interface", default="socketcand")
    ap.add_argument("--channel", default="vcan0")
    ap.add_argument("--host", default="127.0.0.1")
    ap.add_argument("--port", type=int, default=29536)
    ap.add_argument("--duration", type=float, default=None, help="stop after this many seconds")
    ap.add_argument("--json", action="store_true", help="print alerts as JSON lines")
    ap.add_argument("--reconnect-after", type=float, default=1.0,
                    help="reopen the bus after this many seconds without any frame (default 1.0)")
    ap.add_argument("--retry-after", type=float, default=0.1,
                    help="seconds between attempts to open the bus (default 0.1)")
    a = ap.parse_args(argv)

    listener = AlertListener(cantools.database.load_file(a.dbc), json_lines=a.json)
    stop = {"now": False}
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.update(now=True))
    print("listening", flush=True)
    connects = run(a, listener, stop)
    print("summary " + json.dumps({**listener.summary(), "connects": connects}), flush=True)
    return 0

if __name__ == "__main__":
    sys.exit(main())
