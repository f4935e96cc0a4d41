"""Files of the simulated wrist IMU.

* ``imu.csv``: header ``t,ax,ay,az``; t in seconds (2 decimals), accelerations in
  m/s^2 on the wrist sensor's x, y, z axes, 100 Hz.
* ``truth.json``: ``{"sample_rate_hz": 100, "subject": {...}, "events":
  [{"start_s", "end_s", "label", ...detail}], "manoeuvres": [...]}``.
* one ``.npz`` per recording (cohort): ``acc_mps2`` float32 (n, 3), ``sample_rate_hz``,
  ``subject_id``, ``trial``, ``events_json`` and ``subject_json`` (JSON strings).
"""
from __future__ import annotations

import json
import os
from pathlib import Path

import numpy as np

from firmware_sim.devices.wrist import Event, Recording, Subject

CSV_HEADER = "t,ax,ay,az"


def write_imu_csv(rec: Recording, path: str | os.PathLike) -> None:
    t = rec.t_s
    a = np.asarray(rec.acc_mps2, dtype=np.float64)
    with open(path, "w", newline="") as f:
        f.write(CSV_HEADER + "\n")
        np.savetxt(f, np.column_stack([t, a]), fmt=["%.2f", "%.4f", "%.4f", "%.4f"], delimiter=",")


def write_truth_json(rec: Recording, path: str | os.PathLike) -> None:
    Path(path).write_text(json.dumps(rec.truth_json(), indent=1))


def write_drive(rec: Recording, out_dir: str | os.PathLike) -> tuple[Path, Path]:
    """``out_dir/imu.csv`` and ``out_dir/truth.json``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_imu_csv(rec, out / "imu.csv")
    write_truth_json(rec, out / "truth.json")
    return out / "imu.csv", out / "truth.json"


def save_recording_npz(rec: Recording, path: str | os.PathLike) -> None:
    truth = rec.truth_json()
    np.savez_compressed(
        path,
        acc_mps2=np.asarray(rec.acc_mps2, dtype=np.float32),
        sample_rate_hz=np.int64(rec.sample_rate_hz),
        subject_id=np.int64(rec.subject_id),
        trial=np.str_(rec.trial),
        events_json=np.str_(json.dumps(truth["events"])),
        subject_json=np.str_(json.dumps(truth["subject"])),
        manoeuvres_json=np.str_(json.dumps(truth["manoeuvres"])),
    )


def load_recording_npz(path: str | os.PathLike) -> Recording:
    with np.load(path, allow_pickle=False) as z:
        subj = json.loads(str(z["subject_json"]))
        return Recording(
            acc_mps2=z["acc_mps2"].astype(np.float32),
            events=[Event.from_json(e) for e in json.loads(str(z["events_json"]))],
            subject_id=int(z["subject_id"]),
            trial=str(z["trial"]),
            sample_rate_hz=int(z["sample_rate_hz"]),
            subject=Subject.from_json(subj) if "sex" in subj else None,
            manoeuvres=json.loads(str(z["manoeuvres_json"])) if "manoeuvres_json" in z.files else [],
        )
