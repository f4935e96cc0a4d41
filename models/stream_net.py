"""The trigger-free streaming classifier (issue 12): a small causal 1D CNN over the last W seconds.

Unlike the capture models of :mod:`models.nets` it needs no detector trigger: every hop the box averages
the 100 Hz wrist stream to 25 Hz (4 raw frames a step, a running sum on the box) and classifies the last
W s into the six classes. Session 21's prototype (reports/wearable/stream_s21/net.py) chose the layers;
this is the product's copy of that network, with the same parameter names so its checkpoint loads.

Conv1d 3->w k5, max-pool 2, w->1.5w k5, max-pool 2, 1.5w->2w k3 (ReLUs, "same" padding); the features
are the max and the mean of the last conv layer over the window (what happened in it) and the mean of
its last ``NOW_STEPS`` positions (where the hand is now); dropout 0.3; linear -> classes. Pooled over
time, so one model serves any W of at least ``MIN_STEPS`` steps (trained on 2-4 s). Width 64: 71,142
parameters.
"""
from __future__ import annotations

import numpy as np
import torch
from torch import nn

DOWN = 4
"""Raw 100 Hz frames per input step: the model reads 25 Hz."""
RAW_RATE_HZ = 100
STEP_S = DOWN / RAW_RATE_HZ
ACC_SCALE_MPS2 = 9.81
"""The input divisor the prototype trained with (not ``nets.ACC_SCALE_MPS2``'s 9.80665): the weights
expect it."""
NOW_STEPS = 3
"""'Now' features: the mean of the last 3 positions (0.24 s at the last layer's 6.25 Hz) of the last conv layer."""
MIN_STEPS = 16
"""The shortest input (25 Hz steps) the two max-pools leave a 'now' feature for."""


class StreamNet(nn.Module):
    """(N, 3, T) m/s^2 at 25 Hz, T >= ``MIN_STEPS`` -> (N, classes) logits."""

    def __init__(self, classes: int = 6, width: int = 64):
        super().__init__()
        w1, w2, w3 = width, 3 * width // 2, 2 * width
        self.conv = nn.Sequential(
            nn.Conv1d(3, w1, 5, padding=2), nn.ReLU(), nn.MaxPool1d(2),
            nn.Conv1d(w1, w2, 5, padding=2), nn.ReLU(), nn.MaxPool1d(2),
            nn.Conv1d(w2, w3, 3, padding=1), nn.ReLU())
        self.drop = nn.Dropout(0.3)
        self.head = nn.Linear(3 * w3, classes)

    @property
    def width(self) -> int:
        return self.conv[0].out_channels

    def forward(self, x25: torch.Tensor) -> torch.Tensor:
        f = self.conv(x25 / ACC_SCALE_MPS2)
        z = torch.cat([f.amax(dim=2), f.mean(dim=2), f[:, :, -NOW_STEPS:].mean(dim=2)], dim=1)
        return self.head(self.drop(z))


def to25(acc_mps2: np.ndarray) -> np.ndarray:
    """(n, 3) at 100 Hz -> (n // 4, 3) float32 at 25 Hz, each step the mean of 4 raw frames. Step j ends at
    raw frame 4 j + 3: a decision on it can go out at that frame's time."""
    acc = np.asarray(acc_mps2, dtype=np.float32)
    m = len(acc) // DOWN * DOWN
    return acc[:m].reshape(m // DOWN, DOWN, 3).mean(1)


def step_end_s(n_steps: int) -> np.ndarray:
    """The time (s from the recording's first raw frame) of each of ``n_steps`` 25 Hz steps' last raw frame:
    when a decision on the window ending at that step can go out (:func:`to25`)."""
    return (np.arange(n_steps) * DOWN + DOWN - 1) / RAW_RATE_HZ


def windows(x25: np.ndarray, ends: np.ndarray, steps: int) -> np.ndarray:
    """The windows of ``steps`` 25 Hz steps ending at (and including) each step index of ``ends`` ->
    (N, 3, steps); an end before a whole window repeats the stream's first step in front."""
    idx = ends[:, None] - np.arange(steps - 1, -1, -1)[None, :]
    return x25[np.clip(idx, 0, None)].transpose(0, 2, 1)


def width_of(state_dict: dict) -> int:
    """The width a StreamNet state dict was built with (its first conv's output channels)."""
    return int(state_dict["conv.0.weight"].shape[0])
