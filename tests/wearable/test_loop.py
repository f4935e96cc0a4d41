"""wearable/loop.py: the loop's bookkeeping and decisions, with a stand-in classifier (the
shipped model has its own tests) and a stand-in or a real publisher."""
import copy
import time

import can
import numpy as np
import pytest
from support.early_model import NEUTRAL_WEIGHTS, Scripted, step_signal

from edge_runtime.wearable.alerts import AlertEncoder, AlertPublisher
from edge_runtime.wearable.detector import DetectorConfig
from edge_runtime.wearable.labels import CLASSES
from edge_runtime.wearable.loop import AlertPolicy, Decision, Verdict, WearableLoop
from edge_runtime.wearable.sources import ImuBlock


class Fixed:
    """Answers with a fixed class and probability, and records what it was given."""

    classes = CLASSES

    def __init__(self, label="Texting", p=0.9):
        self.k, self.p, self.seen = CLASSES.index(label), p, []

    def classify_capture(self, x700):
        self.seen.append(x700)
        probs = np.full(len(CLASSES), (1 - self.p) / (len(CLASSES) - 1), np.float32)
        probs[self.k] = self.p
        return probs


def _steps(n, at, t_rest=9.81):
    acc = np.zeros((n, 3), np.float32)
    acc[:, 2] = t_rest
    for i, t in enumerate(at):
        acc[t:, 0] += 6.0 if i % 2 == 0 else -6.0
    return acc


def test_decisions_carry_stream_times_and_the_classifier_gets_the_capture():
    clf = Fixed()
    loop = WearableLoop(clf)
    acc = _steps(3000, [1000, 1300])
    ds = loop.feed(ImuBlock(t0_s=100.0, acc_mps2=acc))
    assert [d.t_trigger_s for d in ds] == [110.0]  # second step falls inside the pause
    assert ds[0].t_alert_s == 115.99  # last capture frame T+599
    assert clf.seen[0].shape == (700, 3)  # preprocessing is the classifier's (classify_capture)
    assert ds[0].alerted and ds[0].status == "alert" and loop.stats.captures == 1


def test_policy_never_alerts_other_and_flags_low_confidence():
    acc = _steps(3000, [1000])
    other = WearableLoop(Fixed("Other", 0.99)).feed(ImuBlock(0.0, acc))[0]
    unsure_policy = AlertPolicy(decision="early", min_confidence=0.5, class_weights=NEUTRAL_WEIGHTS)
    unsure = WearableLoop(Fixed("Phone", 0.4), policy=unsure_policy).feed(ImuBlock(0.0, acc))[0]
    assert (other.alerted, other.status) == (False, "not_alerted")
    assert (unsure.alerted, unsure.status) == (False, "uncertain")


def test_nan_run_is_counted_and_no_capture_spans_it():
    acc = _steps(4000, [1000])
    acc[1200:1210] = np.nan  # inside the capture of the trigger at 1000
    loop = WearableLoop(Fixed())
    ds = loop.feed(ImuBlock(0.0, acc))
    counts = loop.status.counts()
    assert ds == [] and counts.non_finite == 10 and counts.detector_restarts == 1 and counts.samples == 4000
    # after the hole, a new step triggers at its true stream time
    more = _steps(2000, [500])
    more[:, 0] += acc[-1, 0]
    ds = loop.feed(ImuBlock(40.0, more))
    assert [d.t_trigger_s for d in ds] == [45.0]


def test_gap_block_restarts_detector_and_times_follow_new_block():
    loop = WearableLoop(Fixed())
    loop.feed(ImuBlock(0.0, _steps(150, [])))
    acc = _steps(1500, [300])
    ds = loop.feed(ImuBlock(20.0, acc, continuous=False))
    assert loop.status.counts().detector_restarts == 1 and [d.t_trigger_s for d in ds] == [23.0]


def test_threshold_comes_from_config():
    acc = _steps(3000, [1000])
    acc[:, 0] *= 0.5  # a 3 m/s^2 step
    assert WearableLoop(Fixed()).feed(ImuBlock(0.0, acc)) == []
    assert len(WearableLoop(Fixed(), DetectorConfig(threshold_mps2=2.5)).feed(ImuBlock(0.0, acc))) == 1


class Publisher:
    """Stands in for AlertPublisher: records what it is handed, answers whether the frame went out."""

    def __init__(self, goes_out=True):
        from edge_runtime.wearable.alerts import WearableStatus

        self.status, self.goes_out, self.handed = WearableStatus(), goes_out, []

    def publish_alert(self, alert):
        self.handed.append(copy.deepcopy(alert))
        if not self.goes_out:
            return None
        if getattr(alert, "event_seq", None) is not None:  # an update goes out under its event's AlertSeq
            return alert.event_seq
        self.seqs = getattr(self, "seqs", -1) + 1
        return self.seqs  # the AlertSeq its frames carry


def _one_capture(label="Texting", p=0.9, goes_out=True, rx=None):
    pub = Publisher(goes_out)
    loop = WearableLoop(Fixed(label, p), publisher=pub)
    (d,) = loop.feed(ImuBlock(0.0, _steps(3000, [1000]), rx_monotonic_s=rx))
    return d, pub, loop


def test_a_would_alert_verdict_goes_to_the_publisher_and_the_decision_says_if_it_went_out():
    sent, pub, loop = _one_capture(rx=time.monotonic())
    assert (sent.alerted, sent.status, sent.alert_seq) == (True, "alert", 0) and sent.latency_ms >= 0
    assert sent.to_json()["alert_seq"] == 0
    assert loop.status.alert_latencies_ms() == [sent.latency_ms]
    (verdict,) = pub.handed
    assert type(verdict) is Verdict and verdict.status == "alert" and verdict.label == "Texting"

    lost, pub, loop = _one_capture(goes_out=False, rx=time.monotonic())
    assert (lost.alerted, lost.status, lost.latency_ms, lost.alert_seq) == (False, "alert_not_sent", None, None)
    assert loop.stats.statuses["alert"] == 1  # the summary counts what the policy said
    assert loop.status.alert_latencies_ms() == []

    replayed, _, _ = _one_capture()  # a recording: no arrival time to measure a latency from
    assert replayed.alerted and replayed.latency_ms is None


@pytest.mark.parametrize("label, p", [("Other", 0.99), ("Phone", 0.3)])
def test_what_the_policy_does_not_alert_never_reaches_the_publisher(label, p):
    d, pub, _ = _one_capture(label, p)
    assert not d.alerted and d.status in ("not_alerted", "uncertain") and pub.handed == []


def test_a_decision_is_complete_when_made_and_never_changed_afterwards():
    seen = []  # (the object an output handler got, a copy of it as it was then)
    loop = WearableLoop(Fixed(), publisher=Publisher(goes_out=False),
                        policy=AlertPolicy(decision="early", event_hold_s=0.0),
                        on_decision=lambda d: seen.append((d, copy.deepcopy(d))))
    acc = _steps(9000, [1000, 2000, 5000])
    returned = loop.feed(ImuBlock(0.0, acc[:4000], rx_monotonic_s=time.monotonic()))
    returned += loop.feed(ImuBlock(40.0, acc[4000:], rx_monotonic_s=time.monotonic()))
    assert len(returned) == 3 and [d for d, _ in seen] == returned
    assert all(type(d) is Decision and d.status == "alert_not_sent" for d in returned)  # final when handed out
    assert all(d == then for d, then in seen)  # untouched after the handlers read it


def _heartbeats_until(rx, want, deadline_s=10.0):
    enc, states = AlertEncoder(), []
    end = time.monotonic() + deadline_s
    while time.monotonic() < end:
        m = rx.recv(0.05)
        if m is not None and m.arbitration_id == 0x3A1:
            sig = enc.decode(m)
            states.append((str(sig["State"]), str(sig["SensorHealth"])))
            if states[-1] == want:
                break
    return states


def test_the_heartbeat_thread_reports_what_the_loop_counts():
    bus = can.Bus(interface="virtual", channel="loop-hb", receive_own_messages=False)
    rx = can.Bus(interface="virtual", channel="loop-hb")
    pub = AlertPublisher(bus, heartbeat_period_s=0.01).start()
    try:
        loop = WearableLoop(Fixed(), publisher=pub)
        assert ("starting", "ok") in _heartbeats_until(rx, ("starting", "ok"))
        loop.feed(ImuBlock(0.0, _steps(150, [])))
        assert _heartbeats_until(rx, ("running", "ok"))[-1] == ("running", "ok")
        holes = _steps(150, [])
        holes[10:15] = np.nan
        loop.feed(ImuBlock(1.5, holes))
        assert _heartbeats_until(rx, ("degraded", "nan_samples"))[-1] == ("degraded", "nan_samples")
        assert _heartbeats_until(rx, ("running", "ok"))[-1] == ("running", "ok")  # for one period only
    finally:
        pub.close()
        rx.shutdown()
    counts = pub.status.counts()
    assert (counts.samples, counts.non_finite, counts.detector_restarts) == (300, 5, 1)


# ---------------------------------------------------------------------------- early decisions and events


def Policy(**kw):
    """An early policy that alerts from S = 1 at the manifest's thresholds (else 0.9): the loop's mechanics,
    not the shipped operating point (tests/sim/test_early_tuning.py pins that one to its validation report),
    with the model's own probabilities (no class weights)."""
    return AlertPolicy(**{"decision": "early", "min_confidence_by_steps": (-1.0,) * 6, "earliest_alert_step": 1,
                          "class_weights": NEUTRAL_WEIGHTS, **kw})


def _early_run(answers, policy=Policy(), acc=None, split=None, clf=None, **kw):
    pub = Publisher()
    clf = Scripted(answers, **kw) if clf is None else clf
    loop = WearableLoop(clf, policy=policy, publisher=pub)
    acc = _steps(3000, [1000]) if acc is None else acc
    cuts = range(0, len(acc), split) if split else [0]
    ds = []
    for a in cuts:
        got = loop.feed(ImuBlock(a / 100.0, acc[a : a + (split or len(acc))], continuous=a > 0))
        if split == 1:  # fed sample by sample: each decision comes with the very sample it waited for
            assert all(round(d.t_alert_s * 100) == a for d in got)
        ds += got
    return ds, pub, clf, loop


def _summary(ds):
    return [(d.status, d.steps, d.label, d.alert_seq) for d in ds]


def test_a_confident_early_step_is_a_preliminary_alert_then_the_full_window_confirms_it():
    ds, pub, clf, _ = _early_run({2: ("Phone", 0.95), 3: ("Phone", 0.97), 6: ("Phone", 0.8)})
    assert _summary(ds) == [("preliminary", 2, "Phone", 0), ("confirmed", 6, "Phone", 0)]
    # the trigger is frame 1000, the capture starts at 900: S sub-windows are decided at frame 900 + needed - 1
    assert [d.t_alert_s for d in ds] == [(900 + 263 - 1) / 100, (900 + 700 - 1) / 100]
    assert all(d.event_start_s == 10.0 and d.t_trigger_s == 10.0 for d in ds)
    assert [v.event_seq for v in pub.handed] == [None, 0]  # the update goes out under the event's AlertSeq
    acc = _steps(3000, [1000])
    for steps, x in clf.seen:  # each step saw exactly the capture's first frames it needs
        assert len(x) == [148, 263, 379, 494, 610, 700][steps - 1]
        np.testing.assert_array_equal(x, acc[900 : 900 + len(x)])
    assert [s for s, _ in clf.seen] == [1, 2, 3, 4, 5, 6]


def test_a_preliminary_alert_may_be_revised_and_the_full_window_may_withdraw_it():
    ds, *_ = _early_run({2: ("Phone", 0.95), 4: ("Texting", 0.95), 6: ("Texting", 0.9)})
    assert _summary(ds) == [("preliminary", 2, "Phone", 0), ("revised", 4, "Texting", 0), ("confirmed", 6, "Texting", 0)]
    ds, *_ = _early_run({1: ("Drink", 0.99), 6: ("Marker", 0.9)})
    assert _summary(ds) == [("preliminary", 1, "Drink", 0), ("revised", 6, "Marker", 0)]
    for final in [("Other", 0.95), ("Drink", 0.4)]:  # Other, or uncertain: the alert is withdrawn
        ds, pub, _, loop = _early_run({1: ("Drink", 0.99), 6: final})
        assert _summary(ds) == [("preliminary", 1, "Drink", 0), ("withdrawn", 6, final[0], 0)]
        assert ds[-1].alerted and pub.handed[-1].status == "withdrawn"


def test_unconfident_early_steps_wait_and_full_window_mode_decides_once():
    ds, pub, *_ = _early_run({2: ("Phone", 0.85), 6: ("Phone", 0.8)})  # 0.85 < 0.9, the default early threshold
    assert _summary(ds) == [("alert", 6, "Phone", 0)] and pub.handed[0].event_seq is None
    ds, _, clf, _ = _early_run({2: ("Phone", 0.95), 6: ("Phone", 0.8)}, policy=Policy(decision="full_window"))
    assert _summary(ds) == [("alert", 6, "Phone", 0)] and [s for s, _ in clf.seen] == [6]
    ds, *_ = _early_run({2: ("Phone", 0.95), 6: ("Phone", 0.8)}, early_steps=(6,))  # a fixed-S model
    assert _summary(ds) == [("alert", 6, "Phone", 0)]


def test_the_shipped_operating_point_alerts_from_s2_at_its_threshold_and_waits_below_it():
    """What the [alerts] defaults do on the capture path with early decisions (their values are pinned to the
    validation report in tests/sim/test_early_tuning.py): no alert at S = 1 however sure, a preliminary alert at
    S = 2 once the step's confidence reaches the shipped threshold (just above it: the model's float32), none just
    below it."""
    shipped = AlertPolicy(decision="early", class_weights=NEUTRAL_WEIGHTS)
    at = {s: shipped.threshold(s, {}) for s in (2, 3)}
    assert shipped.earliest_alert_step == 2 and all(0.5 < t < 1.0 for t in at.values())
    sure = {1: ("Drink", 0.999), 2: ("Phone", at[2] + 0.001), 6: ("Phone", 0.8)}
    ds, *_ = _early_run(sure, policy=shipped)
    assert _summary(ds) == [("preliminary", 2, "Phone", 0), ("confirmed", 6, "Phone", 0)]
    below = {2: ("Phone", at[2] - 0.01), 3: ("Phone", at[3] + 0.001), 6: ("Phone", 0.8)}
    assert _summary(_early_run(below, policy=shipped)[0])[0] == ("preliminary", 3, "Phone", 0)


def test_early_thresholds_come_from_the_config_else_the_manifest():
    answers = {2: ("Phone", 0.85), 6: ("Phone", 0.8)}
    ds, *_ = _early_run(answers, manifest_thresholds={2: 0.8})
    assert _summary(ds)[0] == ("preliminary", 2, "Phone", 0)
    ds, *_ = _early_run(answers, manifest_thresholds={2: 0.8},
                        policy=Policy(min_confidence_by_steps=(-1.0, 0.86, -1.0, -1.0, -1.0, -1.0)))
    assert _summary(ds) == [("alert", 6, "Phone", 0)]
    # the full window: configured, else the manifest's, else min_confidence
    assert _summary(_early_run(answers, manifest_thresholds={6: 0.85})[0])[-1] == ("uncertain", 6, "Phone", None)
    assert _summary(_early_run(answers, manifest_thresholds={6: 0.85}, policy=Policy(
        min_confidence_by_steps=(-1.0,) * 5 + (0.7,)))[0])[-1] == ("alert", 6, "Phone", 0)


def test_a_threshold_of_1_before_the_full_window_means_no_decision_and_no_model_call_at_that_step():
    answers = {1: ("Drink", 1.0), 3: ("Phone", 1.0), 6: ("Phone", 0.8)}  # confidence 1: what float32 may round to
    ds, _, clf, loop = _early_run(answers, manifest_thresholds={1: 1.0})
    assert [s for s, _ in clf.seen] == [2, 3, 4, 5, 6] and loop.decision_mode == "early decisions after S = 2,3,4,5,6"
    assert _summary(ds) == [("preliminary", 3, "Phone", 0), ("confirmed", 6, "Phone", 0)]
    ds, _, clf, loop = _early_run(answers, policy=AlertPolicy(decision="early",
                                                              min_confidence_by_steps=(1.0,) * 5 + (-1.0,)))
    assert [s for s, _ in clf.seen] == [6] and _summary(ds) == [("alert", 6, "Phone", 0)]
    assert loop.decision_mode == "full-window decisions (every S < 6 has threshold 1)"


class Torn(Scripted):
    """Scripted, with a runner-up class per step: (label, p) whose probability is taken from the rest."""

    def __init__(self, answers, runner_up, **kw):
        super().__init__(answers, **kw)
        self.runner_up = runner_up

    def classify_prefix(self, x, steps):
        probs = super().classify_prefix(x, steps)
        if steps in self.runner_up:
            label, p = self.runner_up[steps]
            top = int(np.argmax(probs))
            rest = [k for k in range(len(CLASSES)) if k not in (top, CLASSES.index(label))]
            probs[CLASSES.index(label)] = p
            probs[rest] = (1 - probs[top] - p) / len(rest)
        return probs


def test_no_preliminary_alert_before_the_earliest_step():
    answers = {2: ("Phone", 0.95), 3: ("Phone", 0.95), 6: ("Phone", 0.9)}
    ds, *_ = _early_run(answers, Policy(earliest_alert_step=3))
    assert _summary(ds) == [("preliminary", 3, "Phone", 0), ("confirmed", 6, "Phone", 0)]
    # a revision waits too; the full window always decides
    ds, *_ = _early_run({1: ("Drink", 0.99), 2: ("Phone", 0.95), 6: ("Phone", 0.9)}, Policy(earliest_alert_step=6))
    assert _summary(ds) == [("alert", 6, "Phone", 0)]


def test_steps_before_the_earliest_alert_step_are_not_computed_unless_agreement_needs_them():
    answers = {2: ("Phone", 0.95), 3: ("Phone", 0.95), 6: ("Phone", 0.9)}
    ds, _, clf, loop = _early_run(answers, Policy(earliest_alert_step=3))
    assert [s for s, _ in clf.seen] == [3, 4, 5, 6] and loop.decision_mode == "early decisions after S = 3,4,5,6"
    assert _summary(ds) == [("preliminary", 3, "Phone", 0), ("confirmed", 6, "Phone", 0)]
    ds, _, clf, _ = _early_run(answers, Policy(earliest_alert_step=3, early_agreement_steps=2))
    assert [s for s, _ in clf.seen] == [2, 3, 4, 5, 6]  # S = 2 must agree with S = 3
    assert _summary(ds) == [("preliminary", 3, "Phone", 0), ("confirmed", 6, "Phone", 0)]


def test_two_steps_must_agree_before_an_early_alert_or_a_revision():
    answers = {1: ("Drink", 0.5), 2: ("Phone", 0.95), 3: ("Phone", 0.95), 6: ("Phone", 0.9)}
    assert _summary(_early_run(answers)[0])[0] == ("preliminary", 2, "Phone", 0)
    ds, *_ = _early_run(answers, Policy(early_agreement_steps=2))
    assert _summary(ds) == [("preliminary", 3, "Phone", 0), ("confirmed", 6, "Phone", 0)]
    # agreement counts the top class, confident or not: S = 1 says Phone at 0.3
    ds, *_ = _early_run({2: ("Phone", 0.95), 6: ("Phone", 0.9)}, Policy(early_agreement_steps=2))
    assert _summary(ds)[0] == ("preliminary", 2, "Phone", 0)
    answers = {2: ("Phone", 0.95), 4: ("Texting", 0.95), 5: ("Texting", 0.95), 6: ("Texting", 0.9)}
    ds, *_ = _early_run(answers, Policy(early_agreement_steps=2))
    assert _summary(ds) == [("preliminary", 2, "Phone", 0), ("revised", 5, "Texting", 0),
                            ("confirmed", 6, "Texting", 0)]


def test_an_early_step_torn_between_two_classes_waits():
    answers = {2: ("Phone", 0.5), 3: ("Phone", 0.8), 6: ("Phone", 0.9)}
    policy = Policy(early_min_margin=0.2, min_confidence_by_steps=(-1.0, 0.5, 0.5, -1.0, -1.0, -1.0))
    ds = _early_run(answers, policy, clf=Torn(answers, {2: ("Texting", 0.45), 3: ("Texting", 0.1)}))[0]
    assert _summary(ds) == [("preliminary", 3, "Phone", 0), ("confirmed", 6, "Phone", 0)]
    ds = _early_run(answers, Policy(min_confidence_by_steps=policy.min_confidence_by_steps),
                    clf=Torn(answers, {2: ("Texting", 0.35)}))[0]
    assert _summary(ds)[0] == ("preliminary", 2, "Phone", 0)  # no margin asked: the confident step alerts


@pytest.mark.parametrize("key, value", [("earliest_alert_step", 0), ("earliest_alert_step", 7),
                                        ("early_agreement_steps", 0), ("early_min_margin", 1.5)])
def test_early_policy_settings_are_validated(key, value):
    from edge_runtime import config

    with pytest.raises(config.ConfigError, match=rf"\[alerts\] {key}: must be"):
        config.from_dict({"alerts": {key: value}}, "box.toml")


def test_early_decisions_do_not_depend_on_how_the_stream_is_cut():
    acc = _steps(9000, [1000, 4000])
    answers = {1: ("Drink", 0.99), 3: ("Phone", 0.95), 6: ("Phone", 0.9)}
    policy = Policy(event_hold_s=0.0)
    whole = _summary(_early_run(answers, policy, acc)[0])
    assert whole == [("preliminary", 1, "Drink", 0), ("revised", 3, "Phone", 0), ("confirmed", 6, "Phone", 0),
                     ("preliminary", 1, "Drink", 1), ("revised", 3, "Phone", 1), ("confirmed", 6, "Phone", 1)]
    for split in (1, 7, 100, 333):
        ds = _early_run(answers, policy, acc, split=split)[0]
        assert _summary(ds) == whole
        assert [d.t_alert_s for d in ds] == [d.t_alert_s for d in _early_run(answers, policy, acc)[0]]


def test_a_capture_during_an_active_event_continues_it_and_raises_no_alert():
    # captures at 10 s, 20 s (4 s after the first ended: the hand returning), 45 s (19 s of quiet: a new event)
    acc = _steps(8000, [1000, 2000, 4500])
    ds, pub, _, loop = _early_run({2: ("Phone", 0.95), 6: ("Phone", 0.9)}, Policy(event_hold_s=10.0), acc)
    assert _summary(ds) == [("preliminary", 2, "Phone", 0), ("confirmed", 6, "Phone", 0),
                            ("continued", 6, "Phone", None),
                            ("preliminary", 2, "Phone", 1), ("confirmed", 6, "Phone", 1)]
    assert [d.event_start_s for d in ds] == [10.0, 10.0, 10.0, 45.0, 45.0]
    assert not ds[2].alerted and len(pub.handed) == 4 and loop.stats.events == 2
    # event_hold_s = 0: every capture is its own event
    ds, *_ = _early_run({2: ("Phone", 0.95), 6: ("Phone", 0.9)}, Policy(event_hold_s=0.0), acc)
    assert [d.alert_seq for d in ds if d.steps == 2] == [0, 1, 2]


def test_a_withdrawn_alert_ends_its_event():
    acc = _steps(8000, [1000, 2000])
    ds, *_ = _early_run({2: ("Phone", 0.95), 6: ("Other", 0.9)}, Policy(event_hold_s=10.0), acc)
    assert _summary(ds) == [("preliminary", 2, "Phone", 0), ("withdrawn", 6, "Other", 0),
                            ("preliminary", 2, "Phone", 1), ("withdrawn", 6, "Other", 1)]


def test_decisions_in_the_alert_log_carry_steps_and_event_start():
    ds, *_ = _early_run({2: ("Phone", 0.95), 6: ("Phone", 0.8)})
    line = ds[0].to_json()
    assert (line["status"], line["steps"], line["alert_seq"], line["event_start_s"]) == ("preliminary", 2, 0, 10.0)


def test_a_capture_cut_by_a_gap_gets_no_update_and_the_next_capture_decides_early_again():
    pub = Publisher()
    loop = WearableLoop(Scripted({1: ("Phone", 0.95), 6: ("Phone", 0.9)}), policy=Policy(event_hold_s=60.0),
                        publisher=pub)  # a long hold: only the cut ends the event
    acc = step_signal(1300, [1000])
    first = loop.feed(ImuBlock(0.0, acc))  # the capture from frame 900 holds 400 frames when the stream stops
    assert _summary(first) == [("preliminary", 1, "Phone", 0)]
    later = step_signal(3000, [1000])
    ds = []
    for a in range(0, 3000, 1):  # after the gap, sample by sample
        got = loop.feed(ImuBlock(100.0 + a / 100.0, later[a : a + 1], continuous=a > 0))
        assert all(round((d.t_alert_s - 100.0) * 100) == a for d in got)
        ds += got
    assert _summary(ds) == [("preliminary", 1, "Phone", 1), ("confirmed", 6, "Phone", 1)]


class _OtherOnStepDown(Scripted):
    """A capture whose x steps down (the hand doing something else, say) is Other at the full window."""

    def classify_prefix(self, x, steps):
        if steps == 6 and x[-1, 0] < x[0, 0]:
            self.seen.append((steps, np.array(x)))
            return self._probs("Other", 0.9)
        return super().classify_prefix(x, steps)


def test_a_capture_of_an_active_event_that_says_other_ends_the_event():
    # captures at 10 s (up: Phone), 20 s (down: Other, within the hold: continued) and 30 s (up again,
    # within the hold of the second capture's end): the Other capture ended the event, so the third alerts
    acc = _steps(8000, [1000, 2000, 3000])
    answers = {2: ("Phone", 0.95), 6: ("Phone", 0.9)}
    ds, *_ = _early_run(answers, Policy(event_hold_s=10.0), acc, clf=_OtherOnStepDown(answers))
    assert _summary(ds) == [("preliminary", 2, "Phone", 0), ("confirmed", 6, "Phone", 0),
                            ("continued", 6, "Other", None),
                            ("preliminary", 2, "Phone", 1), ("confirmed", 6, "Phone", 1)]
    assert [d.event_start_s for d in ds] == [10.0, 10.0, 10.0, 30.0, 30.0]
    # without the rule the Other capture extends the event and the third capture only continues it
    ds, *_ = _early_run(answers, Policy(event_hold_s=10.0, event_ends_on_other=False), acc,
                        clf=_OtherOnStepDown(answers))
    assert [d.status for d in ds] == ["preliminary", "confirmed", "continued", "continued"]


def test_class_weights_reweigh_the_probabilities_before_every_decision():
    # the full window says Other 0.5, Marker 0.3 (the rest 0.05 each): weighting Marker by 5 makes it
    # Marker 1.5 / 2.2 = 0.68, an alert; the decision carries the weighted probabilities
    class OtherOverMarker(Scripted):
        def classify_prefix(self, x, steps):
            probs = np.full(len(CLASSES), 0.05, np.float32)
            probs[CLASSES.index("Other")], probs[CLASSES.index("Marker")] = 0.5, 0.3
            return probs

    ds, *_ = _early_run({}, Policy(), clf=OtherOverMarker({}))
    assert [(d.status, d.label) for d in ds] == [("not_alerted", "Other")]
    weights = tuple(5.0 if c == "Marker" else 1.0 for c in CLASSES)
    ds, *_ = _early_run({}, Policy(class_weights=weights), clf=OtherOverMarker({}))
    assert [(d.status, d.label) for d in ds] == [("alert", "Marker")]
    assert ds[0].confidence == pytest.approx(1.5 / 2.2) and sum(ds[0].probs.values()) == pytest.approx(1.0)
    with pytest.raises(ValueError, match="class_weights"):
        AlertPolicy(class_weights=(1.0, 2.0))


def test_a_new_alert_needs_the_mean_p_other_of_its_later_steps_below_max_mean_other():
    # S = 3..5 say Other 0.6, the full window Phone 0.7 (P(Other) 0.06): mean P(Other) over S = 3..6 0.465
    answers = {3: ("Other", 0.6), 4: ("Other", 0.6), 5: ("Other", 0.6), 6: ("Phone", 0.7)}
    ds, *_ = _early_run(answers, Policy(max_mean_other=1.0))
    assert _summary(ds) == [("alert", 6, "Phone", 0)]
    ds, pub, *_ = _early_run(answers, Policy(max_mean_other=0.47))
    assert _summary(ds) == [("alert", 6, "Phone", 0)]
    ds, pub, *_ = _early_run(answers, Policy(max_mean_other=0.46))
    assert _summary(ds) == [("uncertain", 6, "Phone", None)] and pub.handed == []
    # a preliminary alert at S = 4 reads S = 3 and 4 (Other 0.8, then 0.01): 0.405
    early = {3: ("Other", 0.8), 4: ("Phone", 0.95), 6: ("Phone", 0.9)}
    assert _summary(_early_run(early, Policy(max_mean_other=0.41))[0])[0] == ("preliminary", 4, "Phone", 0)
    assert _summary(_early_run(early, Policy(max_mean_other=0.4))[0]) == [("alert", 6, "Phone", 0)]
    # S = 1 and 2 do not count, and an alert already open is confirmed whatever its steps said
    opened = {2: ("Phone", 0.95), 3: ("Other", 0.9), 4: ("Other", 0.9), 5: ("Other", 0.9), 6: ("Phone", 0.7)}
    assert _summary(_early_run(opened, Policy(max_mean_other=0.1))[0]) == [("preliminary", 2, "Phone", 0),
                                                                          ("confirmed", 6, "Phone", 0)]
