"""The stock-tools CAN listener script (python-can + cantools + autosar-e2e only) used by the hub and end-to-end tests:
one line per alert, its copies (same AlertSeq within 1 s, as the DBC says) skipped."""
from __future__ import annotations

import textwrap

LISTENER = textwrap.dedent("""
    import json, sys, time
    import can, cantools
    dbc, port, n = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    db = cantools.database.load_file(dbc)
    bus = can.Bus(interface="socketcand", host="127.0.0.1", port=port, channel="vcan0")
    print("ready", flush=True)
    got, deadline, seen = 0, time.monotonic() + 10, {}
    while got < n and time.monotonic() < deadline:
        m = bus.recv(0.2)
        if m is None or m.arbitration_id != db.get_message_by_name("DISTRACTION_ALERT").frame_id:
            continue
        d = db.decode_message(m.arbitration_id, m.data)
        now = time.monotonic()
        if now - seen.get(d["AlertSeq"], -1e9) < 1.0:  # the DBC: a copy of an alert already counted
            continue
        seen[d["AlertSeq"]] = now
        print(json.dumps({k: (str(v) if not isinstance(v, (int, float)) else v) for k, v in d.items()}), flush=True)
        got += 1
    bus.shutdown()
    mods = sorted({k.split(".")[0] for k in sys.modules})
    print(json.dumps({"project_modules": [k for k in mods if k in ("edge_runtime", "firmware_sim", "models", "e2e")]}))
""")
