"""The loop's bookkeeping, with a stand-in classifier (the shipped model has its own tests)."""
import numpy as np

from edge_runtime.wearable.detector import DetectorConfig
from edge_runtime.wearable.labels import CLASSES
from edge_runtime.wearable.loop import AlertPolicy, WearableLoop
from edge_runtime.wearable.sources import ImuBlock


class Fixed:
    """Answers with a fixed class and probability, and records what it was given."""

    classes = CLASSES

    def __init__(self, label="Texting", p=0.9):
        self.k, self.p, self.seen = CLASSES.index(label), p, []

    def classify(self, x):
        self.seen.append(x)
        probs = np.full((len(x), len(CLASSES)), (1 - self.p) / (len(CLASSES) - 1), np.float32)
        probs[:, self.k] = self.p
        return probs


def _steps(n, at, t_rest=9.81):
    acc = np.zeros((n, 3), np.float32)
    acc[:, 2] = t_rest
    for i, t in enumerate(at):
        acc[t:, 0] += 6.0 if i % 2 == 0 else -6.0
    return acc


def test_decisions_carry_stream_times_and_model_input_shape():
    clf = Fixed()
    loop = WearableLoop(clf)
    acc = _steps(3000, [1000, 1300])
    ds = loop.feed(ImuBlock(t0_s=100.0, acc_mps2=acc))
    assert [d.t_trigger_s for d in ds] == [110.0]  # second step falls inside the pause
    assert ds[0].t_alert_s == 115.99  # last capture frame T+599
    assert clf.seen[0].shape == (1, 6, 33, 3)
    assert ds[0].alerted and ds[0].status == "alert" and loop.stats.captures == 1


def test_policy_never_alerts_other_and_flags_low_confidence():
    acc = _steps(3000, [1000])
    other = WearableLoop(Fixed("Other", 0.99)).feed(ImuBlock(0.0, acc))[0]
    unsure = WearableLoop(Fixed("Phone", 0.4), policy=AlertPolicy(min_confidence=0.5)).feed(ImuBlock(0.0, acc))[0]
    assert (other.alerted, other.status) == (False, "not_alerted")
    assert (unsure.alerted, unsure.status) == (False, "uncertain")


def test_nan_run_is_counted_and_no_capture_spans_it():
    acc = _steps(4000, [1000])
    acc[1200:1210] = np.nan  # inside the capture of the trigger at 1000
    loop = WearableLoop(Fixed())
    ds = loop.feed(ImuBlock(0.0, acc))
    assert ds == [] and loop.stats.non_finite == 10 and loop.stats.detector_resets == 1
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
    assert loop.stats.detector_resets == 1 and [d.t_trigger_s for d in ds] == [23.0]


def test_threshold_comes_from_config():
    acc = _steps(3000, [1000])
    acc[:, 0] *= 0.5  # a 3 m/s^2 step
    assert WearableLoop(Fixed()).feed(ImuBlock(0.0, acc)) == []
    assert len(WearableLoop(Fixed(), DetectorConfig(threshold_mps2=2.5)).feed(ImuBlock(0.0, acc))) == 1
