"""A user's own recording + event list -> dataset NPZ, through the product's detector.

    python -m models import --csv REC.csv --events EVENTS.csv --subject K --out OUT.npz [--split train|test]

Stream CSV: header ``t,ax,ay,az`` (seconds; m/s^2 on the wrist's x, y, z), one
sample per line, constant rate of at least 100 Hz (timestamps strictly
increasing, every step within 10 % of the median). A faster stream is
resampled to 100 Hz with scipy's anti-aliased polyphase resampler.

Events: CSV with header ``start_s,end_s,label`` (further columns are ignored),
or a ``truth.json`` as ``python -m firmware_sim drive`` writes it
(``{"events": [{"start_s", "end_s", "label", ...}]}``). Times are on the
stream's clock (the ``t`` column). Labels must be among the classes (default:
Phone, Texting, TouchScreen, Drink, Marker, Other; ``--classes`` for your own
set; "Other" is appended if missing, since detector false alarms need it).

``--split train``: one window per event from 1 s before its start (ground
truth); ``--split test`` (default): the detector's captures, labelled by the
event their trigger falls in, else Other. ``--append`` adds to an existing NPZ
(one NPZ can hold many subjects and recordings).

Any problem raises :class:`models.dataset.DataError` with one line naming the
file and the line or field.
"""
from __future__ import annotations

import csv
import json
import math
import os
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import Sequence

import numpy as np

from edge_runtime.wearable.labels import CLASSES, OTHER
from models.dataset import SAMPLE_RATE_HZ, DataError, WindowSet, concat, load_npz, save_npz, windows_from_stream

STREAM_HEADER = ["t", "ax", "ay", "az"]
EVENT_HEADER = ["start_s", "end_s", "label"]
RATE_TOLERANCE = 0.10


@dataclass(frozen=True)
class Event:
    start_s: float
    end_s: float
    label: str
    line: int = 0


def _open_text(path: str):
    if not os.path.exists(path):
        raise DataError(f"{path}: file not found")
    if os.path.isdir(path):
        raise DataError(f"{path}: is a directory")
    return open(path, newline="", encoding="utf-8-sig")


def _float(cell: str, where: str, col: str) -> float:
    """``where``: "FILE: line N" or "FILE: events[i]"."""
    try:
        v = float(cell)
    except (TypeError, ValueError):
        raise DataError(f"{where}: field '{col}': not a number: {cell!r}") from None
    if not math.isfinite(v):
        raise DataError(f"{where}: field '{col}': {cell.strip()} (NaN or infinite)")
    return v


def read_stream_csv(path: str) -> tuple[np.ndarray, np.ndarray]:
    """(t (n,), acc (n, 3)) from a ``t,ax,ay,az`` CSV; validated line by line."""
    with _open_text(path) as f:
        rows = csv.reader(f)
        header = next(rows, None)
        if header is None:
            raise DataError(f"{path}: line 1: empty file, expected header {','.join(STREAM_HEADER)}")
        if [h.strip() for h in header] != STREAM_HEADER:
            raise DataError(f"{path}: line 1: header {','.join(header)!r}, expected {','.join(STREAM_HEADER)}")
        data = []
        for ln, row in enumerate(rows, start=2):
            if not row or all(not c.strip() for c in row):
                continue
            if len(row) != 4:
                raise DataError(f"{path}: line {ln}: expected 4 fields (t,ax,ay,az), got {len(row)}")
            data.append([_float(c, f"{path}: line {ln}", name) for c, name in zip(row, STREAM_HEADER)])
    if len(data) < 2:
        raise DataError(f"{path}: field 't': need at least 2 samples, got {len(data)}")
    a = np.asarray(data, dtype=np.float64)
    return a[:, 0], a[:, 1:]


def stream_rate(t: np.ndarray, path: str) -> float:
    """The constant sample rate of timestamps ``t`` (Hz), or a DataError naming the offending line."""
    dt = np.diff(t)
    bad = np.flatnonzero(dt <= 0)
    if bad.size:
        i = int(bad[0]) + 1
        raise DataError(f"{path}: line {i + 2}: field 't': {t[i]} does not increase (previous {t[i - 1]})")
    med = float(np.median(dt))
    off = np.flatnonzero(np.abs(dt - med) > RATE_TOLERANCE * med)
    if off.size:
        i = int(off[0]) + 1
        raise DataError(f"{path}: line {i + 2}: field 't': step {dt[i - 1]:.6g} s differs from the median "
                        f"{med:.6g} s (gap or jitter); the stream must have a constant rate")
    rate = (len(t) - 1) / (t[-1] - t[0])
    if rate < SAMPLE_RATE_HZ * 0.99:
        raise DataError(f"{path}: field 't': sample rate {rate:.2f} Hz, need at least {SAMPLE_RATE_HZ} Hz")
    return float(rate)


def to_100hz(acc: np.ndarray, rate: float) -> np.ndarray:
    """Resample an (n, 3) stream at ``rate`` Hz to 100 Hz (no-op within 1 % of 100 Hz)."""
    if abs(rate - SAMPLE_RATE_HZ) <= 0.01 * SAMPLE_RATE_HZ:
        return acc.astype(np.float32)
    from scipy.signal import resample_poly

    frac = Fraction(SAMPLE_RATE_HZ / rate).limit_denominator(1000)
    return resample_poly(acc, frac.numerator, frac.denominator, axis=0, padtype="line").astype(np.float32)


def read_events(path: str) -> list[Event]:
    """Events from a ``start_s,end_s,label`` CSV or a truth.json."""
    if path.lower().endswith(".json"):
        with _open_text(path) as f:
            try:
                doc = json.load(f)
            except json.JSONDecodeError as e:
                raise DataError(f"{path}: line {e.lineno}: not valid JSON ({e.msg})") from None
        items = doc.get("events") if isinstance(doc, dict) else None
        if not isinstance(items, list):
            raise DataError(f"{path}: field 'events': missing or not a list")
        out = []
        for i, e in enumerate(items):
            where = f"{path}: events[{i}]"
            if not isinstance(e, dict) or not {"start_s", "end_s", "label"} <= set(e):
                raise DataError(f"{where}: needs fields start_s, end_s, label")
            out.append(Event(_float(str(e["start_s"]), where, "start_s"), _float(str(e["end_s"]), where, "end_s"),
                             str(e["label"]), i))
        return out
    with _open_text(path) as f:
        rows = csv.reader(f)
        header = next(rows, None)
        if header is None or [h.strip() for h in header[:3]] != EVENT_HEADER:
            raise DataError(f"{path}: line 1: header {','.join(header or [])!r}, expected "
                            f"{','.join(EVENT_HEADER)}")
        out = []
        for ln, row in enumerate(rows, start=2):
            if not row or all(not c.strip() for c in row):
                continue
            if len(row) < 3:
                raise DataError(f"{path}: line {ln}: expected fields start_s,end_s,label, got {len(row)}")
            where = f"{path}: line {ln}"
            out.append(Event(_float(row[0], where, "start_s"), _float(row[1], where, "end_s"), row[2].strip(), ln))
    return out


def check_events(events: Sequence[Event], classes: Sequence[str], t0: float, t1: float, path: str) -> None:
    for e in events:
        where = f"{path}: line {e.line}" if not path.lower().endswith(".json") else f"{path}: events[{e.line}]"
        if e.label not in classes:
            raise DataError(f"{where}: field 'label': unknown label {e.label!r} (classes: {', '.join(classes)})")
        if e.end_s < e.start_s:
            raise DataError(f"{where}: field 'end_s': {e.end_s} is before start_s {e.start_s}")
        if e.start_s < t0 or e.end_s > t1:
            fld = "start_s" if e.start_s < t0 else "end_s"
            raise DataError(f"{where}: field '{fld}': event {e.start_s}-{e.end_s} s lies outside the stream "
                            f"({t0}-{t1} s)")


def import_recording(csv_path: str, events_path: str, subject: int, *, split: str = "test",
                     classes: Sequence[str] = CLASSES, trial: str = "") -> tuple[WindowSet, dict]:
    """Stream CSV + events -> (windows of ``split``, info dict)."""
    if split not in ("train", "test"):
        raise DataError(f"--split: expected train or test, got {split!r}")
    classes = list(classes)
    if OTHER not in classes:
        classes.append(OTHER)
    t, acc = read_stream_csv(csv_path)
    rate = stream_rate(t, csv_path)
    events = read_events(events_path)
    check_events(events, classes, float(t[0]), float(t[-1]), events_path)
    acc100 = to_100hz(acc, rate)
    shifted = [Event(e.start_s - t[0], e.end_s - t[0], e.label, e.line) for e in events]
    train, test, stats = windows_from_stream(acc100, shifted, subject=int(subject), trial=trial or Path(csv_path).stem,
                                             classes=classes, source=csv_path)
    ws = train if split == "train" else test
    ws.t_s = ws.t_s + float(t[0])
    info = {"rate_hz": rate, "resampled": abs(rate - SAMPLE_RATE_HZ) > 1.0, "samples": int(len(t)),
            "events": len(events), "windows": len(ws), "counts": ws.counts(), "detector": stats.as_dict()}
    return ws, info


def import_to_npz(csv_path: str, events_path: str, subject: int, out: str, *, split: str = "test",
                  classes: Sequence[str] = CLASSES, append: bool = False, trial: str = "") -> dict:
    ws, info = import_recording(csv_path, events_path, subject, split=split, classes=classes, trial=trial)
    if append and os.path.exists(out):
        old = load_npz(out)
        if old.trial is None:
            ws.trial = None
        if old.t_s is None:
            ws.t_s = None
        ws = concat([old, ws])
    if len(ws) == 0:
        raise DataError(f"{csv_path}: no {split} windows (no events inside the stream's capture range"
                        f"{'' if split == 'train' else ' and no detector triggers'})")
    save_npz(out, ws)
    info["out"] = out
    info["total_windows"] = len(ws)
    return info
