import numpy as np

from firmware_sim.scenarios.scoring import class_at, score_alerts

EVENTS = [
    {"start_s": 10.0, "end_s": 15.0, "label": "Drink"},
    {"start_s": 40.0, "end_s": 44.0, "label": "Texting"},
    {"start_s": 70.0, "end_s": 72.0, "label": "Other"},  # never counted as a distraction
]


def _d(t, label, alerted=True):
    return {"t_trigger_s": t, "label": label, "alerted": alerted}


def test_event_level_precision_recall_and_label_accuracy():
    decisions = [
        _d(9.5, "Drink"),  # within the 1 s tolerance before the start
        _d(12.0, "Drink"),  # a second alert on the same event: recall counts the event once
        _d(41.0, "Phone"),  # on a distraction, wrong class
        _d(70.5, "Marker"),  # on an Other motion: a false alert
        _d(90.0, "Phone", alerted=False),  # not alerted: ignored
    ]
    s = score_alerts(decisions, EVENTS)
    assert (s.distractions, s.detected, s.alerts) == (2, 2, 4)
    assert s.recall == 1.0 and s.precision == 0.75 and s.label_accuracy == 2 / 3


def test_trigger_after_the_event_or_long_before_does_not_match():
    s = score_alerts([_d(15.01, "Drink"), _d(8.9, "Drink")], EVENTS)
    assert s.detected == 0 and s.precision == 0.0


def test_updates_of_an_alert_are_not_new_alerts():
    decisions = [{**_d(9.5, "Drink"), "status": "preliminary"}, {**_d(9.5, "Drink"), "status": "confirmed"},
                 {**_d(41.0, "Texting"), "status": "alert"}, {**_d(70.5, "Marker"), "status": "withdrawn"}]
    s = score_alerts(decisions, EVENTS)
    assert (s.alerts, s.detected, s.precision) == (2, 2, 1.0)


def test_class_at_scores_a_distraction_after_its_onset_and_skips_the_hand_on_its_way():
    from edge_runtime.wearable.labels import CLASSES

    t = np.array([29.0, 30.1, 30.4, 49.9, 50.5, 51.2])
    y = class_at(t, [{"label": "Phone", "start_s": 30.0, "end_s": 50.0}, {"label": "Other", "start_s": 1, "end_s": 2}],
                 CLASSES)
    other, phone = CLASSES.index("Other"), CLASSES.index("Phone")
    assert y.tolist() == [other, -1, phone, phone, -1, other]
