"""Alerts decided while the CAN bus is down are held, sent late or counted lost, never dropped silently."""
from types import SimpleNamespace

import can

from edge_runtime.wearable.alerts import UNDELIVERED_HEARTBEATS, AlertEncoder, AlertPublisher, Clock, WearableStatus
from edge_runtime.wearable.backlog import AlertBacklog


class SwitchableBus(can.BusABC):
    """A bus that raises while ``down`` and records what it took."""

    def __init__(self):
        super().__init__(channel="x")
        self.down, self.sent = True, []

    def send(self, msg, timeout=None):
        if self.down:
            raise can.CanOperationError("bus off")
        self.sent.append(msg)

    def _recv_internal(self, timeout):
        return None, False


class FakeClock:
    def __init__(self):
        self.t = 100.0

    def __call__(self):
        return self.t


def alert(label="Phone"):
    return SimpleNamespace(t_trigger_s=10.0, t_alert_s=10.75, label=label, confidence=0.9, alerted=True,
                           status="alert", probs={}, compute_us=2500.0)


def test_alerts_held_while_the_bus_is_down_go_out_late_with_their_age_and_the_status_says_so():
    bus, clock = SwitchableBus(), FakeClock()
    pub = AlertPublisher(bus, status=WearableStatus())
    pub.backlog = AlertBacklog(clock=clock)
    pub.status.count_samples(100)
    assert pub.status.heartbeat()["state"] == "running"
    assert not pub.send_alert(alert("Phone")) and not pub.send_alert(alert("Drink"))
    clock.t += 2.0  # the bus is back two seconds later
    bus.down = False
    assert pub.send_alert(alert("Texting"))
    decoded = [AlertEncoder().decode(m) for m in bus.sent]
    assert [str(d["Class"]) for d in decoded] == ["Phone", "Drink", "Texting"]
    assert decoded[0]["TimeSinceTrigger"] == 750 + 3 + 2000  # the decision's 753 ms plus the 2 s it waited
    assert decoded[2]["TimeSinceTrigger"] == 753
    assert pub.status.heartbeat()["state"] == "degraded"  # not "running" as if nothing happened
    s = pub.summary()
    assert (s["alerts_held"], s["alerts_sent_late"], s["alerts_lost"], s["alerts_sent"]) == (2, 2, 0, 3)


def test_too_old_overflowing_or_never_sent_alerts_are_counted_lost():
    clock = FakeClock()
    backlog = AlertBacklog(max_alerts=2, max_age_s=5.0, clock=clock)
    for label in ("Phone", "Drink", "Marker"):  # the third pushes the oldest out
        backlog.hold(alert(label))
    clock.t += 6.0
    late, too_old = backlog.take()
    assert late == [] and too_old == 2 and backlog.counts().lost == 3
    backlog.hold(alert())
    assert backlog.abandon() == 1 and backlog.counts().lost == 4 and backlog.counts().held == 4


def test_the_summary_reports_alerts_still_held_at_the_end_as_lost():
    bus = SwitchableBus()
    pub = AlertPublisher(bus, status=WearableStatus())
    assert not pub.send_alert(alert())
    pub.close()
    assert pub.summary()["alerts_lost"] == 1


def test_undelivered_alerts_keep_the_status_degraded_for_five_heartbeats_then_running():
    bus = SwitchableBus()
    pub = AlertPublisher(bus, status=WearableStatus())
    pub.status.count_samples(100)
    assert pub.status.heartbeat()["state"] == "running"
    assert not pub.send_alert(alert("Phone"))
    bus.down = False
    assert pub.send_alert(alert("Drink"))  # the held Phone goes out late first
    states = [pub.status.heartbeat() for _ in range(UNDELIVERED_HEARTBEATS + 2)]
    assert [s["state"] for s in states] == ["degraded"] * UNDELIVERED_HEARTBEATS + ["running"] * 2
    assert {s["sensor_health"] for s in states} == {"ok"}  # the sensor is not what went wrong


def test_an_alert_sent_late_goes_out_with_its_copies_like_one_sent_on_time():
    bus, clock = SwitchableBus(), FakeClock()
    pub = AlertPublisher(bus, status=WearableStatus(), clock=Clock.DATA)
    pub.backlog = AlertBacklog(clock=clock)
    assert not pub.send_alert(alert("Phone"))  # held: the bus is down
    bus.down = False
    clock.t += 1.0
    on_time = SimpleNamespace(**{**vars(alert("Drink")), "t_trigger_s": 20.0, "t_alert_s": 20.75})
    assert pub.send_alert(on_time)  # the held Phone goes out late first, then the Drink
    pub.advance_to(30.0)  # every copy is due by then
    enc = AlertEncoder()
    frames = [enc.decode(m) for m in bus.sent if m.arbitration_id == enc.alert_msg.frame_id]
    by_seq: dict[int, list] = {}
    for f in frames:
        by_seq.setdefault(f["AlertSeq"], []).append(f)
    assert [str(fs[0]["Class"]) for fs in by_seq.values()] == ["Phone", "Drink"]
    assert [len(fs) for fs in by_seq.values()] == [1 + enc.repetition.copies] * 2
    late = [f["TimeSinceTrigger"] for f in by_seq[min(by_seq)]]
    assert late[0] == 750 + 3 + 1000 and late == sorted(late)  # its wait counted, each copy older
