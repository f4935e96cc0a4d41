"""Session 21 (issue 12): the hybrid, where the streaming model opens alerts and the shipped capture policy carries on.

    PYTHONPATH=. python reports/wearable/stream_s21/hybrid.py MODEL.pt SEED CHOICE.json OUT.json

Alert events of both sources go on one time line (each from its first alert frame to its last frame: a streaming
event to its close, a shipped event to its last update, either plus ``HOLD_S``). An event that starts while
another is active is that event's continuation (an update, not a new alert; the shipped loop's
``event_hold_s`` idea). Otherwise it raises its own alert: a streaming alert as ``policy.alerts`` makes it, a
shipped one with all its decisions as the runtime made them (its capture's trigger and later frames, so
drive-eval's scorer credits it exactly as it credits the shipped policy).

So the hybrid's first alert is the earlier of the two, and its false alerts are those of either that nothing
absorbed. A withdrawal or a revision by the shipped full window does not change drive-eval's figures (a withdrawn
alert still counts as a false alert; the class is the first alert's) and is not modelled.

The streaming policy is the frozen choice (CHOICE.json's "chosen"), the threshold swept around it.
"""
from __future__ import annotations

import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from data import DEFAULT_DIR, load_streams  # noqa: E402
from policy import GRID, Policy, alerts, load_probs, meets, score_drives  # noqa: E402
from shipped import decisions_path  # noqa: E402

from firmware_sim.scenarios.scoring import raises_alert  # noqa: E402

HOLD_S = 5.0
"""As the shipped ``[alerts] event_hold_s``: an alert within 5 s of the end of the active event continues it."""


def merge(stream: list[dict], shipped: list[dict]) -> list[dict]:
    """One drive's decisions of the hybrid (see the module's docstring)."""
    events = []  # (start, end, decisions that go out if it opens its own alert)
    for d in stream:
        events.append((d["t_alert_s"], d["event_end_s"], [d]))
    by_event: dict[tuple, list[dict]] = {}
    for d in shipped:
        if d["alerted"]:
            by_event.setdefault((d["alert_seq"], d["event_start_s"]), []).append(d)
    for decs in by_event.values():
        first = [d for d in decs if raises_alert(d)]
        if first:
            events.append((first[0]["t_alert_s"], max(d["t_alert_s"] for d in decs), decs))
    out, active_until = [], -1.0
    for start, end, decs in sorted(events, key=lambda e: e[0]):
        if start > active_until:
            out += decs
        active_until = max(active_until, end + HOLD_S)
    return out


def main(argv: list[str]) -> int:
    model, seed, choice, out = argv[0], int(argv[1]), Path(argv[2]), Path(argv[3])
    pol = Policy(**json.loads(choice.read_text())["chosen"]["policy"])
    drives = load_streams(DEFAULT_DIR / f"drives_seed{seed}")
    shipped = json.loads(decisions_path(seed).read_text())
    cache = load_probs(model, seed, pol.window_s, len(drives))
    rows = []
    for thr in sorted(set(GRID["thr"]) | {pol.thr, 0.99, 0.995}):
        q = Policy(**{**pol.__dict__, "thr": thr})
        dec = [merge(alerts(t, p, q), s) for (t, p), s in zip(cache, shipped)]
        f, _ = score_drives(drives, dec)
        rows.append({"thr": thr, "figures": f, "meets": meets(f)})
        print(thr, f, flush=True)
    out.write_text(json.dumps({"seed": seed, "model": model, "stream_policy": pol.__dict__, "hold_s": HOLD_S,
                               "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
