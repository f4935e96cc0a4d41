"""Alerts through CAN hub outages, end to end: how many the wearable decided, how many a stock
listener received, how many were sent late or counted lost, and what WEARABLE_STATUS said.

A simulated drive streams live (``--imu sim?csv=...&speed=X``: the simulated IMU firmware,
time-lapsed) into ``python -m edge_runtime wearable``, which publishes on a CAN hub PROCESS
(``python -m firmware_sim can-hub``). During the run the hub process is stopped (SIGTERM) and
started again on the same port, once per ``--outage START:LENGTH`` (seconds of wall time after
the runtime's first heartbeat reached the listener). The listener is the integrator's
stock-tools one (docs/examples/listen_alerts.py's ``AlertListener``) in one process for the
whole run, reopening its bus when the hub went away (:func:`listen`). Used by
tests/e2e/test_hub_outage.py with a short drive; the figure (issue 16)::

    PYTHONPATH=.:tests python -m support.hub_outage --minutes 10 --seed 11 --speed 10 \\
        --outage 15:3 --outage 35:10

``decided`` are the decisions the alert policy made into alerts (``status`` "alert", or
"alert_not_sent" when the bus did not take it, in the runtime's ``--alerts`` file); ``received`` the distinct AlertSeqs the listeners counted;
``held``/``sent_late``/``lost`` the runtime's own summary; ``unaccounted`` = decided - received -
lost: alerts neither received nor reported lost (must be 0: an alert is never dropped silently).
"""
from __future__ import annotations

import argparse
import json
import os
import re
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

from edge_runtime.wearable.alerts import DBC_PATH
from support import REPO_ROOT

LISTENER = REPO_ROOT / "docs" / "examples" / "listen_alerts.py"
RECONNECT_AFTER_S = 1.0
"""The listener reopens its bus after this long without any frame (s)."""
SUMMARY_LOST = re.compile(r"alerts the bus did not take at first (\d+): sent late (\d+), lost (\d+)")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _wait_for(path: Path, text: str, proc: subprocess.Popen, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline and proc.poll() is None:
        if text in path.read_text():
            return True
        time.sleep(0.05)
    return text in path.read_text()


class _Hub:
    """One lifetime of the hub process."""

    def __init__(self, workdir: Path, port: int, index: int):
        self.log = workdir / f"hub{index}.out"
        self.proc = subprocess.Popen([sys.executable, "-m", "firmware_sim", "can-hub", "--port", str(port)],
                                     stdout=self.log.open("w"), stderr=subprocess.STDOUT, text=True)
        if not _wait_for(self.log, "listening", self.proc, 30):
            raise RuntimeError(f"can-hub did not start: {self.log.read_text()[-300:]}")

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            self.proc.wait(timeout=30)


def listen(port: int, dbc: str) -> int:
    """The stock listener (docs/examples/listen_alerts.py, loaded from that file) with JSON lines,
    retrying every 5 ms so that it is back on a restarted hub before the runtime is (the runtime
    retries every 100 ms). It prints ``connected N`` each time it opens the bus."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("listen_alerts", LISTENER)
    stock = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(stock)
    return stock.main(["--dbc", dbc, "--port", str(port), "--json", "--retry-after", "0.005",
                       "--reconnect-after", str(RECONNECT_AFTER_S)])


def measure(workdir: Path, minutes: float, seed: int, speed: float, outages: list[tuple[float, float]]) -> dict:
    """One run (see the module docstring); ``outages``: (start, length) in s of wall time."""
    workdir.mkdir(parents=True, exist_ok=True)
    r = subprocess.run([sys.executable, "-m", "firmware_sim", "drive", "--minutes", str(minutes), "--seed", str(seed),
                        "--out", str(workdir)], capture_output=True, text=True, timeout=600)
    if r.returncode != 0:
        raise RuntimeError(f"firmware_sim drive: {r.stderr.strip()[-300:]}")
    port = _free_port()
    hubs = [_Hub(workdir, port, 0)]
    heard = workdir / "listener.out"
    listener = subprocess.Popen([sys.executable, "-m", "support.hub_outage", "--listen", str(port)],
                                stdout=heard.open("w"), stderr=(workdir / "listener.err").open("w"), text=True,
                                env={**os.environ, "PYTHONPATH": f"{REPO_ROOT}{os.pathsep}{REPO_ROOT / 'tests'}"})
    box = workdir / "box.toml"
    box.write_text(f'[can]\ninterface = "socketcand"\nchannel = "vcan0"\nport = {port}\n')
    alerts = workdir / "alerts.jsonl"
    # the runtime's and the listener's output go to files, never to pipes read at the end: a
    # process whose pipe is full blocks on its next log line (a flood of python-can warnings
    # did that once: the runtime stalled for a whole outage)
    rt_out, rt_err = workdir / "wearable.out", workdir / "wearable.err"
    rt = None
    done_outages = []
    try:
        if not _wait_for(heard, "connected 1", listener, 60):
            raise RuntimeError(f"listener did not start: {heard.read_text()[-300:]}")
        # full-window decisions: one message per alert, so decided alerts and the listener's AlertSeqs
        # pair up one to one (an early alert's updates share its AlertSeq and would need their own count)
        rt = subprocess.Popen([sys.executable, "-m", "edge_runtime", "wearable", "--imu",
                               f"sim?csv={workdir / 'imu.csv'}&speed={speed:g}", "--config", str(box), "--alerts",
                               str(alerts), "--decision", "full_window", "--quiet"], stdout=rt_out.open("w"), stderr=rt_err.open("w"), text=True)
        if not _wait_for(heard, "WEARABLE_STATUS", rt, 60):
            raise RuntimeError("no heartbeat from the runtime reached the listener")
        t0 = time.monotonic()
        for start_s, length_s in sorted(outages):
            time.sleep(max(0.0, t0 + start_s - time.monotonic()))
            if rt.poll() is not None:
                break
            down = time.monotonic() - t0
            hubs[-1].stop()
            time.sleep(length_s)
            hubs.append(_Hub(workdir, port, len(hubs)))
            done_outages.append({"down_at_s": round(down, 2), "up_at_s": round(time.monotonic() - t0, 2)})
        rt.wait(timeout=minutes * 60 / speed + 120)
        time.sleep(1.0)  # the last alert's copies
    finally:
        if rt is not None and rt.poll() is None:
            rt.kill()
            rt.wait()
        listener.send_signal(signal.SIGTERM)
        try:
            listener.wait(timeout=30)
        except subprocess.TimeoutExpired:
            listener.kill()
            listener.wait()
        for h in hubs:
            h.stop()
    out, err = rt_out.read_text(), rt_err.read_text()
    listener_err = (workdir / "listener.err").read_text()
    if rt.returncode != 0:
        raise RuntimeError(f"wearable: exit {rt.returncode}: {err.strip()[-500:]}")
    decisions = [json.loads(x) for x in alerts.read_text().splitlines()]
    decided = [d for d in decisions if d["status"] in ("alert", "alert_not_sent")]
    lines = heard.read_text().splitlines()
    got = [json.loads(x) for x in lines if x.startswith("{")]
    received = {a["AlertSeq"] for a in got}
    summary = next((json.loads(x.split(" ", 1)[1]) for x in lines if x.startswith("summary ")), None)
    m = SUMMARY_LOST.search(out)
    held, late, lost = (int(g) for g in m.groups()) if m else (0, 0, 0)
    return {
        "minutes": minutes, "seed": seed, "speed": speed, "outages": done_outages,
        "decided": len(decided), "sent_at_once": sum(d["alerted"] for d in decided),
        "received": len(received), "held": held, "sent_late": late, "lost": lost,
        "unaccounted": len(decided) - len(received) - lost,
        "received_late": sorted(a["AlertSeq"] for a in got if a["TimeSinceTrigger"] > 6500),
        "received_twice": len(got) - len(received),
        "wearable_status": [x for x in lines if x.startswith(("WEARABLE_STATUS", "connected"))],
        "hubs": [next((x.split(": ", 1)[1] for x in h.log.read_text().splitlines() if x.startswith("can-hub stopped")),
                      "?") for h in hubs],
        "runtime_connect_retries_logged": err.count("Failed to connect to server"),
        "listener": summary, "listener_stderr_tail": listener_err.strip().splitlines()[-1:] if listener_err else [],
        "runtime_summary": [x.strip() for x in out.splitlines() if x.strip()],
    }


def _outage(text: str) -> tuple[float, float]:
    start, _, length = text.partition(":")
    return float(start), float(length)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--minutes", type=float, default=10)
    p.add_argument("--seed", type=int, default=11, help="the simulated drive's seed")
    p.add_argument("--speed", type=float, default=10, help="the drive streams this many times faster than real time")
    p.add_argument("--outage", type=_outage, action="append", metavar="START:LENGTH",
                   help="stop the hub START s after the first heartbeat, for LENGTH s (repeatable)")
    p.add_argument("--workdir", default="/tmp/hub_outage")
    p.add_argument("--listen", type=int, metavar="PORT", help=argparse.SUPPRESS)  # the listener process
    a = p.parse_args(argv)
    if a.listen:
        return listen(a.listen, str(DBC_PATH))
    r = measure(Path(a.workdir), a.minutes, a.seed, a.speed, a.outage or [(15.0, 3.0), (35.0, 10.0)])
    print(json.dumps(r, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
