"""Alerts through CAN hub outages, end to end: how many the wearable decided, how many a stock
listener received, how many were sent late or counted lost, and what WEARABLE_STATUS said.

A simulated drive streams live (``--imu sim?csv=...&speed=X``: the simulated IMU firmware,
time-lapsed) into ``python -m edge_runtime wearable``, which publishes on a CAN hub PROCESS
(``python -m firmware_sim can-hub``). During the run the hub process is stopped (SIGTERM) and
started again on the same port, once per ``--outage START:LENGTH`` (seconds of wall time after
the runtime's first heartbeat reached the listener). The integrator's stock-tools listener
(docs/examples/listen_alerts.py) listens on every hub lifetime (a listener does not outlive
its hub's connection, so a new one is started on each restart). Used by
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
    """One lifetime of the hub process, with the stock listener on it."""

    def __init__(self, workdir: Path, port: int, index: int):
        self.log = workdir / f"hub{index}.out"
        self.heard = workdir / f"listener{index}.out"
        self.proc = subprocess.Popen([sys.executable, "-m", "firmware_sim", "can-hub", "--port", str(port)],
                                     stdout=self.log.open("w"), stderr=subprocess.STDOUT, text=True)
        if not _wait_for(self.log, "listening", self.proc, 30):
            raise RuntimeError(f"can-hub did not start: {self.log.read_text()[-300:]}")
        self.listener = subprocess.Popen([sys.executable, "-I", str(LISTENER), "--dbc", str(DBC_PATH), "--port",
                                          str(port), "--json"], stdout=self.heard.open("w"),
                                         stderr=subprocess.PIPE, text=True)
        if not _wait_for(self.heard, "listening", self.listener, 30):
            raise RuntimeError(f"listener did not start: {self.listener.stderr.read()[-300:]}")

    def stop_hub(self) -> None:
        self.proc.send_signal(signal.SIGTERM)
        self.proc.wait(timeout=30)

    def stop_listener(self) -> dict:
        """What the listener heard: its alerts, its WEARABLE_STATUS lines, how it ended."""
        if self.listener.poll() is None:
            self.listener.send_signal(signal.SIGTERM)
        try:
            _, err = self.listener.communicate(timeout=30)
        except subprocess.TimeoutExpired:
            self.listener.kill()
            _, err = self.listener.communicate()
        lines = self.heard.read_text().splitlines()
        summary = next((json.loads(x.split(" ", 1)[1]) for x in lines if x.startswith("summary ")), None)
        return {"alerts": [json.loads(x) for x in lines if x.startswith("{")],
                "status_lines": [x for x in lines if x.startswith("WEARABLE_STATUS")],
                "summary": summary, "exit": self.listener.returncode,
                "stderr_tail": err.strip().splitlines()[-1] if err.strip() else ""}


def measure(workdir: Path, minutes: float, seed: int, speed: float, outages: list[tuple[float, float]]) -> dict:
    """One run (see the module docstring); ``outages``: (start, length) in s of wall time."""
    workdir.mkdir(parents=True, exist_ok=True)
    r = subprocess.run([sys.executable, "-m", "firmware_sim", "drive", "--minutes", str(minutes), "--seed", str(seed),
                        "--out", str(workdir)], capture_output=True, text=True, timeout=600)
    if r.returncode != 0:
        raise RuntimeError(f"firmware_sim drive: {r.stderr.strip()[-300:]}")
    port = _free_port()
    hubs = [_Hub(workdir, port, 0)]
    box = workdir / "box.toml"
    box.write_text(f'[can]\ninterface = "socketcand"\nchannel = "vcan0"\nport = {port}\n')
    alerts = workdir / "alerts.jsonl"
    rt = subprocess.Popen([sys.executable, "-m", "edge_runtime", "wearable", "--imu",
                           f"sim?csv={workdir / 'imu.csv'}&speed={speed:g}", "--config", str(box), "--alerts",
                           str(alerts), "--quiet"], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    heard = []
    try:
        if not _wait_for(hubs[0].heard, "WEARABLE_STATUS", rt, 60):
            raise RuntimeError("no heartbeat from the runtime reached the listener")
        t0 = time.monotonic()
        done_outages = []
        for start_s, length_s in sorted(outages):
            time.sleep(max(0.0, t0 + start_s - time.monotonic()))
            if rt.poll() is not None:
                break
            down = time.monotonic() - t0
            hubs[-1].stop_hub()
            time.sleep(length_s)
            hubs.append(_Hub(workdir, port, len(hubs)))
            done_outages.append({"down_at_s": round(down, 2), "up_at_s": round(time.monotonic() - t0, 2)})
        out, err = rt.communicate(timeout=minutes * 60 / speed + 120)
        time.sleep(1.0)  # the last alert's copies
    finally:
        if rt.poll() is None:
            rt.kill()
            rt.communicate()
        for h in hubs:
            heard.append(h.stop_listener())
            if h.proc.poll() is None:
                h.stop_hub()
    if rt.returncode != 0:
        raise RuntimeError(f"wearable: exit {rt.returncode}: {err.strip()[-500:]}")
    decisions = [json.loads(x) for x in alerts.read_text().splitlines()]
    decided = [d for d in decisions if d["status"] in ("alert", "alert_not_sent")]
    received = {a["AlertSeq"] for h in heard for a in h["alerts"]}
    m = SUMMARY_LOST.search(out)
    held, late, lost = (int(g) for g in m.groups()) if m else (0, 0, 0)
    return {
        "minutes": minutes, "seed": seed, "speed": speed, "outages": done_outages,
        "decided": len(decided), "sent_at_once": sum(d["alerted"] for d in decided),
        "received": len(received), "held": held, "sent_late": late, "lost": lost,
        "unaccounted": len(decided) - len(received) - lost,
        "received_twice": sum(len(h["alerts"]) for h in heard) - len(received),
        "wearable_status": [h["status_lines"] for h in heard],
        "listeners": [{"alerts": len(h["alerts"]), "exit": h["exit"], "summary": h["summary"],
                       "stderr_tail": h["stderr_tail"]} for h in heard],
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
    a = p.parse_args(argv)
    r = measure(Path(a.workdir), a.minutes, a.seed, a.speed, a.outage or [(15.0, 3.0), (35.0, 10.0)])
    print(json.dumps(r, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
