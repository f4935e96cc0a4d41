"""The wearable capture loop: IMU samples -> detector -> capture -> classifier -> alert policy -> publisher.

The capture path, ``[alerts] decision = "early"`` or ``"full_window"``. The box ships the other decider,
``"stream"`` (:mod:`edge_runtime.wearable.stream_decider`: no detector, no capture); :class:`AlertPolicy` is
the section of both, and :class:`WearableLoop` refuses a policy that says "stream".

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

Early decisions (``[alerts] decision = "early"``, with a model that accepts fewer than
6 sub-windows: :attr:`~edge_runtime.wearable.classifier.Engine.early_steps`). While a
capture fills, the loop classifies its first S sub-windows as soon as the capture holds
``needed_frames(S)`` frames. A confident distraction at S < 6 is a *preliminary* alert (confident:
the step's threshold, from ``earliest_alert_step`` on, ``early_min_margin`` ahead of the second class,
the same class at ``early_agreement_steps`` consecutive steps: :meth:`AlertPolicy.early_ready`; from
S = 3 on, a new alert also needs the capture's mean P(Other) so far at most ``max_mean_other``);
later steps may *revise* its class, and the full window (S = 6) makes the final decision:
*confirmed*, *revised* or *withdrawn* (Other or uncertain). Each decision that says
something new is made once and handed out, like every other; the full-window decision of
a capture is always one. With ``decision = "full_window"`` (the dissertation's single
decision) or a model with a fixed S = 6 only the full window is decided.

A distraction is one event (:class:`AlertEvent`): the first alert of a capture opens an
event with a new AlertSeq; a capture whose trigger comes while the event is active (within
``event_hold_s`` of the end of the event's last capture: the hand returning, a second reach)
belongs to it and raises no new alert (its decision says ``continued``); such a capture
extends the event, unless its full window says a never-alerted class (Other: the hand did
something else, ``event_ends_on_other``), which ends it. The event ends when ``event_hold_s``
pass with no new trigger, or at once when its alert is withdrawn. Every decision carries its
event's start.

Bad samples never stop the loop: non-finite samples are counted and the
detector restarts after them (its window must not span a hole), and a block
that does not continue the previous one (a gap) restarts it too. The counts go
to the publisher's :class:`~edge_runtime.wearable.alerts.WearableStatus`, which the
heartbeat reports.
"""
from __future__ import annotations

import time
from collections import Counter
from dataclasses import dataclass, field
from typing import Any, Callable, Protocol, Sequence

import numpy as np

from edge_runtime import config
from edge_runtime.errors import ConfigError
from edge_runtime.wearable.alerts import AlertPublisher, WearableStatus
from edge_runtime.wearable.classifier import CAPTURE_FRAMES, N_SUBSEQ, needed_frames
from edge_runtime.wearable.detector import Capture, DetectorConfig, StreamingDetector
from edge_runtime.wearable.labels import CLASSES, OTHER
from edge_runtime.wearable.sources import SAMPLE_RATE_HZ, ImuBlock


class Classifier(Protocol):
    """The classifier the loop asks: ``classify_capture`` always; a model that decides early also has
    ``early_steps`` (the sub-window counts S it accepts), ``classify_prefix(x, S)`` (calibrated
    probabilities after S sub-windows) and ``early.min_confidence_by_steps`` (the manifest's thresholds).
    One that also has ``classify_capture_groups`` (the shipped Engine) is asked for the captures a
    block completes together, which must give each what ``classify_prefix`` gives it alone. One that is
    ``streaming`` (the Engine with a step model) also has ``new_stream()`` (a capture's state) and
    ``advance(stream, frames, S)``: the loop keeps a state per capture, runs a step as each of its
    sub-windows arrives, and reads each decision after S sub-windows from it."""

    classes: Sequence[str]

    def classify_capture(self, x700: np.ndarray) -> np.ndarray:
        """A detector capture (700, 3) m/s^2 at 100 Hz -> (K,) class probabilities."""


BATCH_CAPTURES = 20
"""Captures classified together at most (:meth:`WearableLoop._classify_ahead`): a model run's cost per
capture stops falling at about 16, and onnxruntime's buffers grow with the batch (the day's replay:
the same CPU time with 20, 32 or 64, peak memory 89, 92 and 98 MB); a recording handed over whole
(``command.replay``) must not make it hold every capture's tensors at once (about 50 KB each at S = 6)."""
SAMPLEWISE_ROWS = 16
"""Blocks of at most this many samples go to the detector sample by sample as Python floats
(``StreamingDetector.push_sample``): a live source hands over 5 every 50 ms (``[imu] read_period_s``),
and on the caches a 50 ms sleep leaves cold each numpy call of the block path costs microseconds, more
than the five samples' Python arithmetic (reports/bench/s19_wearable). Larger blocks (a recording) take
the numpy path."""
MIN_CLASS_WEIGHT, MAX_CLASS_WEIGHT = 1e-3, 1e3
"""``AlertPolicy.class_weights``' range: a prior shift of up to 10^6 between two classes; beyond it a
weighted sum can underflow to 0 or overflow (a decision divides by it)."""
EARLY_MIN_CONFIDENCE = 0.9
"""The threshold of a preliminary alert at S < 6 when neither the configuration nor the model's
manifest gives one: stricter than the full window's, since a wrong preliminary is a false alarm."""
OTHER_EVIDENCE_FROM_STEP = 3
"""The first sub-window count whose P(Other) counts towards ``AlertPolicy.max_mean_other``: after 1 or 2
sub-windows (0.5-1.6 s of the motion) the model is right on fewer than two thirds of the captures."""
FLOAT32 = np.dtype(np.float32)
STREAM = "stream"
"""``[alerts] decision`` of the streaming decider (:mod:`edge_runtime.wearable.stream_decider`)."""
CAPTURE_DECISIONS = ("early", "full_window")
"""``[alerts] decision`` values of the capture path (:class:`WearableLoop`)."""
DECISIONS = (*CAPTURE_DECISIONS, STREAM)
ALERTING = ("alert", "preliminary", "confirmed", "revised")
"""Statuses whose frame tells the vehicle a distraction is under way (``withdrawn`` clears it)."""


@config.section("alerts")
@dataclass(frozen=True)
class AlertPolicy:
    """How the box decides a DISTRACTION_ALERT: the decider, and the capture path's alert policy."""

    min_confidence: float = config.setting(0.6, config.PROBABILITY)
    """Capture path only. Below this top-class probability a full-window decision is 'uncertain' and not alerted
    (unless min_confidence_by_steps or the model's manifest gives S = 6 its own)."""
    never_alert: tuple[str, ...] = (OTHER,)
    """Capture path only. Classes that are logged but never alerted (non-coupled hand motions; the stream never alerts
    Other)."""
    decision: str = config.setting(STREAM, config.one_of(*DECISIONS))
    """How the box decides. 'stream' (shipped): no detector and no capture: the streaming classifier decides every
    hop on the last seconds of the stream and sends one final alert (Status 0) per distraction ([stream],
    edge_runtime.wearable.stream_decider). Chosen over 'early' on development drives (``firmware_sim drive-eval``
    seeds 1 and 5, 20 h each: better on event recall, first-alert class, onset -> alert median and p95 and false
    alerts per hour on both, reports/wearable/stream_s22); held-out drive seeds 72 and 82 (20 h each) measured the
    same order afterwards, and seed 92 with session 23's retrained model (reports/drive_eval/fresh_seed92: stream
    0.975 / 0.963 / 2.32 s / 0.8 per h against early's 0.942 / 0.909 / 3.89 s / 1.2 per h). The capture path (the [detector]'s trigger, then the
    ConvLSTM on the 7-s capture): 'early', decide after each sub-window the capture's evidence allows
    (preliminary, then confirmed, revised or withdrawn), when the model accepts partial captures; 'full_window',
    one decision per capture at T+599, the dissertation's. Every other key of this section is the capture path's
    only: 'stream' does not read them."""
    min_confidence_by_steps: tuple[float, ...] = config.setting(
        (0.9, 0.9, 0.9, 0.9, 0.9, -1.0), ("a list of 6 numbers, each in [0, 1] or negative",
                                             lambda v: len(v) == N_SUBSEQ and all(p <= 1.0 for p in v)))
    """Capture path only. Threshold of a decision after S = 1..6 sub-windows (a preliminary alert or a revision for S <
    6, the full window's for S = 6); a negative entry: the model manifest's min_confidence_by_steps for that S, else
    0.9 for S < 6 and min_confidence for S = 6; 1 for an S < 6: no decision after S sub-windows (the step is not
    computed). 0.9 before the full window was chosen on validation drives (``firmware_sim early-tune --seed 1``,
    reports/wearable/early_tuning): the manifest's early thresholds tell a distraction from Other in single captures
    but not which distraction (first-alert class 0.81 on those drives, Phone taken for Texting most), and the rule
    there asks class accuracy >= 0.90 at the full window's recall. S = 6 keeps the manifest's. Session 9's model,
    the same command and rule: 0.9 at every early step was no longer eligible (33 repeat alerts in 20 h against the
    full window's 32) and (0.97, 0.98, 0.99, 0.97, 0.96) shipped, median onset -> first alert 5.76 s on validation.
    Session 12 gave the rule's repeat- and false-alert limits a tolerance of one Poisson standard deviation of the
    full window's counts (``early_tuning.RULE``: one count in 20 h no longer decides); on the same validation drives
    it takes 0.9 again: median 3.85 s, class accuracy 0.903, recall 0.924 (full window 0.922), 33 repeat and 44
    false alerts in 20 h (full window 32 and 45)."""
    event_hold_s: float = config.setting(5.0, config.within(0.0, 120.0, "s"))
    """Capture path only. An alert event stays active until this long after the end of its last capture: a capture
    triggered meanwhile continues it and raises no new alert. 0: every capture is its own event. 5 s was chosen on
    validation drives (``firmware_sim drive-eval --seed 1``, 5 h, full window): repeat alerts 23 -> 1 at unchanged
    event recall (0.886); 10 s cost 0.03 of recall, 15 s 0.13. The early-decision sweep (``firmware_sim
    early-tune``) kept it: 3 s gained 0.01 of recall at 3.6 times the repeat alerts, 10 s cost 0.05 of recall."""
    event_ends_on_other: bool = True
    """Capture path only. A capture of an active event whose full window says a never-alerted class (Other: the hand
    did something else in between) ends the event instead of extending it, so that the next distraction alerts
    afresh rather than continuing an event opened long before (or by a false alert). Chosen on development drives
    (``firmware_sim drive-eval --seed 5`` and ``--seed 1``, 10 h each): event recall +0.008 on both, in both
    decision modes, at unchanged repeat alerts and false alerts +0.1 / 0 per hour
    (reports/drive_eval/development.md)."""
    class_weights: tuple[float, ...] = config.setting(
        (1.0, 1.0, 1.0, 1.0, 3.0, 1.5), (f"a list of one number in [{MIN_CLASS_WEIGHT:g}, {MAX_CLASS_WEIGHT:g}] per class",
                                         lambda v: len(v) == len(CLASSES) and all(
                                             MIN_CLASS_WEIGHT <= w <= MAX_CLASS_WEIGHT for w in v)))
    """Capture path only. Weights of the classes (Phone, Texting, TouchScreen, Drink, Marker, Other) the classifier's
    probabilities are multiplied by, and renormalised, before every decision (a decision's probs and confidence are
    the weighted ones): a prior-shift correction of a model that under-calls a class on the deployment's captures. 1
    everywhere: the model's own probabilities. On development drives (``firmware_sim drive-eval --seed 5`` and
    ``--seed 1``, 10 h each) Marker was most missed, its full window calling it Other (the Marker reach to the
    passenger seat is Other's grab_from_seat with a stop at the cup holder); other classes' misses gained less than
    they cost in false alerts. Rule: the highest mean event recall (early decisions) over both seeds with false
    alerts per hour on each no higher than with weights 1. Session 8's model: Marker 8, Other 1.5. Refitted by the
    same rule for session 9's model (label smoothing, rotation up to 15 degrees; Marker 1..8 x Other 1..1.5): Marker
    3, Other 1.5, event recall +0.012 / +0.007, false alerts -0.1 / -0.4 per hour, class accuracy -0.000 / -0.002
    against weights 1 (reports/drive_eval/development.md, round 3). Fitted on simulated drives: refit on a
    deployment's own validation drives."""
    max_mean_other: float = config.setting(0.5, config.PROBABILITY)
    """Capture path only. A capture that has raised no alert yet may open one after S >= ``OTHER_EVIDENCE_FROM_STEP``
    sub-windows only if its mean probability of Other (class weights applied) over the sub-window counts decided so
    far from that step on is at most this (1: no such check). Several steps' evidence that the hand is doing
    something else outweighs one confident step: a false alert's Other motion keeps some P(Other) at most steps, a
    distraction's usually loses it. With ``decision = "full_window"`` (or no early step computed) the mean is of the
    full window alone. Alerts already open (confirmed, revised) are not checked. Chosen on development drives
    (``firmware_sim drive-eval --seed 5`` and ``--seed 1``, 10 h each) by a rule fixed beforehand: the largest cut
    in false alerts over 1, 0.5, 0.4, ..., 0.05 with event recall (early) not lower on either seed: 0.5, false
    alerts 2.1 -> 1.9 and 2.0 -> 1.7 per hour, recall +0.001 / 0; 0.4 and below cost recall on seed 5
    (reports/drive_eval/development.md, round 2)."""

    earliest_alert_step: int = config.setting(2, ("an integer in 1..6", lambda v: 1 <= v <= N_SUBSEQ))
    """Capture path only. No preliminary alert or revision before this many sub-windows (the full window, S = 6, always
    decides): the first sub-windows hold little of the motion, and a wrong early class is a false alarm. 2 was
    chosen with the thresholds above: at 0.9, S = 1 alerts are rare and tie with 2 on validation, and the tie goes
    to the later step (int8 and fp32 agree least at S = 1)."""
    early_agreement_steps: int = config.setting(1, ("an integer in 1..6", lambda v: 1 <= v <= N_SUBSEQ))
    """Capture path only. A preliminary alert or a revision needs the same top class at this many consecutive decided
    sub-window counts, ending at its own (1: its own step alone). One confident step may be a passing shape of the
    motion; two that agree are less often. On validation, 2 cost 0.24 s of median latency on average for 0.003 of
    class accuracy (a higher threshold buys it cheaper): 1."""
    early_min_margin: float = config.setting(0.0, config.PROBABILITY)
    """Capture path only. A preliminary alert or a revision needs its top class this far (calibrated probability) above
    the second: a confident step torn between two distractions (Phone or Texting) waits. On validation the early
    mistakes are confident ones: 0.3 moved class accuracy by 0.003 on average: 0."""

    def __post_init__(self) -> None:
        if not 0.0 <= self.min_confidence <= 1.0:
            raise ValueError("min_confidence must lie in [0, 1]")
        if self.decision not in DECISIONS:
            raise ValueError(f"decision must be one of {DECISIONS}")
        if len(self.class_weights) != len(CLASSES) or not all(
                MIN_CLASS_WEIGHT <= w <= MAX_CLASS_WEIGHT for w in self.class_weights):
            raise ValueError(f"class_weights: one number in [{MIN_CLASS_WEIGHT:g}, {MAX_CLASS_WEIGHT:g}] per class "
                             f"({len(CLASSES)})")
        if set(CLASSES) <= set(self.never_alert):
            raise ValueError(f"never_alert: {list(self.never_alert)} holds every class; nothing would ever be alerted")

    def status(self, label: str, confidence: float, threshold: float | None = None) -> str:
        if label in self.never_alert:
            return "not_alerted"
        if confidence < (self.min_confidence if threshold is None else threshold):
            return "uncertain"
        return "alert"

    def early_ready(self, steps: int, margin: float, agreeing_steps: int) -> bool:
        """Whether a confident early step (S < 6) may alert or revise: late enough, far enough ahead
        of the second class, and agreeing with the steps before it (``agreeing_steps``: consecutive
        decided steps, its own included, whose top class is its)."""
        return (steps >= self.earliest_alert_step and margin >= self.early_min_margin
                and agreeing_steps >= self.early_agreement_steps)

    def threshold(self, steps: int, manifest: dict[int, float]) -> float:
        """The threshold after ``steps`` sub-windows: configured, else the manifest's, else 0.9 before
        the full window and min_confidence at it."""
        configured = self.min_confidence_by_steps[steps - 1]
        if configured >= 0:
            return configured
        return manifest.get(steps, EARLY_MIN_CONFIDENCE if steps < N_SUBSEQ else self.min_confidence)


CAPTURE_DEFAULT = AlertPolicy(decision="early")
"""The capture loop's policy when it is given none: early decisions, every other key the section's default."""


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
    """Full window, no earlier alert: 'alert', 'uncertain' (below the confidence threshold) or
    'not_alerted' (e.g. Other). Early: 'preliminary' (S < 6), then 'revised' (another class),
    'confirmed' or 'withdrawn' (the full window says Other or uncertain). 'continued': a capture of
    an active event, never alerted. A :class:`Decision` whose frame did not go out says 'alert_not_sent'."""
    probs: dict[str, float]
    compute_us: float
    """Wall time from the completed capture to the verdict (preprocessing + inference), microseconds; for
    captures classified together (a replay's block), the batch's time divided among its captures and steps."""
    rx_monotonic_s: float | None = None
    """Host ``time.monotonic()`` when the sample the decision waited for arrived (live sources only)."""
    steps: int = N_SUBSEQ
    """Sub-windows of the capture the decision saw (S = 6: the full window, final)."""
    event_start_s: float | None = None
    """Stream time of the trigger that opened the alert event this decision belongs to (None: no event)."""
    event_seq: int | None = None
    """The AlertSeq of the event an update (confirmed, revised, withdrawn) belongs to; None: a new alert."""


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
        # the verdict's fields as they are (asdict would deep-copy probs: a third of a replay's decision cost)
        return cls(**{**vars(verdict), "status": status or verdict.status}, alerted=alerted, latency_ms=latency_ms,
                   alert_seq=alert_seq)

    def to_json(self) -> dict:
        """One line of ``--alerts`` (the host clock ``rx_monotonic_s`` means nothing outside this process)."""
        return {"t_trigger_s": self.t_trigger_s, "t_alert_s": self.t_alert_s, "label": self.label,
                "confidence": round(self.confidence, 5), "alerted": self.alerted, "status": self.status,
                "probs": {k: round(v, 5) for k, v in self.probs.items()}, "compute_us": round(self.compute_us, 1),
                "latency_ms": None if self.latency_ms is None else round(self.latency_ms, 3),
                "alert_seq": self.alert_seq, "steps": self.steps, "event_start_s": self.event_start_s}


@dataclass
class LoopStats:
    """What the loop decided (the sample counts are the status's: :class:`WearableStatus`)."""

    captures: int = 0
    statuses: Counter = field(default_factory=Counter)
    """Per policy status of every decision ('alert', 'preliminary', 'confirmed', ..., 'uncertain')."""
    labels: Counter = field(default_factory=Counter)
    """Per class of the full-window decisions (one per capture)."""
    events: int = 0
    """Alert events opened."""


@dataclass
class AlertEvent:
    """One distraction as the vehicle sees it: opened by an alert, continued by later captures."""

    start_s: float
    """Stream time of the trigger whose capture raised the first alert."""
    seq: int | None
    """The AlertSeq of its frames (None: the first frame did not go out)."""
    label: str
    """The class last alerted."""
    last_end_s: float
    """Stream time of the last frame of its latest capture."""
    withdrawn: bool = False


@dataclass
class _CaptureState:
    """What the loop has decided so far about the capture of one trigger."""

    trigger: int
    steps: list[int]
    """Sub-window counts still to decide, ascending."""
    event: AlertEvent | None = None
    continues: bool = False
    """It started while ``event`` was active: it continues that event, and raises no alert."""
    last_label: str | None = None
    agreeing: int = 0
    """Consecutive decided steps so far whose top class is ``last_label``."""
    other_sum: float = 0.0
    other_steps: int = 0
    """P(Other) summed over the decided steps S >= OTHER_EVIDENCE_FROM_STEP, and their count."""
    stream: Any = None
    """The classifier's step state of this capture (``new_stream()``), when it decides by steps."""


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
        policy: AlertPolicy = CAPTURE_DEFAULT,
        on_decision: Callable[[Decision], None] | None = None,
        sample_rate_hz: int = SAMPLE_RATE_HZ,
        publisher: AlertPublisher | None = None,
    ):
        if policy.decision not in CAPTURE_DECISIONS:  # the box's default is the streaming decider, not this loop
            raise ConfigError(f"[alerts] decision = {policy.decision!r}: the capture loop (WearableLoop) decides "
                              f"{' or '.join(map(repr, CAPTURE_DECISIONS))} only; 'stream' runs the streaming decider "
                              "(edge_runtime.wearable.stream_decider.StreamLoop, as command.make_loop builds it)")
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
        early = getattr(classifier, "early", None)
        self._manifest_thresholds: dict[int, float] = dict(getattr(early, "min_confidence_by_steps", {}) or {})
        offered = tuple(getattr(classifier, "early_steps", (N_SUBSEQ,)))
        # A threshold of 1 before the full window means no decision at that step (the manifest gives S = 1
        # one: near-chance, and outside int8's agreement gate), so the loop does not compute it at all;
        # nor a step before the earliest that may alert, unless it counts for agreement with that one.
        first_useful = policy.earliest_alert_step - (policy.early_agreement_steps - 1)
        self._early_steps = tuple(s for s in offered if s == N_SUBSEQ or (s >= first_useful and self.policy.threshold(
            s, self._manifest_thresholds) < 1.0)) if policy.decision == "early" else (N_SUBSEQ,)
        self._early = self._early_steps != (N_SUBSEQ,)
        self.decision_mode = "early decisions after S = " + ",".join(map(str, self._early_steps)) if self._early \
            else "full-window decisions" + (" (the model takes S = 6 only)" if offered == (N_SUBSEQ,) else
                                            " (every S < 6 has threshold 1)" if policy.decision == "early" else "")
        self._prefix = getattr(classifier, "classify_prefix", None)
        # a classifier that decides by steps keeps each capture's state and runs a step per sub-window
        self._stream = classifier.new_stream if getattr(classifier, "streaming", False) else None
        # a block that completes several captures classifies them together (see _classify_ahead)
        self._batch = getattr(classifier, "classify_capture_groups", None) if self._prefix is not None else None
        self._ready: dict[tuple[int, int], tuple[list[float], float]] = {}
        weights = dict(zip(CLASSES, policy.class_weights))
        self._weights = None if set(policy.class_weights) == {1.0} else [
            weights.get(c, 1.0) for c in self.classes]  # in the model's class order
        self._other_k = self.classes.index(OTHER) if OTHER in self.classes and policy.max_mean_other < 1.0 else None
        self._capture: _CaptureState | None = None  # the capture being decided
        # a capture still filling is acted on when it may decide early, or when a step model runs a step as each
        # of its sub-windows arrives, whatever the decisions: every decision then costs one step, never six
        self._fills = self._early or self._stream is not None
        self._first_frames = needed_frames(1 if self._stream is not None else self._early_steps[0])
        self._next_frames = self._first_frames  # frames the next early step (or sub-window) needs
        self._event: AlertEvent | None = None  # the alert event under way, if any

    def _time_of(self, index: int) -> float:
        return self._seg_t0 + (index - self._seg_index0) / self.rate_hz

    def _drop_capture(self) -> None:
        """The detector dropped the capture in progress (a gap, a hole): a preliminary alert of it
        gets no update and expires (the DBC says after 7 s), and the event it opened ends with it,
        so that the next capture may alert afresh instead of continuing an alert the vehicle dropped."""
        st = self._capture
        if st is not None and not st.continues and st.event is not None and st.event is self._event:
            self._event = None
        self._capture = None
        self._next_frames = self._first_frames

    def _restart(self, t0_s: float) -> None:
        self._drop_capture()
        if self.detector.n_seen:
            self.detector.reset()
            self.status.count_detector_restart()
        self._seg_index0, self._seg_t0 = self.detector.n_seen, t0_s

    def feed(self, block: ImuBlock) -> list[Decision]:
        acc = block.acc_mps2
        # the dtype by identity first: a comparison with the type np.float32 converts it to a dtype per call
        if type(acc) is not np.ndarray or (acc.dtype is not FLOAT32 and acc.dtype != FLOAT32) or acc.ndim != 2 \
                or acc.shape[1] != 3:
            acc = np.asarray(acc, dtype=np.float32).reshape(-1, 3)
        if not block.continuous or self.detector.n_seen == 0:  # nothing fed yet, or a gap
            self._restart(block.t0_s)
        self._rx = block.rx_monotonic_s
        if len(acc) <= SAMPLEWISE_ROWS:  # a live source's block: its samples as floats, one numpy call in all
            rows = acc.tolist()
            # finite: v - v is 0 for a finite v, NaN for NaN or an infinity (arithmetic: no call per sample,
            # and every call costs microseconds on the caches a 50 ms sleep leaves cold)
            if all(x - x == 0.0 and y - y == 0.0 and z - z == 0.0 for x, y, z in rows):
                self.status.count_samples(len(rows))
                out: list[Decision] = []
                for x, y, z in rows:  # the detector's push_sample gives push's triggers and captures
                    cap = self.detector.push_sample(x, y, z)
                    if cap is not None:
                        out += self._steps_of(cap.trigger_index, cap.data)
                return out + self._early_due() if self._fills else out
        elif np.isfinite(acc).all():  # the common case
            self.status.count_samples(len(acc))
            return self._push(acc)
        bad = ~np.isfinite(acc).all(axis=1)
        self.status.count_samples(len(acc), non_finite=int(bad.sum()))
        decisions: list[Decision] = []
        # Split at runs of bad samples: push the good runs, restart after each bad run.
        edges = np.flatnonzero(np.diff(np.r_[False, bad, False].astype(np.int8)))
        good_start = 0
        for a, b in zip(edges[::2], edges[1::2]):
            decisions += self._push(acc[good_start:a])
            self.detector.skip(b - a)  # the hole keeps its place in stream time
            self._drop_capture()
            self.status.count_detector_restart()
            self._seg_index0, self._seg_t0 = self.detector.n_seen, block.t0_s + b / self.rate_hz
            good_start = b
        decisions += self._push(acc[good_start:])
        return decisions

    def _push(self, acc: np.ndarray) -> list[Decision]:
        if not len(acc):
            return []
        out: list[Decision] = []
        captures = self.detector.push(acc)
        for i in range(0, len(captures), BATCH_CAPTURES):
            batch = captures[i:i + BATCH_CAPTURES]
            if len(batch) > 1 and self._batch is not None:
                self._classify_ahead(batch)
            for cap in batch:  # completed in this block: every step still due, in order
                out += self._steps_of(cap.trigger_index, cap.data)
            self._ready = {}
        return out + self._early_due()

    def _classify_ahead(self, captures: list[Capture]) -> None:
        """The probabilities of the steps the captures completed in one block will be decided at, with
        one model run per step for all of them (``classify_capture_groups``), into ``_ready``.

        What a decision does never changes which captures the detector takes, nor their frames, so a
        block's captures are known before the first of them is decided; which steps each is decided
        at depends on the decisions before it: a capture that continues an alert event is decided at
        S = 6 only. So the full windows go first, and from them a guess at which captures may continue
        an event: one triggered within ``event_hold_s`` of the end of the capture before it, when that
        one may have continued an event itself or its full window is an alert (only then does an event
        outlive it: one it opened with a preliminary alert is withdrawn otherwise). The early steps of
        the others go second. The guess decides nothing: a capture that opens an event against it has
        its early steps classified when it opens (:meth:`_steps_of`), and one that continues against
        it leaves them unused. Each row is what the classifier gives for that capture alone, so the
        decisions are those of one call per step.

        A step model needs no guess: it runs sub-windows 1..6 of every capture for the full window, so each
        capture's early steps come with it, at no further model run (asked for later, they ran again)."""
        st, ev = self._capture, self._event
        fresh = tuple(self._early_steps) if self._stream is not None else (N_SUBSEQ,)
        first = [(c, tuple(st.steps) if st is not None and c.trigger_index == st.trigger else fresh)
                 for c in captures]  # the capture opened in an earlier block: the steps it still has
        self._classify_groups([([c.trigger_index for c, s in first if s == steps],
                                np.stack([c.data for c, s in first if s == steps]), steps)
                               for steps in dict.fromkeys(s for _, s in first)])
        if self._stream is not None:
            return
        hold_s = self.policy.event_hold_s + 1.0 / self.rate_hz  # a frame's margin: a guess, never a decision
        threshold = self.policy.threshold(N_SUBSEQ, self._manifest_thresholds)
        may_continue = ev is not None and not ev.withdrawn  # the event under way may outlive ...
        last_end_s = ev.last_end_s if may_continue else None  # ... this end
        early = []
        for cap, _ in first:
            opened = st is not None and cap.trigger_index == st.trigger
            if not opened:
                may_continue = last_end_s is not None and self._time_of(cap.trigger_index) <= last_end_s + hold_s
                if not may_continue:
                    early.append(cap)
            label, conf = self._top(self._weighted(self._ready[cap.trigger_index, N_SUBSEQ][0]))
            # max_mean_other may still withhold this alert (it reads early steps not classified yet): the
            # guess takes it as an alert, which at worst leaves the next capture's early steps to _steps_of
            alerts = self.policy.status(label, conf, threshold) == "alert"
            ends = (may_continue and not opened and self.policy.event_ends_on_other
                    and label in self.policy.never_alert)  # an Other capture ends the event it continues
            may_continue = (may_continue or alerts or opened) and not ends
            last_end_s = self._time_of(cap.start_index + len(cap.data) - 1) if may_continue else None
        steps = tuple(s for s in self._early_steps if s != N_SUBSEQ)
        if early and steps:
            self._classify_groups([([c.trigger_index for c in early], np.stack([c.data for c in early]), steps)])

    def _top(self, values: list[float]) -> tuple[str, float]:
        """The top class and its probability; the first of equal maxima, as ``np.argmax`` (the guess of
        ``_classify_ahead`` and the decision must break ties alike)."""
        conf = max(values)
        return self.classes[values.index(conf)], conf

    def _weighted(self, values: list[float]) -> list[float]:
        """The probabilities a decision reads: the model's, times the deployment's class weights
        (``AlertPolicy.class_weights``) and renormalised; the model's own when every weight is 1."""
        if self._weights is None:
            return values
        weighted = [p * w for p, w in zip(values, self._weights)]
        total = sum(weighted)
        return [p / total for p in weighted]

    def _classify_groups(self, groups: list[tuple[list[int], np.ndarray, tuple[int, ...]]]) -> None:
        """Into ``_ready``: for each group (triggers, their captures (N, 700, 3), steps), every step's
        probabilities for every capture, and the compute time each one's share of the batch."""
        t_start = time.perf_counter()
        results = self._batch([(data, steps) for _, data, steps in groups])
        compute_us = (time.perf_counter() - t_start) * 1e6 / sum(len(t) * len(s) for t, _, s in groups)
        for (triggers, _, _), by_steps in zip(groups, results):
            for steps, probs in by_steps.items():
                for trigger, row in zip(triggers, probs.tolist()):
                    self._ready[trigger, steps] = row, compute_us

    def _early_due(self) -> list[Decision]:
        """The early steps (or with a step model the sub-windows) the capture still filling now holds the frames for."""
        if self._fills and self.detector.capturing and self.detector.filled >= self._next_frames:
            trigger, so_far = self.detector.filling
            return self._steps_of(trigger, so_far)
        return []

    # ------------------------------------------------------------------ decisions

    def _steps_of(self, trigger: int, data: np.ndarray) -> list[Decision]:
        """The decisions of the capture of ``trigger`` whose sub-windows ``data`` (its frames so far)
        now holds; a capture is decided at S = 6 once, when it is complete."""
        st = self._capture
        if st is None or st.trigger != trigger:
            st = self._capture = self._open_capture(trigger)
        if len(st.steps) > 1 and len(data) == CAPTURE_FRAMES and self._batch is not None:
            missing = tuple(s for s in st.steps if (trigger, s) not in self._ready)
            if missing:  # a whole capture, not classified ahead (or not at these steps): its steps in one go
                self._classify_groups([([trigger], data[None], missing)])
        elif st.stream is not None and len(data) < CAPTURE_FRAMES:  # filling: a step per sub-window arrived
            arrived = max(s for s in range(N_SUBSEQ + 1) if s == 0 or needed_frames(s) <= len(data))
            if arrived > st.stream.done:
                self.classifier.advance(st.stream, data, arrived)
        out = []
        while st.steps and needed_frames(st.steps[0]) <= len(data):
            steps = st.steps.pop(0)
            d = self._decide(st, data, steps)
            if d is not None:
                out.append(d)
        if st.steps:  # the next step to decide at, or with a step model the next sub-window to run
            self._next_frames = needed_frames(st.steps[0] if st.stream is None else min(st.steps[0], st.stream.done + 1))
        else:  # decided: the next capture's first early step is the next to wait for
            self._capture = None
            self._next_frames = self._first_frames
        return out

    def _open_capture(self, trigger: int) -> _CaptureState:
        ev = self._event
        t_trig = self._time_of(trigger)
        if ev is not None and (ev.withdrawn or t_trig > ev.last_end_s + self.policy.event_hold_s):
            ev = self._event = None  # the event ended: quiet for event_hold_s, or withdrawn
        continues = ev is not None
        steps = [N_SUBSEQ] if continues else list(self._early_steps)
        return _CaptureState(trigger, steps, ev, continues, stream=self._stream() if self._stream else None)

    def _decide(self, st: _CaptureState, data: np.ndarray, steps: int) -> Decision | None:
        verdict = self._classify(st, data, steps)
        if verdict is None:  # an early step that changes nothing
            return None
        decision = self._conclude(verdict)
        if decision.alerted or decision.status == "alert_not_sent":
            self._track(st, verdict, decision)
        if steps == N_SUBSEQ:
            self.stats.captures += 1
            self.stats.labels[verdict.label] += 1
            if st.continues and self.policy.event_ends_on_other and verdict.label in self.policy.never_alert:
                if self._event is st.event:
                    self._event = None  # the hand did something else: the distraction is over
            elif st.event is not None:
                st.event.last_end_s = max(st.event.last_end_s, verdict.t_alert_s)
        self.stats.statuses[verdict.status] += 1  # what the policy said, sent or not
        if self.on_decision is not None:
            self.on_decision(decision)
        return decision

    def _track(self, st: _CaptureState, verdict: Verdict, decision: Decision) -> None:
        """The event the capture's alert opened or updated."""
        if st.event is None:
            st.event = self._event = AlertEvent(verdict.t_trigger_s, decision.alert_seq, verdict.label,
                                                verdict.t_alert_s)
            self.stats.events += 1
        elif verdict.status == "withdrawn":
            st.event.withdrawn = True
        else:
            st.event.label = verdict.label

    def _classify(self, st: _CaptureState, data: np.ndarray, steps: int) -> Verdict | None:
        full = steps == N_SUBSEQ
        ready = self._ready.pop((st.trigger, steps), None)
        if ready is not None:  # classified with the other captures of its block
            values, compute_us = ready
        else:
            t_start = time.perf_counter()
            if st.stream is not None:
                probs = self.classifier.advance(st.stream, data, steps)
            elif self._prefix is not None:
                probs = np.asarray(self._prefix(data[: needed_frames(steps)], steps))
            else:
                probs = np.asarray(self.classifier.classify_capture(data))
            compute_us = (time.perf_counter() - t_start) * 1e6
            values = probs.tolist()  # K Python floats: cheaper to pick from than numpy calls on K numbers
        values = self._weighted(values)
        label, conf = self._top(values)
        st.agreeing = st.agreeing + 1 if label == st.last_label else 1
        st.last_label = label
        threshold = self.policy.threshold(steps, self._manifest_thresholds)
        status = self.policy.status(label, conf, threshold)
        if status == "alert" and not full and not self.policy.early_ready(
                steps, conf - sorted(values)[-2], st.agreeing):
            status = "uncertain"
        ev = st.event
        if self._other_k is not None and steps >= OTHER_EVIDENCE_FROM_STEP:
            st.other_sum += values[self._other_k]
            st.other_steps += 1
            if status == "alert" and ev is None and st.other_sum > self.policy.max_mean_other * st.other_steps:
                status = "uncertain"  # no new alert while the capture's steps keep saying Other
        if st.continues:
            status = "continued"
        elif ev is None:
            if not full and status != "alert":
                return None  # not confident yet: wait for more sub-windows
            status = "preliminary" if not full else status
        elif not full:
            if status != "alert" or label == ev.label:
                return None  # a preliminary stands until the evidence is confidently different
            status = "revised"
        else:
            status = {True: "confirmed", False: "revised"}[label == ev.label] if status == "alert" else "withdrawn"
        trigger = st.trigger
        start = trigger - self.detector.cfg.pre_frames
        t_trigger_s = round(self._time_of(trigger), 3)
        opens = ev is None and status in ALERTING  # the first alert of a capture opens an event
        return Verdict(
            t_trigger_s=t_trigger_s,
            t_alert_s=round(self._time_of(start + needed_frames(steps) - 1), 3),
            label=label,
            confidence=conf,
            status=status,
            probs=dict(zip(self.classes, values)),
            compute_us=compute_us,
            rx_monotonic_s=self._rx,
            steps=steps,
            event_start_s=ev.start_s if ev is not None else (t_trigger_s if opens else None),
            event_seq=None if ev is None else ev.seq,
        )

    def _conclude(self, verdict: Verdict) -> Decision:
        return conclude(verdict, self.publisher, self.status)


def conclude(verdict: Verdict, publisher: AlertPublisher | None, status: WearableStatus) -> Decision:
    """The decision, made once: a verdict whose frame should go out is alerted only if it went out (through
    ``publisher``; without one, offline, it counts as alerted). The alert path of every decider (this loop's,
    ``stream_decider``'s)."""
    if verdict.status in ("uncertain", "not_alerted", "continued"):
        return Decision.made(verdict, alerted=False)
    if publisher is None:
        return Decision.made(verdict, alerted=True)
    seq = publisher.publish_alert(verdict)
    if seq is None:
        return Decision.made(verdict, alerted=False, status="alert_not_sent")
    if verdict.rx_monotonic_s is None:  # a recording: no arrival time to measure from
        return Decision.made(verdict, alerted=True, alert_seq=seq)
    latency_ms = (time.monotonic() - verdict.rx_monotonic_s) * 1e3
    status.add_alert_latency(latency_ms)
    return Decision.made(verdict, alerted=True, latency_ms=latency_ms, alert_seq=seq)
