"""Window datasets: the NPZ format, and recordings -> train/test windows.

NPZ format (docs/design.md section 7; extend, never rename)
-----------------------------------------------------------
``X``        float32 (N, 700, 3)  capture windows in m/s^2 at 100 Hz (x, y, z)
``y``        int (N,)             class index into ``classes``
``subject``  int (N,)             subject id (leave-one-subject-out groups)
``classes``  str (K,)             class names, model-output order; K need not be 6

Optional fields, validated when present (all length N):
``trial``    str (N,)             trial name ("baseline", "exp1", ...): within-subject folds
``t_s``      float (N,)           window start time in its recording (s)
``repeat``   int (N,)             1 = a detector capture of a truth event that an earlier
                                  capture already caught (e.g. the return-to-wheel motion of a
                                  long Phone call); 0 otherwise (onsets, false alarms, train windows)

Train and test windows (dissertation section 2.2.4)
---------------------------------------------------
* TRAIN = ground-truth segments: for every truth event (the five distractions
  and Other), the 700 frames from 1 s before the event's start, i.e. the window
  the detector would hand over had it triggered exactly at the start.
* TEST = what the detector captured (``detect_triggers`` + ``extract_captures``
  of edge_runtime, the same code the product runs). A capture is labelled with
  the truth event its trigger frame falls in, ``[start_s - 1 s, end_s]``
  (nearest start when several overlap), else "Other": a detector false alarm.

Detector figures as in section 2.3.1: recall = distractions (truth events other
than "Other") with at least one trigger in ``[start_s - 1, end_s]`` / all
distractions; precision = captures labelled with one of the distractions / all
captures (captures of truth "Other" motions count as false alarms, as in the
dissertation).
"""
from __future__ import annotations

import json
import os
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from edge_runtime.wearable.detector import DetectorConfig, detect_triggers, extract_captures
from edge_runtime.wearable.labels import CLASSES, OTHER

SAMPLE_RATE_HZ = 100
WINDOW_FRAMES = 700


class DataError(ValueError):
    """Bad input data. ``str(err)`` is one line naming the file and the field."""


@dataclass
class WindowSet:
    """N labelled capture windows (see the module docstring)."""

    X: np.ndarray
    y: np.ndarray
    subject: np.ndarray
    classes: list[str]
    trial: np.ndarray | None = None
    t_s: np.ndarray | None = None
    source: str = ""
    repeat: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.y)

    def subset(self, mask_or_idx) -> "WindowSet":
        pick = lambda a: None if a is None else a[mask_or_idx]  # noqa: E731
        return WindowSet(self.X[mask_or_idx], self.y[mask_or_idx], self.subject[mask_or_idx],
                         list(self.classes), pick(self.trial), pick(self.t_s), self.source, pick(self.repeat))

    def counts(self) -> dict[str, int]:
        c = np.bincount(self.y, minlength=len(self.classes))
        return {name: int(n) for name, n in zip(self.classes, c)}

    @staticmethod
    def empty(classes: Sequence[str]) -> "WindowSet":
        return WindowSet(np.zeros((0, WINDOW_FRAMES, 3), np.float32), np.zeros(0, np.int64),
                         np.zeros(0, np.int64), list(classes), np.zeros(0, dtype="<U16"), np.zeros(0))


def concat(sets: Iterable[WindowSet]) -> WindowSet:
    sets = list(sets)
    if not sets:
        raise ValueError("nothing to concatenate")
    classes = list(sets[0].classes)
    for s in sets[1:]:
        if list(s.classes) != classes:
            raise DataError(f"{s.source or 'dataset'}: field 'classes': {list(s.classes)} differs from {classes}")
    opt = lambda name: (np.concatenate([getattr(s, name) for s in sets])  # noqa: E731
                        if all(getattr(s, name) is not None for s in sets) else None)
    return WindowSet(np.concatenate([s.X for s in sets]).astype(np.float32, copy=False),
                     np.concatenate([s.y for s in sets]).astype(np.int64),
                     np.concatenate([s.subject for s in sets]).astype(np.int64),
                     classes, opt("trial"), opt("t_s"), sets[0].source, opt("repeat"))


# --------------------------------------------------------------------------- NPZ I/O

def save_npz(path: str | os.PathLike, ws: WindowSet) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    arrays = dict(X=np.asarray(ws.X, np.float32), y=np.asarray(ws.y, np.int64),
                  subject=np.asarray(ws.subject, np.int64), classes=np.asarray(list(ws.classes), dtype=str))
    if ws.trial is not None:
        arrays["trial"] = np.asarray(ws.trial, dtype=str)
    if ws.t_s is not None:
        arrays["t_s"] = np.asarray(ws.t_s, np.float64)
    if ws.repeat is not None:
        arrays["repeat"] = np.asarray(ws.repeat, np.int8)
    with open(path, "wb") as f:  # np.savez would append ".npz" to other suffixes
        np.savez_compressed(f, **arrays)
    return path


def load_npz(path: str | os.PathLike) -> WindowSet:
    """Load and validate a dataset NPZ; any problem raises :class:`DataError`."""
    p = str(path)
    if not os.path.exists(p):
        raise DataError(f"{p}: file not found")
    if os.path.isdir(p):
        raise DataError(f"{p}: is a directory, expected an .npz file")
    try:
        with np.load(p, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except (zipfile.BadZipFile, OSError, EOFError) as e:
        raise DataError(f"{p}: not a readable .npz file ({type(e).__name__}: {e})") from None
    except ValueError as e:  # object arrays need pickle: refuse them
        raise DataError(f"{p}: not a plain-array .npz file ({e})") from None
    for key in ("X", "y", "subject", "classes"):
        if key not in data:
            raise DataError(f"{p}: field '{key}': missing (file has {sorted(data)})")
    X, y, subject, classes = data["X"], data["y"], data["subject"], data["classes"]

    if classes.ndim != 1 or classes.dtype.kind not in "US" or classes.size == 0:
        raise DataError(f"{p}: field 'classes': expected a non-empty 1-D array of strings, "
                        f"got dtype {classes.dtype} shape {classes.shape}")
    classes = [str(c) for c in classes]
    if len(set(classes)) != len(classes) or any(not c for c in classes):
        raise DataError(f"{p}: field 'classes': names must be unique and non-empty, got {classes}")

    if X.ndim != 3 or X.shape[1:] != (WINDOW_FRAMES, 3):
        raise DataError(f"{p}: field 'X': expected shape (N, {WINDOW_FRAMES}, 3), got {X.shape}")
    if X.dtype.kind != "f":
        raise DataError(f"{p}: field 'X': expected float32 m/s^2, got dtype {X.dtype}")
    n = X.shape[0]
    if n == 0:
        raise DataError(f"{p}: field 'X': no windows (N = 0)")
    bad = ~np.isfinite(X).all(axis=(1, 2))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise DataError(f"{p}: field 'X': {int(bad.sum())} window(s) hold NaN or infinite values "
                        f"(first: window {i})")
    for key, arr in (("y", y), ("subject", subject)):
        if arr.ndim != 1 or arr.shape[0] != n:
            raise DataError(f"{p}: field '{key}': expected shape ({n},), got {arr.shape}")
        if arr.dtype.kind not in "iu":
            raise DataError(f"{p}: field '{key}': expected integers, got dtype {arr.dtype}")
    if y.min() < 0 or y.max() >= len(classes):
        i = int(np.flatnonzero((y < 0) | (y >= len(classes)))[0])
        raise DataError(f"{p}: field 'y': label {int(y[i])} at index {i} outside 0..{len(classes) - 1} "
                        f"({len(classes)} classes)")
    trial = data.get("trial")
    if trial is not None and (trial.ndim != 1 or trial.shape[0] != n or trial.dtype.kind not in "US"):
        raise DataError(f"{p}: field 'trial': expected {n} strings, got dtype {trial.dtype} shape {trial.shape}")
    t_s = data.get("t_s")
    if t_s is not None and (t_s.ndim != 1 or t_s.shape[0] != n or t_s.dtype.kind not in "fiu"):
        raise DataError(f"{p}: field 't_s': expected {n} numbers, got dtype {t_s.dtype} shape {t_s.shape}")
    repeat = data.get("repeat")
    if repeat is not None and (repeat.ndim != 1 or repeat.shape[0] != n or repeat.dtype.kind not in "iub"):
        raise DataError(f"{p}: field 'repeat': expected {n} 0/1 flags, got dtype {repeat.dtype} shape {repeat.shape}")
    return WindowSet(X.astype(np.float32, copy=False), y.astype(np.int64), subject.astype(np.int64),
                     classes, None if trial is None else trial.astype(str),
                     None if t_s is None else t_s.astype(np.float64), source=p,
                     repeat=None if repeat is None else repeat.astype(np.int8))


# --------------------------------------------------------------------------- recordings -> windows

@dataclass
class DetectorStats:
    """Counts behind the detector's recall and precision (section 2.3.1)."""

    distractions: int = 0
    detected: int = 0
    captures: int = 0
    captures_distraction: int = 0
    triggers: int = 0
    other_events: int = 0
    skipped_train: int = 0
    repeats: int = 0
    per_label: dict = field(default_factory=dict)  # label -> [events, detected]

    def add(self, o: "DetectorStats") -> "DetectorStats":
        for k in ("distractions", "detected", "captures", "captures_distraction", "triggers",
                  "other_events", "skipped_train", "repeats"):
            setattr(self, k, getattr(self, k) + getattr(o, k))
        for lab, (n, d) in o.per_label.items():
            a = self.per_label.setdefault(lab, [0, 0])
            a[0] += n
            a[1] += d
        return self

    @property
    def recall(self) -> float:
        return self.detected / self.distractions if self.distractions else float("nan")

    @property
    def precision(self) -> float:
        return self.captures_distraction / self.captures if self.captures else float("nan")

    @property
    def precision_per_event(self) -> float:
        """The dissertation's count: detected distractions / (detected distractions + false alarms)."""
        fa = self.captures - self.captures_distraction
        return self.detected / (self.detected + fa) if self.detected + fa else float("nan")

    def as_dict(self) -> dict:
        return {"recall": self.recall, "precision": self.precision,
                "precision_per_event": self.precision_per_event, "repeat_captures": self.repeats,
                "distractions": self.distractions,
                "detected": self.detected, "captures": self.captures,
                "captures_distraction": self.captures_distraction,
                "false_alarms": self.captures - self.captures_distraction, "triggers": self.triggers,
                "other_events": self.other_events, "skipped_train_windows": self.skipped_train,
                "recall_per_label": {k: (d / n if n else None) for k, (n, d) in sorted(self.per_label.items())}}


def _label_index(label: str, classes: Sequence[str], where: str) -> int:
    try:
        return list(classes).index(label)
    except ValueError:
        raise DataError(f"{where}: field 'label': unknown label {label!r} (classes: {', '.join(classes)})") from None


def windows_from_stream(acc: np.ndarray, events: Sequence, *, subject: int, trial: str = "",
                        classes: Sequence[str] = CLASSES, cfg: DetectorConfig = DetectorConfig(),
                        rate_hz: float = SAMPLE_RATE_HZ, source: str = "recording"
                        ) -> tuple[WindowSet, WindowSet, DetectorStats]:
    """(n, 3) m/s^2 stream at 100 Hz + truth events -> (train, test, detector stats).

    ``events``: objects with ``start_s``, ``end_s`` and ``label`` (seconds from the
    stream's first sample). Labels must be in ``classes``; "Other" must be in
    ``classes`` for detector false alarms.
    """
    acc = np.asarray(acc, dtype=np.float32)
    if acc.ndim != 2 or acc.shape[1] != 3:
        raise DataError(f"{source}: field 'acc': expected shape (n, 3), got {acc.shape}")
    if rate_hz != SAMPLE_RATE_HZ:
        raise DataError(f"{source}: field 'rate': expected {SAMPLE_RATE_HZ} Hz, got {rate_hz}")
    classes = list(classes)
    if OTHER not in classes:
        raise DataError(f"{source}: field 'classes': {OTHER!r} is needed for detector false alarms")
    other = classes.index(OTHER)
    n = len(acc)
    stats = DetectorStats()
    ev = sorted(events, key=lambda e: float(e.start_s))
    ev_idx = [_label_index(str(e.label), classes, source) for e in ev]
    starts = np.array([float(e.start_s) for e in ev])
    ends = np.array([float(e.end_s) for e in ev])

    # TRAIN: ground-truth segments, 1 s before each truth event start.
    tx, ty, tt = [], [], []
    for e, k in zip(ev, ev_idx):
        lo = int(round(float(e.start_s) * rate_hz)) - cfg.pre_frames
        if lo < 0 or lo + cfg.capture_frames > n:
            stats.skipped_train += 1
            continue
        tx.append(acc[lo:lo + cfg.capture_frames])
        ty.append(k)
        tt.append(lo / rate_hz)

    # TEST: what the detector captured.
    trig = detect_triggers(acc, cfg)
    stats.triggers = len(trig)
    trig_s = trig / rate_hz
    caps = extract_captures(acc, trig, cfg)
    cx, cy, ct, cr = [], [], [], []
    caught: set[int] = set()
    for c in caps:
        t = c.trigger_index / rate_hz
        hit = np.flatnonzero((starts - 1.0 <= t) & (t <= ends))
        j = None if hit.size == 0 else int(hit[np.argmin(np.abs(starts[hit] - t))])
        k = other if j is None else ev_idx[j]
        cx.append(c.data)
        cy.append(k)
        ct.append(c.start_index / rate_hz)
        cr.append(int(j is not None and j in caught))
        if j is not None:
            caught.add(j)
        stats.captures += 1
        stats.captures_distraction += int(k != other)
        stats.repeats += cr[-1]

    for e, k in zip(ev, ev_idx):
        if k == other:
            stats.other_events += 1
            continue
        found = bool(np.any((trig_s >= float(e.start_s) - 1.0) & (trig_s <= float(e.end_s))))
        stats.distractions += 1
        stats.detected += int(found)
        a = stats.per_label.setdefault(classes[k], [0, 0])
        a[0] += 1
        a[1] += int(found)

    def mk(xs, ys, ts, rep) -> WindowSet:
        m = len(ys)
        X = np.stack(xs).astype(np.float32) if m else np.zeros((0, cfg.capture_frames, 3), np.float32)
        return WindowSet(X, np.asarray(ys, np.int64), np.full(m, subject, np.int64), classes,
                         np.full(m, trial, dtype="<U16"), np.asarray(ts, np.float64), source,
                         np.asarray(rep, np.int8))

    return mk(tx, ty, tt, [0] * len(ty)), mk(cx, cy, ct, cr), stats


def windows_from_recording(rec, classes: Sequence[str] = CLASSES, cfg: DetectorConfig = DetectorConfig()
                           ) -> tuple[WindowSet, WindowSet, DetectorStats]:
    """A ``firmware_sim.devices.wrist.Recording`` (``acc_mps2``, ``events``, ``subject_id``, ``trial``)
    -> (train windows, test windows, detector stats)."""
    return windows_from_stream(rec.acc_mps2, rec.events, subject=int(rec.subject_id),
                               trial=str(getattr(rec, "trial", "")), classes=classes, cfg=cfg,
                               source=f"subject {rec.subject_id} trial {getattr(rec, 'trial', '')}")


def build_cohort_datasets(n_subjects: int = 20, seed: int = 0, minutes_per_trial: float = 15.0,
                          out_dir: str | os.PathLike = "data", progress: bool = True) -> dict:
    """Simulate the cohort (firmware_sim.devices.wrist) -> out_dir/train.npz, test.npz, detector.json."""
    from tqdm import tqdm

    from firmware_sim.devices.wrist import simulate_cohort  # the simulator is only needed here

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    trains, tests, stats = [], [], DetectorStats()
    recs = simulate_cohort(n_subjects=n_subjects, seed=seed, minutes_per_trial=minutes_per_trial)
    for rec in tqdm(recs, desc="simulate cohort", unit="trial", disable=not progress,
                    total=n_subjects * 6, leave=False):
        tr, te, st = windows_from_recording(rec)
        trains.append(tr)
        tests.append(te)
        stats.add(st)
    train, test = concat(trains), concat(tests)
    save_npz(out / "train.npz", train)
    save_npz(out / "test.npz", test)
    det = stats.as_dict()
    det.update(n_subjects=n_subjects, seed=seed, minutes_per_trial=minutes_per_trial,
               train_counts=train.counts(), test_counts=test.counts())
    (out / "detector.json").write_text(json.dumps(det, indent=2))
    return {"train": str(out / "train.npz"), "test": str(out / "test.npz"), "detector": det}
