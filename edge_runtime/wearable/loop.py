"""The wearable loop: IMU samples -> detector -> capture -> classifier -> alert policy -> publisher.

In the shape of TFLite Micro's magic_wand: a data provider (``sources``,
``mavlink_source``) hands over blocks of 100 Hz samples, the model (``classifier``)
classifies each capture the detector completes, and the alert policy says what the
result is worth. Calls go one way: the loop calls the detector, the classifier and
the publisher, and none of them calls back.

Every decision is complete when it is made. A would-alert :class:`Verdict` is handed
to the publisher (``alerts.AlertPublisher.publish_alert``), which answers with the
AlertSeq its DISTRACTION_ALERT frames carry, or that none went out; only then is the :class:`Decision` built, once, and
:meth:`WearableLoop.feed` returns it. Output handlers (the alert log, the console,
``on_decision``) only read it.

Bad samples never stop the loop: non-finite samples are counted and the
detector restarts after them (its window must not span a hole), and a block
that does not continue the previous one (a gap) restarts it too. The counts go
to the publisher's :class:`~edge_runtime.wearable.alerts.WearableStatus`, which the
heartbeat reports.
"""
from __future__ import annotations

import time
from collections import Counter
from dataclasses import asdict, dataclass, field
from typing import Callable, Protocol, Sequence

import numpy as np

from edge_runtime import config
from edge_runtime.wearable.alerts import AlertPublisher, WearableStatus
from edge_runtime.wearable.detector import Capture, DetectorConfig, StreamingDetector
from edge_runtime.wearable.labels import CLASSES, OTHER
from edge_runtime.wearable.sources import SAMPLE_RATE_HZ, ImuBlock


class Classifier(Protocol):
    classes: Sequence[str]

    def classify_capture(self, x700: np.ndarray) -> np.ndarray:
        """A detector capture (700, 3) m/s^2 at 100 Hz -> (K,) class probabilities."""


@config.section("alerts")
@dataclass(frozen=True)
class AlertPolicy:
    """Which classifier decisions become a DISTRACTION_ALERT."""

    min_confidence: float = config.setting(0.6, config.PROBABILITY)
    """Below this top-class probability a decision is 'uncertain' and not alerted."""
    never_alert: tuple[str, ...] = (OTHER,)
    """Classes that are logged but never alerted (non-coupled hand motions)."""

    def __post_init__(self) -> None:
        if not 0.0 <= self.min_confidence <= 1.0:
            raise ValueError("min_confidence must lie in [0, 1]")
        if set(CLASSES) <= set(self.never_alert):
            raise ValueError(f"never_alert: {list(self.never_alert)} holds every class; nothing would ever be alerted")

    def status(self, label: str, confidence: float) -> str:
        if label in self.never_alert:
            return "not_alerted"
        if confidence < self.min_confidence:
            return "uncertain"
        return "alert"


@dataclass
class Verdict:
    """What the classifier and the alert policy made of one capture, before anything was sent."""

    t_trigger_s: float
    """Stream time of the detector's trigger frame (s)."""
    t_alert_s: float
    """Stream time of the capture's last sample, when the decision could be made (s)."""
    label: str
    confidence: float
    status: str
    """'alert', 'uncertain' (below the confidence threshold) or 'not_alerted' (e.g. Other); a
    :class:`Decision` whose alert did not go out says 'alert_not_sent'."""
    probs: dict[str, float]
    compute_us: float
    """Wall time from the completed capture to the verdict (preprocessing + inference), microseconds."""
    rx_monotonic_s: float | None = None
    """Host ``time.monotonic()`` when the capture's last sample arrived (live sources only)."""


@dataclass(kw_only=True)
class Decision(Verdict):
    """A verdict and what became of it; made once, never changed afterwards."""

    alerted: bool
    """A DISTRACTION_ALERT went out for it (for a loop without a publisher: the policy says 'alert')."""
    latency_ms: float | None = None
    """Arrival of the capture's last sample -> its frame handed to the bus (sent alerts of live sources)."""
    alert_seq: int | None = None
    """The AlertSeq its DISTRACTION_ALERT frames carry (None: no frame went out for it)."""

    @classmethod
    def made(cls, verdict: Verdict, alerted: bool, status: str | None = None,
             latency_ms: float | None = None, alert_seq: int | None = None) -> "Decision":
        return cls(**{**asdict(verdict), "status": status or verdict.status}, alerted=alerted, latency_ms=latency_ms,
                   alert_seq=alert_seq)

    def to_json(self) -> dict:
        """One line of ``--alerts`` (the host clock ``rx_monotonic_s`` means nothing outside this process)."""
        return {"t_trigger_s": self.t_trigger_s, "t_alert_s": self.t_alert_s, "label": self.label,
                "confidence": round(self.confidence, 5), "alerted": self.alerted, "status": self.status,
                "probs": {k: round(v, 5) for k, v in self.probs.items()}, "compute_us": round(self.compute_us, 1),
                "latency_ms": None if self.latency_ms is None else round(self.latency_ms, 3),
                "alert_seq": self.alert_seq}


@dataclass
class LoopStats:
    """What the loop decided (the sample counts are the status's: :class:`WearableStatus`)."""

    captures: int = 0
    statuses: Counter = field(default_factory=Counter)
    """Per policy status ('alert', 'uncertain', 'not_alerted')."""
    labels: Counter = field(default_factory=Counter)


class WearableLoop:
    """``feed(block)`` -> the decisions completed in it.

    With a ``publisher``, a would-alert verdict is sent through it and its sample counts
    go to ``publisher.status``; without one (offline evaluation) nothing is sent and
    ``status`` is the loop's own. ``on_decision`` is called with every decision once it
    is made (an output handler: it only reads it)."""

    def __init__(
        self,
        classifier: Classifier,
        detector: DetectorConfig = DetectorConfig(),
        policy: AlertPolicy = AlertPolicy(),
        on_decision: Callable[[Decision], None] | None = None,
        sample_rate_hz: int = SAMPLE_RATE_HZ,
        publisher: AlertPublisher | None = None,
    ):
        self.classifier = classifier
        self.classes = list(classifier.classes)
        self.policy = policy
        self.detector = StreamingDetector(detector)
        self.on_decision = on_decision
        self.rate_hz = sample_rate_hz
        self.publisher = publisher
        self.status = publisher.status if publisher is not None else WearableStatus()
        self.stats = LoopStats()
        self._seg_index0 = 0  # detector index of the current continuous stretch ...
        self._seg_t0 = 0.0  # ... and its stream time
        self._rx: float | None = None  # arrival time of the block being fed

    def _time_of(self, index: int) -> float:
        return self._seg_t0 + (index - self._seg_index0) / self.rate_hz

    def _restart(self, t0_s: float) -> None:
        if self.detector.n_seen:
            self.detector.reset()
            self.status.count_detector_restart()
        self._seg_index0, self._seg_t0 = self.detector.n_seen, t0_s

    def feed(self, block: ImuBlock) -> list[Decision]:
        acc = np.asarray(block.acc_mps2, dtype=np.float32).reshape(-1, 3)
        if not block.continuous or self.detector.n_seen == 0:  # nothing fed yet, or a gap
            self._restart(block.t0_s)
        self._rx = block.rx_monotonic_s
        finite = np.isfinite(acc)
        if finite.all():  # the common case, one reduction: the 100 Hz loop's per-sample cost
            self.status.count_samples(len(acc))
            return self._push(acc)
        bad = ~finite.all(axis=1)
        self.status.count_samples(len(acc), non_finite=int(bad.sum()))
        decisions: list[Decision] = []
        # Split at runs of bad samples: push the good runs, restart after each bad run.
        edges = np.flatnonzero(np.diff(np.r_[False, bad, False].astype(np.int8)))
        good_start = 0
        for a, b in zip(edges[::2], edges[1::2]):
            decisions += self._push(acc[good_start:a])
            self.detector.skip(b - a)  # the hole keeps its place in stream time
            self.status.count_detector_restart()
            self._seg_index0, self._seg_t0 = self.detector.n_seen, block.t0_s + b / self.rate_hz
            good_start = b
        decisions += self._push(acc[good_start:])
        return decisions

    def _push(self, acc: np.ndarray) -> list[Decision]:
        return [self._decide(c) for c in self.detector.push(acc)] if len(acc) else []

    def _decide(self, cap: Capture) -> Decision:
        verdict = self._classify(cap)
        decision = self._conclude(verdict)
        self.stats.captures += 1
        self.stats.statuses[verdict.status] += 1
        self.stats.labels[verdict.label] += 1
        if self.on_decision is not None:
            self.on_decision(decision)
        return decision

    def _classify(self, cap: Capture) -> Verdict:
        t_start = time.perf_counter()
        probs = np.asarray(self.classifier.classify_capture(cap.data))
        compute_us = (time.perf_counter() - t_start) * 1e6
        k = int(np.argmax(probs))
        label, conf = self.classes[k], float(probs[k])
        return Verdict(
            t_trigger_s=round(self._time_of(cap.trigger_index), 3),
            t_alert_s=round(self._time_of(cap.start_index + len(cap.data) - 1), 3),
            label=label,
            confidence=conf,
            status=self.policy.status(label, conf),
            probs={c: float(p) for c, p in zip(self.classes, probs)},
            compute_us=compute_us,
            rx_monotonic_s=self._rx,
        )

    def _conclude(self, verdict: Verdict) -> Decision:
        """The decision, made once: a would-alert verdict is 'alert' only if its frame went out."""
        if verdict.status != "alert" or self.publisher is None:
            return Decision.made(verdict, alerted=verdict.status == "alert")
        seq = self.publisher.publish_alert(verdict)
        if seq is None:
            return Decision.made(verdict, alerted=False, status="alert_not_sent")
        if verdict.rx_monotonic_s is None:  # a recording: no arrival time to measure from
            return Decision.made(verdict, alerted=True, alert_seq=seq)
        latency_ms = (time.monotonic() - verdict.rx_monotonic_s) * 1e3
        self.status.add_alert_latency(latency_ms)
        return Decision.made(verdict, alerted=True, latency_ms=latency_ms, alert_seq=seq)
