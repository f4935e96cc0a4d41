"""The wearable loop: IMU samples -> detector -> capture -> classifier -> alert policy.

In the shape of TFLite Micro's magic_wand: a data provider (``sources``) hands
over blocks of 100 Hz samples, the model (``engine``) classifies each capture
the detector completes, and an output handler (``on_decision``: the alert
log, the CAN publisher) receives every decision.

Bad samples never stop the loop: non-finite samples are counted and the
detector restarts after them (its window must not span a hole), and a block
that does not continue the previous one (a gap) restarts it too.
"""
from __future__ import annotations

import time
from collections import Counter
from dataclasses import asdict, dataclass, field
from typing import Callable, Protocol, Sequence

import numpy as np

from edge_runtime.wearable.detector import Capture, DetectorConfig, StreamingDetector
from edge_runtime.wearable.labels import OTHER
from edge_runtime.wearable.preprocess import preprocess
from edge_runtime.wearable.sources import SAMPLE_RATE_HZ, ImuBlock


class Classifier(Protocol):
    classes: Sequence[str]

    def classify(self, x: np.ndarray) -> np.ndarray:
        """(N, 6, 33, 3) m/s^2 -> (N, K) class probabilities."""


@dataclass(frozen=True)
class AlertPolicy:
    min_confidence: float = 0.6
    """Below this top-class probability a decision is 'uncertain' and not alerted."""
    never_alert: tuple[str, ...] = (OTHER,)
    """Classes that are logged but never alerted (non-coupled hand motions)."""

    def __post_init__(self) -> None:
        if not 0.0 <= self.min_confidence <= 1.0:
            raise ValueError("min_confidence must lie in [0, 1]")

    def status(self, label: str, confidence: float) -> str:
        if label in self.never_alert:
            return "not_alerted"
        if confidence < self.min_confidence:
            return "uncertain"
        return "alert"


@dataclass
class Decision:
    t_trigger_s: float
    """Stream time of the detector's trigger frame (s)."""
    t_alert_s: float
    """Stream time of the capture's last sample, when the decision could be made (s)."""
    label: str
    confidence: float
    alerted: bool
    status: str
    """'alert', 'uncertain' (below the confidence threshold) or 'not_alerted' (e.g. Other)."""
    probs: dict[str, float]
    compute_us: float
    """Wall time from the completed capture to the decision (preprocess + inference), microseconds."""
    rx_monotonic_s: float | None = None
    """Host ``time.monotonic()`` when the capture's last sample arrived (live sources only)."""
    latency_ms: float | None = None
    """Set by whoever sends the alert: arrival of the capture's last sample -> frame handed to the bus."""

    def to_json(self) -> dict:
        d = asdict(self)
        del d["rx_monotonic_s"]  # host clock, meaningless outside this process
        if d["latency_ms"] is not None:
            d["latency_ms"] = round(d["latency_ms"], 3)
        d["probs"] = {k: round(v, 5) for k, v in self.probs.items()}
        d["confidence"] = round(self.confidence, 5)
        d["compute_us"] = round(self.compute_us, 1)
        return d


@dataclass
class LoopStats:
    samples: int = 0
    non_finite: int = 0
    detector_resets: int = 0
    captures: int = 0
    statuses: Counter = field(default_factory=Counter)
    labels: Counter = field(default_factory=Counter)


class WearableLoop:
    def __init__(
        self,
        classifier: Classifier,
        detector: DetectorConfig = DetectorConfig(),
        policy: AlertPolicy = AlertPolicy(),
        on_decision: Callable[[Decision], None] | None = None,
        sample_rate_hz: int = SAMPLE_RATE_HZ,
    ):
        self.classifier = classifier
        self.classes = list(classifier.classes)
        self.policy = policy
        self.detector = StreamingDetector(detector)
        self.on_decision = on_decision
        self.rate_hz = sample_rate_hz
        self.stats = LoopStats()
        self._seg_index0 = 0  # detector index of the current continuous stretch ...
        self._seg_t0 = 0.0  # ... and its stream time
        self._rx: float | None = None  # arrival time of the block being fed

    def _time_of(self, index: int) -> float:
        return self._seg_t0 + (index - self._seg_index0) / self.rate_hz

    def _restart(self, t0_s: float) -> None:
        if self.detector.n_seen:
            self.detector.reset()
            self.stats.detector_resets += 1
        self._seg_index0, self._seg_t0 = self.detector.n_seen, t0_s

    def feed(self, block: ImuBlock) -> list[Decision]:
        acc = np.asarray(block.acc_mps2, dtype=np.float32).reshape(-1, 3)
        if not block.continuous or self.stats.samples == 0:
            self._restart(block.t0_s)
        self._rx = block.rx_monotonic_s
        self.stats.samples += len(acc)
        bad = ~np.isfinite(acc).all(axis=1)
        if not bad.any():
            return self._push(acc)
        decisions: list[Decision] = []
        self.stats.non_finite += int(bad.sum())
        # Split at runs of bad samples: push the good runs, restart after each bad run.
        edges = np.flatnonzero(np.diff(np.r_[False, bad, False].astype(np.int8)))
        good_start = 0
        for a, b in zip(edges[::2], edges[1::2]):
            decisions += self._push(acc[good_start:a])
            self.detector.skip(b - a)  # the hole keeps its place in stream time
            self.stats.detector_resets += 1
            self._seg_index0, self._seg_t0 = self.detector.n_seen, block.t0_s + b / self.rate_hz
            good_start = b
        decisions += self._push(acc[good_start:])
        return decisions

    def _push(self, acc: np.ndarray) -> list[Decision]:
        return [self._decide(c) for c in self.detector.push(acc)] if len(acc) else []

    def _decide(self, cap: Capture) -> Decision:
        t_start = time.perf_counter()
        probs = np.asarray(self.classifier.classify(preprocess(cap.data)[None]))[0]
        compute_us = (time.perf_counter() - t_start) * 1e6
        k = int(np.argmax(probs))
        label, conf = self.classes[k], float(probs[k])
        status = self.policy.status(label, conf)
        d = Decision(
            t_trigger_s=round(self._time_of(cap.trigger_index), 3),
            t_alert_s=round(self._time_of(cap.start_index + len(cap.data) - 1), 3),
            label=label,
            confidence=conf,
            alerted=status == "alert",
            status=status,
            probs={c: float(p) for c, p in zip(self.classes, probs)},
            compute_us=compute_us,
            rx_monotonic_s=self._rx,
        )
        self.stats.captures += 1
        self.stats.statuses[status] += 1
        self.stats.labels[label] += 1
        if self.on_decision is not None:
            self.on_decision(d)
        return d
