"""The trigger-free streaming decider (issue 12): ``[alerts] decision = "stream"``, the box's default.

The capture path (:mod:`edge_runtime.wearable.loop`) waits for the detector's trigger and classifies the 7-s
capture after it. This path needs no trigger: it keeps the last ``[stream] window_s`` of the wrist stream at
25 Hz and classifies it every ``hop_s`` with the streaming classifier (``python -m models stream-train``,
``python -m export stream``: the manifest's ``stream-*`` entries).

* 100 Hz -> 25 Hz: a running sum of 4 samples (Python floats on a live source's few samples, one numpy sum
  on a recording's block: the same float64 sums, so both give the same steps), written into a ring of 25 Hz
  steps that holds every step twice (at i and i + W), so that the last W steps are always one contiguous slice:
  nothing is allocated per sample, and one copy per decision makes the model's input.
* A decision every hop once W s are there (the first at the W-th step of a stretch of samples).
* The alert rule (:class:`StreamDecider`, session 21's "stream B" policy): the score of a hop is the largest
  distraction probability (``top``) or 1 - P(Other) (``any``); an alert event opens when the score is >=
  ``threshold`` on ``consecutive_hops`` hops in a row, with the class of the largest summed probability over
  those hops; while it is open no other alert is raised; it closes after ``close_after_s`` of hops whose
  P(Other) is >= ``close_other_p``.
* One event = one alert: a DISTRACTION_ALERT with a new AlertSeq through the same publisher as the capture
  path, status ``alert`` (the DBC's final decision: the stream sends no update, so a ``preliminary`` would
  expire on the vehicle after 7 s). Its ``t_trigger_s`` is the time of the first of the k hops (when the
  evidence began; TimeSinceTrigger counts from it) and its ``event_start_s`` the same.
* A gap or non-finite samples restart the stream (the window must not span a hole) and end the event under
  way, as they drop the capture path's capture: the next distraction alerts afresh.

The decisions the loop returns are the alerts (:class:`~edge_runtime.wearable.loop.Decision`, ``steps`` 0: no
capture); a hop that changes nothing returns none. No torch here: numpy and onnxruntime only.
"""
from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import numpy as np
import onnxruntime as ort

from edge_runtime import config
from edge_runtime.core.manifest import ASSETS_DIR, STREAM_ARCH, load_verified
from edge_runtime.core.onnx import fast_run, open_session
from edge_runtime.errors import ConfigError, ModelIntegrityError
from edge_runtime.wearable.alerts import AlertPublisher, WearableStatus
from edge_runtime.wearable.labels import OTHER
from edge_runtime.wearable.loop import FLOAT32, SAMPLEWISE_ROWS, LoopStats, Verdict, conclude

RAW_RATE_HZ = 100
DOWN = 4
"""Raw frames per 25 Hz step (the model's rate)."""
STEP_S = DOWN / RAW_RATE_HZ
MIN_STEPS = 16
"""The shortest window the model takes (its two max-pools leave a 'now' feature)."""
STREAM_STEPS = 0
"""``Decision.steps`` of a stream decision: it saw no capture's sub-windows."""
INPUT_NAME, OUTPUT_NAME = "imu", "probs"
SCORES = ("top", "any")


def _steps_of(seconds: float) -> float:
    return seconds / STEP_S


def _whole_steps(lo_s: float, hi_s: float) -> config.Check:
    """A duration that is a whole number of 25 Hz steps (0.04 s), in [lo_s, hi_s]."""
    return (f"a multiple of {STEP_S:g} s in [{lo_s:g}, {hi_s:g}] s",
            lambda v: lo_s <= v <= hi_s and abs(_steps_of(v) - round(_steps_of(v))) < 1e-6)


@config.section("stream")
@dataclass(frozen=True)
class StreamParams:
    """The trigger-free streaming decider, used when [alerts] decision = "stream" (the default)."""

    model: str = config.setting("stream-int8", ("a non-empty string", bool))
    """Manifest entry of the streaming classifier (arch stream): a name, or a precision (int8, fp32); the
    assets directory, threads and signing key are [model]'s."""
    window_s: float = config.setting(4.0, _whole_steps(MIN_STEPS * STEP_S, 30.0))
    """Seconds of the stream each decision sees (25 Hz steps). 4 s, hop 0.24 s, threshold 0.8, k 3, close
    after 1 s: session 23's operating point for its model, chosen on development drive seed 1 by a rule fixed
    beforehand (reports/wearable/stream_s23/report.md; session 21's stream B had hop 0.48 s, threshold 0.7)."""
    hop_s: float = config.setting(0.24, _whole_steps(STEP_S, 10.0))
    """Seconds between decisions."""
    score: str = config.setting("top", config.one_of(*SCORES))
    """A hop's score: 'top', the largest distraction probability; 'any', 1 - P(Other)."""
    threshold: float = config.setting(0.8, config.PROBABILITY)
    """A hop counts towards an alert when its score is at least this."""
    consecutive_hops: int = config.setting(3, ("an integer in 1..100", lambda v: 1 <= v <= 100))
    """An alert event opens after this many counting hops in a row."""
    close_after_s: float = config.setting(1.0, config.within(0.0, 60.0, "s"))
    """The open event closes after this long of hops whose P(Other) is at least close_other_p (rounded up to
    whole hops: at hop 0.24 s, 1 s is 5 hops); only then may a new alert open."""
    close_other_p: float = config.setting(0.5, config.PROBABILITY)
    """P(Other) from which a hop counts towards closing the event."""

    @property
    def window_steps(self) -> int:
        return int(round(_steps_of(self.window_s)))

    @property
    def hop_steps(self) -> int:
        return int(round(_steps_of(self.hop_s)))

    @property
    def close_hops(self) -> int:
        return max(1, math.ceil(self.close_after_s / self.hop_s - 1e-9))


# ---------------------------------------------------------------------------------------------- the model


class StreamModel:
    """The streaming classifier on onnxruntime: a window (T, 3) of 25 Hz steps in m/s^2 -> (K,) probabilities."""

    def __init__(self, model: bytes | str | os.PathLike, *, classes: Sequence[str], name: str = "", precision: str = "",
                 threads: int = 1, entry: dict | None = None, source: str = "", window_steps: int = 100):
        self.source = source or str(model)
        self.session = open_session(model, threads, self.source)
        inputs = {i.name: i.shape for i in self.session.get_inputs()}
        outputs = [o.name for o in self.session.get_outputs()]
        if INPUT_NAME not in inputs or OUTPUT_NAME not in outputs or len(inputs[INPUT_NAME]) != 3 \
                or inputs[INPUT_NAME][2] != 3:
            raise ModelIntegrityError(f"{self.source}: not a streaming classifier (want input {INPUT_NAME} (N, T, 3) "
                                      f"and output {OUTPUT_NAME}; got inputs {inputs}, outputs {outputs})")
        self.classes = [str(c) for c in classes]
        self.name, self.precision, self.entry = name or Path(self.source).stem, precision, entry or {}
        self.threads = threads
        self.step_model = None  # what the summary asks of a capture classifier
        self._x = np.zeros((1, window_steps, 3), FLOAT32)
        """The model's input: filled by a copy of the window, never reallocated."""
        self._outputs = [OUTPUT_NAME]
        self._feed = {INPUT_NAME: self._x}
        self._options = ort.RunOptions()
        self._run = fast_run(self.session, self._outputs, self._feed, self._options)
        probe = self._run(self._outputs, self._feed, self._options)[0]
        if probe.shape != (1, len(self.classes)):
            raise ModelIntegrityError(f"{self.source}: {probe.shape[-1]} outputs but {len(self.classes)} classes listed")

    @classmethod
    def from_manifest(cls, assets_dir: str | os.PathLike = ASSETS_DIR, name_or_precision: str = "stream-int8",
                      threads: int = 1, public_key_file: str | os.PathLike | None = None,
                      window_steps: int = 100) -> "StreamModel":
        """The hash-checked manifest entry of arch ``stream`` named ``name_or_precision`` (or the first of that
        precision)."""
        entry, data, path = load_verified(assets_dir, name_or_precision, arch=STREAM_ARCH,
                                          public_key_file=public_key_file)
        return cls(data, classes=entry["classes"], name=entry["name"], precision=entry["precision"], threads=threads,
                   entry=entry, source=str(path), window_steps=window_steps)

    @classmethod
    def from_params(cls, stream: StreamParams, model, name_or_precision: str | None = None) -> "StreamModel":
        """The model ``[stream] model`` names, from ``[model]``'s assets, threads and signing key (or another entry
        of those assets with ``name_or_precision``)."""
        return cls.from_manifest(model.assets or ASSETS_DIR, name_or_precision or stream.model, threads=model.threads,
                                 public_key_file=model.manifest_public_key or None, window_steps=stream.window_steps)

    def classify_window(self, window: np.ndarray) -> np.ndarray:
        """``window`` (T, 3) float32 25 Hz steps, oldest first (T = the window this model was opened for) ->
        (K,) probabilities. The input buffer is reused: the returned array is the model's own output."""
        np.copyto(self._x[0], window)
        return self._run(self._outputs, self._feed, self._options)[0][0]

    def decision_path(self) -> dict:
        return {"model": self.name, "precision": self.precision, "sha256": self.entry.get("sha256"),
                "arch": STREAM_ARCH}


# ---------------------------------------------------------------------------------------------- the alert rule


@dataclass
class StreamEvent:
    """One distraction as the vehicle sees it: opened by a stream alert, closed by Other."""

    start_s: float
    seq: int | None
    label: str


@dataclass
class Opened:
    """What :meth:`StreamDecider.hop` says when an alert event opens."""

    t_trigger_s: float
    """The first of the k hops."""
    label: str
    confidence: float
    """The score of the hop that opened it."""


class StreamDecider:
    """The alert rule over the model's hops (module docstring), one hop at a time; no time, no model, no I/O."""

    def __init__(self, params: StreamParams, classes: Sequence[str]):
        if OTHER not in classes:
            raise ModelIntegrityError(f"a streaming classifier needs the class {OTHER!r}; it has {list(classes)}")
        self.p = params
        self.classes = list(classes)
        self._other = self.classes.index(OTHER)
        self._distractions = [k for k in range(len(self.classes)) if k != self._other]
        self._k = params.consecutive_hops
        self._recent: list[tuple[float, list[float]]] = []  # the last k hops (time, probabilities)
        self.reset()

    def reset(self) -> None:
        """A new stretch of the stream: no hop counts, no event open."""
        self.counting = 0
        """Consecutive hops whose score is >= threshold."""
        self.other = 0
        """Consecutive hops whose P(Other) is >= close_other_p."""
        self._recent.clear()
        self.open = False

    def score(self, probs: Sequence[float]) -> float:
        if self.p.score == "top":
            return max(probs[k] for k in self._distractions)
        return 1.0 - probs[self._other]

    def hop(self, t_s: float, probs: list[float]) -> Opened | str | None:
        """One hop's probabilities (classes order) at stream time ``t_s`` -> :class:`Opened` when an alert event
        opens, "closed" when the open one closes, None when nothing changes."""
        score = self.score(probs)
        self.counting = self.counting + 1 if score >= self.p.threshold else 0
        self.other = self.other + 1 if probs[self._other] >= self.p.close_other_p else 0
        self._recent.append((t_s, probs))
        if len(self._recent) > self._k:
            del self._recent[0]
        if self.open:
            if self.other >= self.p.close_hops:
                self.open = False
                return "closed"
            return None
        if self.counting < self._k:
            return None
        self.open = True
        sums = [sum(p[k] for _, p in self._recent) for k in self._distractions]
        label = self.classes[self._distractions[sums.index(max(sums))]]  # the first of equal sums, as argmax
        return Opened(self._recent[0][0], label, score)


# ---------------------------------------------------------------------------------------------- the loop


class StreamLoop:
    """``feed(block)`` -> the alerts decided in it; the interface of :class:`~edge_runtime.wearable.loop.WearableLoop`
    (``stats``, ``status``, ``publisher``, ``rate_hz``, ``decision_mode``, ``classifier``)."""

    def __init__(self, classifier: StreamModel, params: StreamParams = StreamParams(), on_decision=None,
                 sample_rate_hz: int = RAW_RATE_HZ, publisher: AlertPublisher | None = None):
        if sample_rate_hz != RAW_RATE_HZ:
            raise ConfigError(f"[imu] sample_rate_hz: the streaming decider needs {RAW_RATE_HZ} Hz (its 25 Hz steps are "
                              f"{DOWN} samples), got {sample_rate_hz}")
        self.classifier = classifier
        self.classes = list(classifier.classes)
        self.params = params
        self.rule = StreamDecider(params, self.classes)
        self.on_decision = on_decision
        self.rate_hz = sample_rate_hz
        self.publisher = publisher
        self.status = publisher.status if publisher is not None else WearableStatus()
        self.stats = LoopStats()
        self.hops = 0
        self.decision_mode = (f"stream decisions every {params.hop_s:g} s on the last {params.window_s:g} s, alert "
                              f"after {params.consecutive_hops} hops with {params.score} >= {params.threshold:g}")
        self._w = params.window_steps
        self._ring = np.zeros((2 * self._w, 3), FLOAT32)
        """Every 25 Hz step twice, at i and i + W (i = step mod W): ring[i + 1 : i + 1 + W] is the last W steps."""
        self._event: StreamEvent | None = None
        self._rx: float | None = None
        self._restart(0.0)

    def _restart(self, t0_s: float) -> None:
        """A new stretch of samples from ``t0_s``: no step, no window, no event (the next distraction alerts afresh)."""
        self._t0_s = t0_s
        self._steps = 0
        """25 Hz steps of this stretch."""
        self._sx = self._sy = self._sz = 0.0
        self._n = 0
        """Samples in the running sums (the step being summed)."""
        self._event = None
        self.rule.reset()

    def feed(self, block) -> list:
        acc = block.acc_mps2
        if type(acc) is not np.ndarray or acc.dtype != FLOAT32 or acc.ndim != 2 or acc.shape[1] != 3:
            acc = np.asarray(acc, dtype=np.float32).reshape(-1, 3)
        if not block.continuous or (self._steps == 0 and self._n == 0):
            if self._steps or self._n:
                self.status.count_detector_restart()
            self._restart(block.t0_s)
        self._rx = block.rx_monotonic_s
        if len(acc) <= SAMPLEWISE_ROWS:  # a live source's block: Python floats, no numpy call (see loop.SAMPLEWISE_ROWS)
            rows = acc.tolist()
            if all(x - x == 0.0 and y - y == 0.0 and z - z == 0.0 for x, y, z in rows):  # finite, by arithmetic
                self.status.count_samples(len(rows))
                return self._sum(rows)
        elif np.isfinite(acc).all():
            self.status.count_samples(len(acc))
            return self._push(acc)
        finite = np.isfinite(acc).all(axis=1)
        self.status.count_samples(len(acc), non_finite=int((~finite).sum()))
        out = []
        edges = np.flatnonzero(np.diff(np.r_[False, ~finite, False].astype(np.int8)))
        good = 0
        for a, b in zip(edges[::2], edges[1::2]):  # each run of bad samples restarts the stream after it
            out += self._push(acc[good:a])
            self.status.count_detector_restart()
            self._restart(block.t0_s + b / self.rate_hz)
            good = b
        return out + self._push(acc[good:])

    def _sum(self, rows: list) -> list:
        """Samples as Python floats into the running sums; a 25 Hz step (and a decision when due) every 4."""
        out: list = []
        for x, y, z in rows:
            self._sx += x
            self._sy += y
            self._sz += z
            self._n += 1
            if self._n == DOWN:
                out += self._step(self._sx / DOWN, self._sy / DOWN, self._sz / DOWN)
                self._sx = self._sy = self._sz = 0.0
                self._n = 0
        return out

    def _push(self, acc: np.ndarray) -> list:
        """Finite samples of a block -> 25 Hz steps -> the decisions due."""
        if len(acc) < DOWN:
            return self._sum(acc.tolist())
        head = (DOWN - self._n) % DOWN  # the samples that complete the step being summed
        out = self._sum(acc[:head].tolist()) if head else []
        whole = (len(acc) - head) // DOWN * DOWN
        # float64 sums of the 4 float32 samples in order, as the running sums add them: the same steps
        sums = acc[head:head + whole].astype(np.float64).reshape(-1, DOWN, 3)
        for x, y, z in ((((sums[:, 0] + sums[:, 1]) + sums[:, 2]) + sums[:, 3]) / DOWN).tolist():
            out += self._step(x, y, z)
        return out + self._sum(acc[head + whole:].tolist())  # the rest (< 4 samples) into the running sums

    def _step(self, x: float, y: float, z: float) -> list:
        """One 25 Hz step into the ring; a decision when a hop is due."""
        i = self._steps % self._w
        self._ring[i] = self._ring[i + self._w] = (x, y, z)
        self._steps += 1
        due = self._steps - self._w
        if due < 0 or due % self.params.hop_steps:
            return []
        return self._decide(self._ring[i + 1:i + 1 + self._w])

    def _decide(self, window: np.ndarray) -> list:
        t_s = round(self._t0_s + (self._steps * DOWN - 1) / self.rate_hz, 3)  # the last raw frame the window holds
        t_start = time.perf_counter()
        probs = self.classifier.classify_window(window).tolist()
        compute_us = (time.perf_counter() - t_start) * 1e6
        self.hops += 1
        said = self.rule.hop(t_s, probs)
        if said is None:
            return []
        if said == "closed":
            self._event = None
            return []
        verdict = Verdict(t_trigger_s=round(said.t_trigger_s, 3), t_alert_s=t_s, label=said.label,
                          confidence=said.confidence, status="alert", probs=dict(zip(self.classes, probs)),
                          compute_us=compute_us, rx_monotonic_s=self._rx, steps=STREAM_STEPS,
                          event_start_s=round(said.t_trigger_s, 3), event_seq=None)
        decision = conclude(verdict, self.publisher, self.status)
        self._event = StreamEvent(verdict.event_start_s, decision.alert_seq, verdict.label)
        self.stats.events += 1
        self.stats.statuses[decision.status] += 1
        self.stats.labels[decision.label] += 1
        if self.on_decision is not None:
            self.on_decision(decision)
        return [decision]
