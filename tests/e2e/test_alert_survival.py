"""Alerts survive lost frames (issue 12 item 6): a drive replayed onto a hub that drops a fifth of
the frames; the integrator's stock-tools listener gets every alert, from a copy when the first
frame is lost, within 200 ms of it, and counts none twice. The full figure (>= 100 alerts) is
``python -m support.alert_survival`` (tests/support/alert_survival.py)."""
import pytest
from support.alert_survival import measure

pytestmark = pytest.mark.slow  # starts the simulator, the runtime and the listener


def _every_alert_once(r: dict) -> None:
    assert r["hub_dropped"] > 0.1 * r["hub_frames_in"]  # the hub did drop about a fifth
    assert (r["alerts_received"], r["received_twice"], r["unknown"]) == (r["alerts_sent"], 0, 0)
    assert r["classes_match"] and r["max_recovery_ms"] <= 200
    assert r["listener"]["alerts"] + r["listener"]["updates"] == r["alerts_sent"] and r["listener"]["alert_copies"] > 0


def test_every_replayed_alert_reaches_the_listener_once_at_20_percent_frame_drop(tmp_path):
    """A replay is on the data clock: the frames' order, hence which the seeded hub drops, is fixed."""
    # 15 minutes, so that some alert loses its first frame for any hub seed but a rare one (with n
    # alerts none does with probability 0.8^n: 13 % for the 9 of a 5-minute drive, which made the
    # outcome depend on the seed and on the alert policy of the day)
    r = measure(tmp_path, minutes=15, seed=11, drop=0.2, hub_seed=5)
    assert r["alerts_sent"] >= 20
    assert r["first_frame_lost"] >= 1  # some alert was recovered from a copy, not from its first frame
    _every_alert_once(r)


def test_every_live_alert_reaches_the_listener_once_at_20_percent_frame_drop(tmp_path):
    """A live source is on the wall clock: the copies come from the heartbeat thread."""
    r = measure(tmp_path, minutes=3, seed=11, drop=0.2, hub_seed=4, speed=10)
    assert r["alerts_sent"] >= 5
    _every_alert_once(r)
