"""What a target checks at the model and command boundary: the wearable loop with a
classifier that refuses (SilentAcceptance) any capture with a value outside the sensor range."""
from __future__ import annotations

from typing import Iterable

import numpy as np

from edge_runtime.wearable.labels import CLASSES
from edge_runtime.wearable.loop import WearableLoop
from edge_runtime.wearable.sources import ImuBlock, ImuParams
from fuzz.harness import SilentAcceptance

RANGE_MPS2 = ImuParams().range_mps2


class RangeProbeClassifier:
    """Stands in for the int8 model: every capture must be finite and within ``range_mps2``."""

    classes = CLASSES

    def __init__(self, range_mps2: float = RANGE_MPS2):
        self.range_mps2 = range_mps2
        self.captures = 0

    def classify_capture(self, x700: np.ndarray) -> np.ndarray:
        x = np.asarray(x700, dtype=np.float32)
        if not np.isfinite(x).all():
            raise SilentAcceptance(f"a non-finite value reached the model ({int((~np.isfinite(x)).sum())} values)")
        peak = float(np.abs(x).max())
        if peak > self.range_mps2:
            raise SilentAcceptance(f"{peak:.4g} m/s^2 reached the model (sensor range {self.range_mps2} m/s^2)")
        self.captures += 1
        return np.full(len(self.classes), 1.0 / len(self.classes), dtype=np.float32)


def through_loop(blocks: Iterable[ImuBlock], range_mps2: float = RANGE_MPS2) -> RangeProbeClassifier:
    """Every block through a WearableLoop whose model is the range probe."""
    probe = RangeProbeClassifier(range_mps2)
    loop = WearableLoop(probe)
    for block in blocks:
        loop.feed(block)
    return probe
