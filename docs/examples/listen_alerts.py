"""A vehicle integrator's listener, written with stock tools only.

It imports python-can, cantools and autosar-e2e, never this project's code: it is
what an ECU-side integration looks like, given our DBC (edge_runtime/assets/vehicle_alerts.dbc).

    python docs/examples/listen_alerts.py --dbc edge_runtime/assets/vehicle_alerts.dbc \\
        --interface socketcand --channel vcan0 --host 127.0.0.1 --port 29536

On a real box: ``--interface socketcan --channel can0``, or ``--interface slcan --channel /dev/ttyACM0``.
It prints one line per alert and per heartbeat state change, warns when the
heartbeat is missing for more than 300 ms, and on exit (SIGINT/SIGTERM or
--duration) prints a JSON summary: alerts, alert copies skipped, heartbeats, E2E errors,
largest heartbeat gap.

Each alert comes as several DISTRACTION_ALERT frames (the DBC's GenMsgNrOfRepetition copies,
GenMsgCycleTimeFast ms apart, all with one AlertSeq), so a lost frame costs nothing but the
wait for the next copy. An alert counts once: the first valid frame of an AlertSeq is the
alert, a frame with an AlertSeq accepted within the last COPY_WINDOW_S is a copy.
"""
import argparse
import json
import signal
import sys
import time

import can
import cantools
import e2e.p01 as p01

COUNTER_MAX = 14  # AUTOSAR E2E Profile 1: alive counter 0..14
HEARTBEAT_TIMEOUT_S = 0.3
COPY_WINDOW_S = 1.0  # the DBC: copies of one alert span 200 ms; the same AlertSeq later is a new alert (a restart)


def data_id(message):
    attr = message.dbc.attributes.get("E2E_DataID") if message.dbc is not None else None
    return int(attr.value) if attr is not None else message.frame_id


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dbc", required=True)
    ap.add_argument("--interface", default="socketcand")
    ap.add_argument("--channel", default="vcan0")
    ap.add_argument("--host", default="127.0.0.1")
    ap.add_argument("--port", type=int, default=29536)
    ap.add_argument("--duration", type=float, default=None, help="stop after this many seconds")
    ap.add_argument("--json", action="store_true", help="print alerts as JSON lines")
    a = ap.parse_args(argv)

    db = cantools.database.load_file(a.dbc)
    alert = db.get_message_by_name("DISTRACTION_ALERT")
    status = db.get_message_by_name("WEARABLE_STATUS")
    ids = {m.frame_id: data_id(m) for m in (alert, status)}
    extra = {"host": a.host, "port": a.port} if a.interface == "socketcand" else {}
    bus = can.Bus(interface=a.interface, channel=a.channel, **extra)
    stop = {"now": False}
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.update(now=True))
    print("listening", flush=True)

    counts = {"alerts": 0, "alert_copies": 0, "heartbeats": 0, "e2e_wrong_crc": 0, "e2e_repeated": 0, "e2e_lost": 0, "heartbeat_timeouts": 0}
    last_counter, last_beat, max_gap, state = {}, None, 0.0, None
    accepted = {}  # AlertSeq -> when its alert was counted (monotonic s)
    t_end = None if a.duration is None else time.monotonic() + a.duration
    while not stop["now"] and (t_end is None or time.monotonic() < t_end):
        msg = bus.recv(0.05)
        now = time.monotonic()
        if last_beat is not None and now - last_beat > HEARTBEAT_TIMEOUT_S and state != "missing":
            counts["heartbeat_timeouts"] += 1
            state = "missing"
            print(f"WEARABLE_STATUS missing for {now - last_beat:.2f} s: treat the wearable as unavailable", flush=True)
        if msg is None or msg.arbitration_id not in ids:
            continue
        data = bytearray(msg.data)
        if not p01.e2e_p01_check(data, ids[msg.arbitration_id], length=len(data)):
            counts["e2e_wrong_crc"] += 1
            continue
        counter, prev = data[1] & 0x0F, last_counter.get(msg.arbitration_id)
        last_counter[msg.arbitration_id] = counter
        if prev is not None:
            delta = (counter - prev) % (COUNTER_MAX + 1)
            if delta == 0:
                counts["e2e_repeated"] += 1
                continue
            counts["e2e_lost"] += delta - 1
        sig = db.decode_message(msg.arbitration_id, msg.data)
        if msg.arbitration_id == status.frame_id:
            counts["heartbeats"] += 1
            if last_beat is not None:
                max_gap = max(max_gap, now - last_beat)
            last_beat = now
            if str(sig["State"]) != state:
                state = str(sig["State"])
                print(f"WEARABLE_STATUS {state}, sensor {sig['SensorHealth']}, dropped {sig['DroppedSamples']}", flush=True)
        else:
            seq = sig["AlertSeq"]
            if now - accepted.get(seq, float("-inf")) < COPY_WINDOW_S:
                counts["alert_copies"] += 1  # the alert is already counted: this is a copy
                continue
            accepted = {s: t for s, t in accepted.items() if now - t < COPY_WINDOW_S}
            accepted[seq] = now
            counts["alerts"] += 1
            rec = {k: (v if isinstance(v, (int, float)) else str(v)) for k, v in sig.items()}
            if a.json:
                print(json.dumps(rec), flush=True)
            else:
                print(f"ALERT {rec['AlertSeq']:>5} {rec['Class']:<12} confidence {rec['Confidence']:.2f}, "
                      f"{rec['TimeSinceTrigger']} ms after the trigger", flush=True)
    bus.shutdown()
    counts["e2e_errors"] = counts["e2e_wrong_crc"] + counts["e2e_repeated"] + counts["e2e_lost"]
    counts["max_heartbeat_gap_ms"] = round(max_gap * 1000, 1)
    print("summary " + json.dumps(counts), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
