"""``make demo``: the product on simulated devices with the shipped models.

Live (the default), as separate processes, the way a vehicle would run it:

1. the simulated CAN bus: a socketcand hub on 127.0.0.1 (``python -m firmware_sim can-hub``);
2. an integrator's listener that knows only python-can, cantools, autosar-e2e and our DBC
   (``docs/examples/listen_alerts.py``); it prints each alert as it arrives;
3. the wrist IMU firmware streaming MAVLink HIGHRES_IMU at a real 100 Hz on a
   pseudo-terminal (``python -m firmware_sim imu``);
4. the edge runtime as shipped: serial line -> the int8 streaming classifier (a decision every 0.48 s on
   the last 4 s of the stream, ``[alerts] decision = "stream"``) -> CAN alerts and heartbeat
   (``python -m edge_runtime wearable --imu serial:PATH?unsigned=yes``).

Then the alerts are scored against the simulator's truth (event level), and a PNG
shows the IMU trace with the truth and the alerts. ``--replay`` runs
the same chain on a recording, as fast as it goes, in a few seconds.

Then the robot side, in simulated time: the dissertation's three walks past, across and
straight at a working Sawyer (chapter 3), seen by one camera at 30 Hz through the
shipped int8 lifter, with the safety runtime commanding the simulated arm over CAN and
over signed MAVLink, and the same walks without the runtime for comparison; a table and
a top-down plot (``hrc.png``). Last, chapter 4 in small: GOLA-HRC finds the work-piece
position for four simulated workers over the CAN robot link (``gola.png``).

No hardware and no training: only the models shipped in edge_runtime/assets.
"""
from __future__ import annotations

import argparse
import json
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np

from firmware_sim.scenarios.scoring import score_alerts


def _run(cmd: list[str]) -> None:
    print("$ " + " ".join(cmd[2:] if cmd[0] == sys.executable else cmd), flush=True)
    r = subprocess.run(cmd)
    if r.returncode != 0:
        raise SystemExit(f"demo: step failed ({' '.join(cmd[1:4])}, exit {r.returncode})")


def plot_trace(t, acc, events: list[dict], decisions: list[dict], out_png: Path, threshold_mps2: float = 5.0) -> None:
    """IMU trace (t s, acc (n, 3) m/s^2) with truth events shaded, alerts red at their trigger (a stream alert's:
    the first of the hops that raised it), decisions not alerted dashed; below, P3 (the capture path's detector)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from edge_runtime.wearable.detector import p3_series

    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(14, 6), sharex=True, height_ratios=[3, 1])
    for k, name in enumerate("xyz"):
        ax1.plot(t, acc[:, k], lw=0.6, label=f"a{name}")
    colours = {"Phone": "C0", "Texting": "C1", "TouchScreen": "C2", "Drink": "C3", "Marker": "C4", "Other": "0.6"}
    for e in events:
        ax1.axvspan(e["start_s"], e["end_s"], color=colours.get(e["label"], "0.8"), alpha=0.15)
        ax1.text(e["start_s"], 24, e["label"], fontsize=6, rotation=90, va="top")
    for d in decisions:
        style = dict(color="red", lw=1.0) if d["alerted"] else dict(color="0.4", lw=0.8, ls="--")
        ax1.axvline(d["t_trigger_s"], **style)
        if d["alerted"]:
            ax1.annotate(d["label"], (d["t_alert_s"], -20), color="red", fontsize=7)
    ax1.set_ylim(-25, 25)
    ax1.set_ylabel("acceleration (m/s²)")
    ax1.set_title("Wrist IMU with truth (shaded), alerts (red) and decisions not alerted (dashed), at their trigger")
    ax1.legend(loc="upper right", fontsize=7)
    ax2.plot(t, p3_series(acc[:, 0]), lw=0.6, color="k")
    ax2.axhline(threshold_mps2, color="red", lw=0.8)
    ax2.set_ylabel("P3 (m/s²), detector")
    ax2.set_xlabel("time (s)")
    fig.tight_layout()
    fig.savefig(out_png, dpi=110)
    plt.close(fig)


def _score_and_plot(out: Path, t, acc, events: list[dict], alerts: Path) -> None:
    decisions = [json.loads(line) for line in alerts.read_text().splitlines() if line.strip()]
    s = score_alerts(decisions, events)
    png = out / "imu_trace.png"
    plot_trace(t, acc, events, decisions, png)
    print("== scored against the simulator's truth (event level, by trigger: an alert counts for the distraction "
          "its trigger falls in, from 1 s before its start to its end; a stream alert's trigger is the first of the "
          "hops that raised it)")
    print(f"  distractions {s.distractions}, alerts {s.alerts}: recall {s.recall:.2f}, precision {s.precision:.2f} (by trigger), "
          f"correct class {s.label_accuracy:.2f} of matched alerts")
    (out / "score.json").write_text(json.dumps(s.as_dict(), indent=2))
    print(f"  wrote {png}, {alerts}, {out / 'score.json'}")


def run_replay(out: Path, minutes: float, seed: int) -> None:
    py = sys.executable
    print(f"== simulated wrist IMU: a {minutes:g}-minute drive (seed {seed})", flush=True)
    _run([py, "-m", "firmware_sim", "drive", "--minutes", str(minutes), "--seed", str(seed), "--out", str(out)])
    print("== edge runtime as shipped: int8 streaming classifier (onnxruntime, 1 thread; a decision every 0.48 s on the "
          "last 4 s) -> alert rule -> CAN (virtual)", flush=True)
    alerts = out / "alerts.jsonl"
    _run([py, "-m", "edge_runtime", "wearable", "--replay", str(out / "imu.csv"), "--alerts", str(alerts),
          "--can-log", str(out / "can.log")])
    truth = json.loads((out / "truth.json").read_text())
    data = np.loadtxt(out / "imu.csv", delimiter=",", skiprows=1)
    _score_and_plot(out, data[:, 0], data[:, 1:], truth["events"], alerts)


class _Procs:
    """Child processes that are always ended, whatever happens to the demo."""

    def __init__(self):
        self.procs: list[subprocess.Popen] = []

    def start(self, name: str, cmd: list[str]) -> subprocess.Popen:
        p = subprocess.Popen(cmd, stdout=subprocess.PIPE, text=True, bufsize=1)
        p.name = name
        self.procs.append(p)
        return p

    def first_line(self, p: subprocess.Popen, timeout_s: float = 30.0) -> str:
        box: list[str] = []
        th = threading.Thread(target=lambda: box.append(p.stdout.readline()), daemon=True)
        th.start()
        th.join(timeout_s)
        if not box or not box[0]:
            raise SystemExit(f"demo: {p.name} did not start (exit {p.poll()})")
        return box[0].strip()

    def stop(self, p: subprocess.Popen, timeout_s: float = 5.0) -> None:
        if p.poll() is None:
            p.send_signal(signal.SIGTERM)
            try:
                p.wait(timeout_s)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        for p in reversed(self.procs):
            self.stop(p)


def run_live(out: Path, minutes: float, seed: int) -> None:
    from edge_runtime.wearable.alerts import DBC_PATH
    from firmware_sim.devices.wrist import simulate_drive

    py = sys.executable
    listener_py = Path(__file__).resolve().parents[2] / "docs" / "examples" / "listen_alerts.py"
    if not listener_py.exists():
        raise SystemExit(f"demo: {listener_py} not found (run the demo from a clone of the repository)")
    alerts, can_log, box = out / "alerts.jsonl", out / "can.log", out / "box.toml"
    with _Procs() as procs:
        hub = procs.start("can-hub", [py, "-m", "firmware_sim", "can-hub", "--port", "0"])
        port = int(procs.first_line(hub).split()[3].rsplit(":", 1)[1])
        print(f"== 1. CAN hub (socketcand) on 127.0.0.1:{port}", flush=True)
        listener = procs.start("listener", [py, str(listener_py), "--dbc", str(DBC_PATH), "--port", str(port)])
        procs.first_line(listener)
        print("== 2. integrator's listener (python-can + cantools + autosar-e2e only) connected", flush=True)
        lines: list[str] = []

        def echo():
            for line in listener.stdout:
                lines.append(line.rstrip())
                if not line.startswith("summary"):
                    print(f"   integrator | {line.rstrip()}", flush=True)

        threading.Thread(target=echo, daemon=True).start()
        imu = procs.start("imu", [py, "-m", "firmware_sim", "imu", "--minutes", str(minutes), "--seed", str(seed),
                                  "--pty", "--linger", "1.5"])
        path = procs.first_line(imu)
        print(f"== 3. wrist IMU firmware: {minutes:g} min of driving as MAVLink at 100 Hz on {path}", flush=True)
        box.write_text(f'[can]\ninterface = "socketcand"\nchannel = "vcan0"\nhost = "127.0.0.1"\nport = {port}\n')
        print("== 4. edge runtime as shipped: serial -> int8 streaming classifier -> CAN (alerts + 10 Hz heartbeat)",
              flush=True)
        rt = subprocess.run([py, "-m", "edge_runtime", "wearable", "--imu", f"serial:{path}?unsigned=yes", "--config", str(box),
                             "--alerts", str(alerts), "--can-log", str(can_log), "--quiet",
                             "--duration", str(minutes * 60 + 3)])
        if rt.returncode != 0:
            raise SystemExit(f"demo: the runtime failed (exit {rt.returncode})")
        imu.wait(10)
        time.sleep(0.5)  # let the last frames reach the listener
        procs.stop(listener)
        time.sleep(0.2)
        summary = next((json.loads(x.split(" ", 1)[1]) for x in lines if x.startswith("summary ")), {})
        print(f"== integrator received {summary.get('alerts', '?')} alerts, {summary.get('heartbeats', '?')} heartbeats; "
              f"E2E errors {summary.get('e2e_errors', '?')}, largest heartbeat gap {summary.get('max_heartbeat_gap_ms', '?')} ms")
        (out / "integrator.json").write_text(json.dumps(summary, indent=2))
    rec = simulate_drive(minutes, seed)
    _score_and_plot(out, rec.t_s, rec.acc_mps2, [e.to_json() for e in rec.events], alerts)


def run_robot(out: Path, seed: int) -> None:
    """Chapter 3's three walks on both link types, with and without the runtime."""
    from firmware_sim.scenarios.hrc import format_table, run_dissertation

    print("\n== robot co-worker: the dissertation's three walks (simulated time) ==", flush=True)
    for link in ("can", "mavlink"):
        result = run_dissertation(link, seed)
        (out / f"hrc_{link}.json").write_text(json.dumps(result, indent=1))
        print(format_table(result), flush=True)
    from firmware_sim.scenarios.hrc import run
    from firmware_sim.scenarios.hrc_plots import plot_runs

    summary, results = run("dissertation", "can", seed, keep_results=True)
    print(f"top-down plot (Fig. 3.8): {plot_runs(results, summary, out / 'hrc.png')}")


def run_posture(out: Path, seed: int, workers: int = 4) -> None:
    """Chapter 4 in small: GOLA-HRC over the CAN robot link."""
    print("\n== posture: GOLA-HRC over the CAN robot link ==", flush=True)
    _run([sys.executable, "-m", "firmware_sim", "gola", "--cohort", str(workers), "--seed", str(seed), "--link", "can",
          "--json", str(out / "gola.json"), "--plot", str(out / "gola.png"), "--quiet"])


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m firmware_sim.scenarios.demo", description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="demo_out", help="directory for the recording, alerts, CAN log and PNG")
    ap.add_argument("--minutes", type=float, default=3.0, help="length of the simulated drive")
    ap.add_argument("--seed", type=int, default=2026, help="seed of the simulated drive (a subject outside the training cohort)")
    ap.add_argument("--replay", action="store_true", help="replay a recording as fast as possible instead of live")
    ap.add_argument("--part", choices=("all", "wearable", "robot", "posture"), default="all",
                    help="which product function to show (default: all three)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.part in ("all", "wearable"):
        (run_replay if args.replay else run_live)(out, args.minutes, args.seed)
    if args.part in ("all", "robot"):
        run_robot(out, seed=0)
    if args.part in ("all", "posture"):
        run_posture(out, seed=0)
    return 0


if __name__ == "__main__":
    sys.exit(main())
