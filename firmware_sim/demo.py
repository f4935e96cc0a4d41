"""``make demo``: the product on simulated devices with the shipped models.

1. the simulated wrist IMU records a drive of a subject the shipped model never saw
   (``python -m firmware_sim drive``);
2. the edge runtime replays it through the detector and the int8 ConvLSTM
   (``python -m edge_runtime wearable --replay``);
3. the alerts are scored against the simulator's truth, and a PNG shows the
   IMU trace with the truth, the triggers and the alerts.

No hardware and no training: only the models shipped in edge_runtime/assets.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

from .scoring import score_alerts


def _run(cmd: list[str]) -> None:
    print("$ " + " ".join(cmd[2:] if cmd[0] == sys.executable else cmd), flush=True)
    r = subprocess.run(cmd)
    if r.returncode != 0:
        raise SystemExit(f"demo: step failed ({' '.join(cmd[1:4])}, exit {r.returncode})")


def plot_trace(imu_csv: Path, truth: dict, decisions: list[dict], out_png: Path, threshold_mps2: float = 5.0) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

    data = np.loadtxt(imu_csv, delimiter=",", skiprows=1)
    t, acc = data[:, 0], data[:, 1:]
    from edge_runtime.detector import p3_series

    fig, (ax1, ax2) = plt.subplots(2, 1, figsize=(14, 6), sharex=True, height_ratios=[3, 1])
    for k, name in enumerate("xyz"):
        ax1.plot(t, acc[:, k], lw=0.6, label=f"a{name}")
    colours = {"Phone": "C0", "Texting": "C1", "TouchScreen": "C2", "Drink": "C3", "Marker": "C4", "Other": "0.6"}
    for e in truth["events"]:
        ax1.axvspan(e["start_s"], e["end_s"], color=colours.get(e["label"], "0.8"), alpha=0.15)
        ax1.text(e["start_s"], 24, e["label"], fontsize=6, rotation=90, va="top")
    for d in decisions:
        style = dict(color="red", lw=1.0) if d["alerted"] else dict(color="0.4", lw=0.8, ls="--")
        ax1.axvline(d["t_trigger_s"], **style)
        if d["alerted"]:
            ax1.annotate(d["label"], (d["t_alert_s"], -20), color="red", fontsize=7)
    ax1.set_ylim(-25, 25)
    ax1.set_ylabel("acceleration (m/s²)")
    ax1.set_title("Wrist IMU with truth (shaded), triggers (dashed) and alerts (red)")
    ax1.legend(loc="upper right", fontsize=7)
    ax2.plot(t, p3_series(acc[:, 0]), lw=0.6, color="k")
    ax2.axhline(threshold_mps2, color="red", lw=0.8)
    ax2.set_ylabel("P3 (m/s²)")
    ax2.set_xlabel("time (s)")
    fig.tight_layout()
    fig.savefig(out_png, dpi=110)
    plt.close(fig)


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m firmware_sim.demo", description=__doc__.splitlines()[0])
    ap.add_argument("--out", default="demo_out", help="directory for the recording, alerts and PNG")
    ap.add_argument("--minutes", type=float, default=5.0, help="length of the simulated drive")
    ap.add_argument("--seed", type=int, default=2026, help="seed of the simulated drive (a subject outside the training cohort)")
    args = ap.parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    py = sys.executable

    print(f"== 1. simulated wrist IMU: a {args.minutes:g}-minute drive (seed {args.seed})", flush=True)
    _run([py, "-m", "firmware_sim", "drive", "--minutes", str(args.minutes), "--seed", str(args.seed), "--out", str(out)])
    print("== 2. edge runtime: detector -> int8 ConvLSTM (onnxruntime, 1 thread) -> alert policy", flush=True)
    alerts = out / "alerts.jsonl"
    _run([py, "-m", "edge_runtime", "wearable", "--replay", str(out / "imu.csv"), "--alerts", str(alerts)])

    truth = json.loads((out / "truth.json").read_text())
    decisions = [json.loads(line) for line in alerts.read_text().splitlines() if line.strip()]
    s = score_alerts(decisions, truth["events"])
    png = out / "imu_trace.png"
    plot_trace(out / "imu.csv", truth, decisions, png)
    print("== 3. scored against the simulator's truth (event level)")
    print(
        f"  distractions {s.distractions}, alerts {s.alerts}: recall {s.recall:.2f}, precision {s.precision:.2f}, "
        f"correct class {s.label_accuracy:.2f} of matched alerts"
    )
    (out / "score.json").write_text(json.dumps(s.as_dict(), indent=2))
    print(f"  wrote {png}, {alerts}, {out / 'score.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
