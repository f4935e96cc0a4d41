"""Session 21 (issue 12): the trigger-free streaming classifier, a small causal 1D CNN over the last W seconds.

Every hop the box would average the last W s of the 100 Hz wrist stream to 25 Hz (4 raw frames per step, what a
firmware can do with a running sum) and classify the window into the six classes. The network is length-agnostic
(its features are pooled over time), so one model is trained on windows of 2-4 s and W is chosen on development
drive seed 1.

Features: the max and the mean of the last conv layer over the window (what happened in it), plus the mean of its
last 3 positions (0.24 s: where the hand is now). No hand-made feature: the input is the raw 3-axis acceleration,
scaled by g.
"""
from __future__ import annotations

import numpy as np
import torch
import torch.nn as nn

DOWN = 4
"""Raw 100 Hz frames per input step: 25 Hz."""
STEP_S = DOWN / 100.0
G_MPS2 = 9.81
NOW_STEPS = 3
"""'Now' features: the mean of the last 3 positions of the last conv layer."""


class StreamNet(nn.Module):
    def __init__(self, classes: int = 6, width: int = 32):
        super().__init__()
        w1, w2, w3 = width, 3 * width // 2, 2 * width
        self.conv = nn.Sequential(
            nn.Conv1d(3, w1, 5, padding=2), nn.ReLU(), nn.MaxPool1d(2),
            nn.Conv1d(w1, w2, 5, padding=2), nn.ReLU(), nn.MaxPool1d(2),
            nn.Conv1d(w2, w3, 3, padding=1), nn.ReLU())
        self.drop = nn.Dropout(0.3)
        self.head = nn.Linear(3 * w3, classes)

    def forward(self, x25: torch.Tensor) -> torch.Tensor:
        """(N, 3, T) m/s^2 at 25 Hz, T >= 16 -> (N, classes) logits."""
        f = self.conv(x25 / G_MPS2)
        z = torch.cat([f.amax(dim=2), f.mean(dim=2), f[:, :, -NOW_STEPS:].mean(dim=2)], dim=1)
        return self.head(self.drop(z))


def params(model: nn.Module) -> int:
    return sum(p.numel() for p in model.parameters())


def to25(acc_mps2: np.ndarray) -> np.ndarray:
    """(n, 3) at 100 Hz -> (n // 4, 3) at 25 Hz, each step the mean of 4 raw frames (float32). Step j ends at raw
    frame 4 j + 3: its decision can go out at that frame's time, (4 j + 3) / 100 s."""
    m = len(acc_mps2) // DOWN * DOWN
    return acc_mps2[:m].reshape(m // DOWN, DOWN, 3).mean(1).astype(np.float32)


def windows(x25: np.ndarray, ends: np.ndarray, steps: int) -> np.ndarray:
    """The windows of ``steps`` 25 Hz steps ending at (and including) each step index in ``ends`` -> (N, 3, steps);
    ends before the stream holds a whole window repeat its first step in front (the box's start-up)."""
    idx = ends[:, None] - np.arange(steps - 1, -1, -1)[None, :]
    return x25[np.clip(idx, 0, None)].transpose(0, 2, 1)


def load(path: str) -> tuple[StreamNet, dict]:
    ck = torch.load(path, map_location="cpu", weights_only=False)
    model = StreamNet(width=ck["width"])
    model.load_state_dict(ck["state"])
    model.eval()
    return model, ck
