"""Event-level scoring of the wearable's decisions against the simulator's truth.

A decision matches a truth event when its trigger time falls within
[start_s - tolerance_s, end_s] (the detector's capture starts 1 s before the
trigger, so a trigger just before the annotated start still sees the motion).

Alerts are the decisions that raise one (:func:`raises_alert`): an update of an alert (confirmed,
revised, withdrawn) is not a second alert.

* recall    = distraction events with at least one alert / distraction events
* precision = alerts that match a distraction event / alerts
* label accuracy = matched alerts whose class equals the event's / matched alerts
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from edge_runtime.wearable.labels import DISTRACTIONS, OTHER

ONSET_IGNORE_S = 0.3
"""A distraction's class is what a decision should say from this long after its start (before it the hand has only
just left the wheel: neither its class nor Other is right)."""
AFTER_END_IGNORE_S = 1.0
"""Nor is either right for this long after its end (the hand on its way back, the window still mostly the
distraction)."""
NOT_SCORED = -1


def class_at(t_s: np.ndarray, events: list[dict], classes) -> np.ndarray:
    """The class index a decision made at each time ``t_s`` should report against the truth ``events``
    (label, start_s, end_s): a distraction's class from :data:`ONSET_IGNORE_S` after its start to its end,
    :data:`NOT_SCORED` from its start to then and for :data:`AFTER_END_IGNORE_S` after its end, Other elsewhere
    (an Other motion too). The streaming classifier learns this (models/stream_train.py) and drive-eval's
    every-hop macro-F1 scores it."""
    classes = list(classes)
    t_s = np.asarray(t_s, dtype=float)
    y = np.full(len(t_s), classes.index(OTHER), dtype=np.int64)
    for e in events:
        if e["label"] in DISTRACTIONS:
            y[(t_s >= e["start_s"]) & (t_s <= e["end_s"] + AFTER_END_IGNORE_S)] = NOT_SCORED
            y[(t_s >= e["start_s"] + ONSET_IGNORE_S) & (t_s <= e["end_s"])] = classes.index(e["label"])
    return y


@dataclass
class AlertScore:
    distractions: int
    detected: int
    alerts: int
    alerts_on_distraction: int
    alerts_label_correct: int

    @property
    def recall(self) -> float:
        return self.detected / self.distractions if self.distractions else float("nan")

    @property
    def precision(self) -> float:
        return self.alerts_on_distraction / self.alerts if self.alerts else float("nan")

    @property
    def label_accuracy(self) -> float:
        return self.alerts_label_correct / self.alerts_on_distraction if self.alerts_on_distraction else float("nan")

    def as_dict(self) -> dict:
        return {
            "distractions": self.distractions,
            "alerts": self.alerts,
            "recall": round(self.recall, 4),
            "precision": round(self.precision, 4),
            "label_accuracy": round(self.label_accuracy, 4),
        }


def raises_alert(d: dict) -> bool:
    """A decision that warned the driver of a new distraction: an alert that went out, the first of
    its event (``alert``, or ``preliminary`` when decided early); its updates are not new alerts."""
    return bool(d["alerted"]) and d.get("status", "alert") in ("alert", "preliminary")


def score_alerts(decisions: list[dict], events: list[dict], tolerance_s: float = 1.0) -> AlertScore:
    """``decisions``: dicts with t_trigger_s, label, alerted; ``events``: dicts with start_s, end_s, label."""
    truth = [e for e in events if e["label"] in DISTRACTIONS]
    alerts = [d for d in decisions if raises_alert(d)]

    def match(d):
        for e in truth:
            if e["start_s"] - tolerance_s <= d["t_trigger_s"] <= e["end_s"]:
                return e
        return None

    matched = [(d, match(d)) for d in alerts]
    hit_events = {id(e) for _, e in matched if e is not None}
    return AlertScore(
        distractions=len(truth),
        detected=len(hit_events),
        alerts=len(alerts),
        alerts_on_distraction=sum(e is not None for _, e in matched),
        alerts_label_correct=sum(e is not None and e["label"] == d["label"] for d, e in matched),
    )
