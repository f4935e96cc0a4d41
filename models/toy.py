"""Small synthetic data for tests and examples (not the simulator: see firmware_sim.devices.wrist).

``toy_windows``: separable capture windows, one waveform per class on top of
gravity and noise. ``toy_stream``: a 100 Hz wrist stream with step-like hand
motions at known times, big enough on x to trip the detector.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from models.dataset import WindowSet

G = 9.80665


def toy_windows(n_per_class: int = 20, n_classes: int = 3, n_subjects: int = 3, seed: int = 0,
                classes: list[str] | None = None) -> WindowSet:
    rng = np.random.default_rng(seed)
    classes = classes or [f"C{k}" for k in range(n_classes)]
    t = np.arange(700) / 100.0
    xs, ys = [], []
    for k in range(len(classes)):
        for _ in range(n_per_class):
            x = np.zeros((700, 3))
            x[:, 2] = G
            on = 1.0 + rng.uniform(0, 0.3)
            env = np.clip((t - on) * 2, 0, 1) * np.clip((on + 4 - t) * 2, 0, 1)
            axis = k % 3
            freq = 0.4 + 0.6 * (k // 3)
            x[:, axis] += 6.0 * env * np.sin(2 * np.pi * freq * (t - on))
            x += rng.normal(scale=0.3, size=x.shape)
            xs.append(x)
            ys.append(k)
    n = len(ys)
    subject = np.arange(n) % n_subjects
    trial = np.array([f"exp{1 + (i // n_subjects) % 2}" for i in range(n)])
    return WindowSet(np.asarray(xs, np.float32), np.asarray(ys, np.int64), subject.astype(np.int64),
                     list(classes), trial, np.zeros(n), source="toy")


@dataclass
class ToyEvent:
    start_s: float
    end_s: float
    label: str
    detail: str = ""


@dataclass
class ToyRecording:
    acc_mps2: np.ndarray
    events: list
    subject_id: int = 0
    trial: str = "exp1"


def toy_stream(events: list[tuple[float, float, str]], seconds: float = 120.0, seed: int = 0,
               false_alarms: list[float] = (), subject_id: int = 0) -> ToyRecording:
    """Stream whose x axis rises by 8 m/s^2 0.3 s after each event start and falls back at the end;
    ``false_alarms``: times of extra, unlabelled motions."""
    rng = np.random.default_rng(seed)
    n = int(seconds * 100)
    acc = np.zeros((n, 3), np.float32)
    acc[:, 2] = G
    t = np.arange(n) / 100.0
    for s, e, _ in events:
        acc[:, 0] += 8.0 * ((t >= s + 0.3) & (t < e))
    for s in false_alarms:
        acc[:, 0] += 8.0 * ((t >= s) & (t < s + 1.0))
    acc += rng.normal(scale=0.1, size=acc.shape).astype(np.float32)
    return ToyRecording(acc, [ToyEvent(s, e, lab) for s, e, lab in events], subject_id)
