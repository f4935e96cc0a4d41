"""WEARABLE_STATUS fields follow the loop's and the serial source's counters."""
from types import SimpleNamespace

from edge_runtime.__main__ import _status
from edge_runtime.wearable.loop import LoopStats


def _loop(**kw):
    return SimpleNamespace(stats=LoopStats(**kw))


def _health():
    return {"sensor": "ok", "non_finite": 0, "gaps": 0, "saturated": 0}


def test_starting_then_running_then_each_fault_for_one_period():
    h = _health()
    assert _status(_loop(), h)["state"] == "starting"
    assert _status(_loop(samples=100), h) == {"state": "running", "sensor_health": "ok", "dropped_samples": 0}
    src = SimpleNamespace(saturated=3, dropped=5)
    st = _status(_loop(samples=200, non_finite=2), h, src)
    assert st == {"state": "degraded", "sensor_health": "nan_samples", "dropped_samples": 7}
    assert _status(_loop(samples=300, non_finite=2), h, src)["state"] == "running"  # nothing new since
    src.saturated = 4
    assert _status(_loop(samples=400, non_finite=2), h, src)["sensor_health"] == "saturated"
    assert _status(_loop(samples=500, non_finite=2, detector_resets=1), h, src)["sensor_health"] == "gaps"
    h["sensor"] = "silent"
    assert _status(_loop(samples=500, non_finite=2), h, src)["state"] == "sensor_silent"


def test_dropped_samples_saturate_at_the_signal_range():
    st = _status(_loop(samples=1, non_finite=70000), _health())
    assert st["dropped_samples"] == 65535
