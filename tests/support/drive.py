"""Detector captures of a simulated drive: real motions, real gravity."""
from __future__ import annotations

import numpy as np


def drive_captures(minutes: float = 6.0, seed: int = 3) -> np.ndarray:
    """Every detector capture of a simulated drive (N, 700, 3)."""
    from edge_runtime.wearable.detector import StreamingDetector
    from firmware_sim.devices.wrist import simulate_drive

    acc = np.ascontiguousarray(simulate_drive(minutes, seed=seed).acc_mps2, dtype=np.float32)
    return np.stack([c.data for c in StreamingDetector().push(acc)])
