"""The simulated cohort on disk, and detector figures against the simulator's truth.

``write_cohort`` simulates 20 subjects x (baseline + exp1..exp5) and writes one
``sNN_<trial>.npz`` per recording (see :mod:`firmware_sim.devices.wrist_io`) plus
``cohort.json`` (subjects, files, event counts, detector recall/precision).

Detector scoring (dissertation section 2.3.1):

* a distraction (Phone, Texting, TouchScreen, Drink, Marker) is detected when a
  trigger falls within ``[start_s - 1 s, end_s]``;
* a false alarm is a capture (``[T - 1 s, T + 6 s]`` around its trigger T) that
  overlaps no distraction: Other motions and driving manoeuvres (sharp turns
  steered hand over hand, hard braking);
* recall = detected distractions / distractions;
* precision = detected distractions / (detected distractions + false alarms),
  the dissertation's counting (1714 / (1714 + 275) = 0.86): a long distraction
  that the re-armed detector captures twice is one detected action.

Two capture-level readings are reported too: ``precision_captures`` = captures
overlapping a distraction / captures, and ``precision_trigger_in_event`` =
captures whose trigger lies in ``[start_s - 1 s, end_s]`` of a distraction /
captures (stricter: a re-armed detector can trigger just after the hand is
back on the wheel, comparing with a frame 2 s earlier).
"""
from __future__ import annotations

import json
import os
from collections import Counter
from pathlib import Path
from typing import Iterable, Iterator

import numpy as np

from edge_runtime.wearable.detector import DetectorConfig, detect_triggers
from edge_runtime.wearable.labels import DISTRACTIONS, OTHER
from firmware_sim.devices.wrist import TRIALS, Recording, make_subjects, simulate_trial
from firmware_sim.devices.wrist_io import load_recording_npz, save_recording_npz


class DetectorTally:
    """Accumulates detector figures over recordings."""

    def __init__(self, cfg: DetectorConfig = DetectorConfig()):
        self.cfg = cfg
        self.events = Counter()
        self.detected = Counter()
        self.captures = 0
        self.captures_overlap = 0
        self.captures_trigger_in = 0
        self.false_alarm_sources = Counter()

    def add(self, rec: Recording) -> None:
        fs = float(rec.sample_rate_hz)
        trig = detect_triggers(rec.acc_mps2, self.cfg) / fs
        pre, post = self.cfg.pre_frames / fs, self.cfg.post_frames / fs
        dis = [e for e in rec.events if e.label in DISTRACTIONS]
        for e in rec.events:
            key = e.label if e.label != OTHER else f"Other:{e.detail.get('kind', '?')}"
            self.events[key] += 1
            self.detected[key] += int(np.any((trig >= e.start_s - 1.0) & (trig <= e.end_s)))
        for t in trig:
            self.captures += 1
            self.captures_overlap += int(any(t - pre <= e.end_s and t + post >= e.start_s for e in dis))
            inside = [e for e in rec.events if e.start_s - 1.0 <= t <= e.end_s]
            self.captures_trigger_in += int(any(e.label in DISTRACTIONS for e in inside))
            if not any(t - pre <= e.end_s and t + post >= e.start_s for e in dis):
                if inside:
                    self.false_alarm_sources[f"Other:{inside[0].detail.get('kind', '?')}"] += 1
                else:
                    near = [m["kind"] for m in rec.manoeuvres if m["start_s"] - 2 <= t <= m["end_s"] + 3]
                    self.false_alarm_sources[f"driving:{near[0]}" if near else "driving"] += 1

    def as_dict(self) -> dict:
        n_d = sum(self.events[k] for k in DISTRACTIONS)
        n_det = sum(self.detected[k] for k in DISTRACTIONS)
        oth = [k for k in self.events if k.startswith("Other:")]
        fa = self.captures - self.captures_overlap
        return {
            "distractions": n_d,
            "detected": n_det,
            "recall": round(n_det / n_d, 4) if n_d else None,
            "captures": self.captures,
            "false_alarms": fa,
            "precision": round(n_det / (n_det + fa), 4) if n_det + fa else None,
            "precision_captures": round(self.captures_overlap / self.captures, 4) if self.captures else None,
            "precision_trigger_in_event": round(self.captures_trigger_in / self.captures, 4) if self.captures else None,
            "other_events": sum(self.events[k] for k in oth),
            "other_detected": sum(self.detected[k] for k in oth),
            "per_label": {k: {"events": self.events[k], "detected": self.detected[k]} for k in sorted(self.events)},
            "false_alarm_sources": dict(self.false_alarm_sources.most_common()),
        }


def detector_stats(recordings: Iterable[Recording], cfg: DetectorConfig = DetectorConfig()) -> dict:
    tally = DetectorTally(cfg)
    for rec in recordings:
        tally.add(rec)
    return tally.as_dict()


def recording_filename(subject_id: int, trial: str) -> str:
    return f"s{subject_id:02d}_{trial}.npz"


def write_cohort(out_dir: str | os.PathLike, n_subjects: int = 20, seed: int = 0, minutes_per_trial: float = 15.0,
                 progress: bool = True) -> dict:
    """Simulate and write the cohort; returns the ``cohort.json`` content."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    subjects = make_subjects(n_subjects, seed)
    jobs = [(s, t) for s in subjects for t in TRIALS]
    it: Iterable = jobs
    if progress:
        from tqdm import tqdm  # lazily: only the CLI shows a progress bar
        it = tqdm(jobs, desc="simulate cohort", unit="trial")
    tally = DetectorTally()
    files = []
    for subj, trial in it:
        rec = simulate_trial(subj, trial, seed, minutes_per_trial)
        name = recording_filename(subj.subject_id, trial)
        save_recording_npz(rec, out / name)
        tally.add(rec)
        counts = Counter(e.label for e in rec.events)
        files.append({"file": name, "subject_id": subj.subject_id, "trial": trial, "n_samples": len(rec.acc_mps2),
                      "events": dict(sorted(counts.items()))})
    index = {
        "sample_rate_hz": 100,
        "n_subjects": n_subjects,
        "seed": seed,
        "trial_minutes": minutes_per_trial,
        "trials": list(TRIALS),
        "npz_fields": ["acc_mps2", "sample_rate_hz", "subject_id", "trial", "events_json", "subject_json",
                       "manoeuvres_json"],
        "subjects": [s.to_json() for s in subjects],
        "recordings": files,
        "detector": tally.as_dict(),
    }
    (out / "cohort.json").write_text(json.dumps(index, indent=1))
    return index


def load_cohort(out_dir: str | os.PathLike) -> Iterator[Recording]:
    """The recordings ``write_cohort`` wrote, in index order."""
    out = Path(out_dir)
    index = json.loads((out / "cohort.json").read_text())
    for f in index["recordings"]:
        yield load_recording_npz(out / f["file"])
