"""wearable/stream_decider.py: the trigger-free streaming decider (issue 12), with a stand-in classifier (the
shipped stream model has its own tests in tests/export/test_stream_model.py): the alert rule, the 25 Hz steps and
windows, the alert path it shares with the capture loop, and its selection by the configuration."""
import json

import can
import numpy as np
import pytest

from edge_runtime import __main__ as table
from edge_runtime import config
from edge_runtime.errors import ConfigError
from edge_runtime.wearable import command
from edge_runtime.wearable.alerts import AlertEncoder, AlertPublisher, Clock
from edge_runtime.wearable.labels import CLASSES, OTHER
from edge_runtime.wearable.loop import WearableLoop
from edge_runtime.wearable.sources import ImuBlock
from edge_runtime.wearable.stream_decider import (
    STREAM_STEPS,
    Opened,
    StreamDecider,
    StreamLoop,
    StreamModel,
    StreamParams,
)

PHONE, TEXTING, I_OTHER = CLASSES.index("Phone"), CLASSES.index("Texting"), CLASSES.index(OTHER)
DECISION_KEYS = ["t_trigger_s", "t_alert_s", "label", "confidence", "alerted", "status", "probs", "compute_us",
                 "latency_ms", "alert_seq", "steps", "event_start_s"]
"""The ``--alerts`` line of every decision, the capture path's (tests/wearable/test_command.py)."""


def _p(**by_class) -> list[float]:
    """Probabilities in CLASSES order; the rest of the mass on Other."""
    p = [0.0] * len(CLASSES)
    for name, v in by_class.items():
        p[CLASSES.index(name)] = v
    p[I_OTHER] = 1.0 - sum(p)
    return p


PHONE_HOP, OTHER_HOP, UNSURE_HOP = _p(Phone=0.8), _p(), _p(Phone=0.45)


RULE_PARAMS = {"hop_s": 0.48, "threshold": 0.7}
"""The rule's tests below are written for session 21's stream B (hop 0.48 s, threshold 0.7), not for whatever
the section's defaults are."""


def _run(hops, **params):
    rule = StreamDecider(StreamParams(**{**RULE_PARAMS, **params}), CLASSES)
    return [rule.hop(0.48 * i, p) for i, p in enumerate(hops)]


# ---------------------------------------------------------------------------- the alert rule


def test_an_alert_needs_k_consecutive_hops_over_the_threshold():
    said = _run([PHONE_HOP, PHONE_HOP, UNSURE_HOP, PHONE_HOP, PHONE_HOP, PHONE_HOP])  # k = 3, threshold 0.7
    assert said[:5] == [None] * 5  # two, broken by a hop under the threshold, then two: not yet
    assert said[5] == Opened(t_trigger_s=0.48 * 3, label="Phone", confidence=0.8)  # the first of the k hops
    assert _run([PHONE_HOP] * 2, consecutive_hops=2)[1] == Opened(0.0, "Phone", 0.8)


def test_the_alert_class_is_the_largest_summed_probability_over_the_k_hops():
    hops = [_p(Texting=0.9), _p(Phone=0.75), _p(Phone=0.75)]  # Phone tops two hops, Texting sums more: 0.9 vs 1.5
    assert _run(hops)[-1].label == "Phone"
    hops = [_p(Texting=0.95, Phone=0.01), _p(Phone=0.71, Texting=0.2), _p(Phone=0.71, Texting=0.2)]
    assert _run(hops)[-1].label == "Phone"  # 1.43 vs 1.35
    hops = [_p(Texting=0.95, Phone=0.01), _p(Phone=0.71, Texting=0.28), _p(Phone=0.71, Texting=0.28)]
    assert _run(hops)[-1].label == "Texting"  # 1.43 vs 1.51


def test_one_event_is_one_alert_until_off_s_of_other_closes_it():
    # open, stay confident, two Other hops (not yet the 3 that 1 s takes at hop 0.48 s), confident again:
    # still the same event; then 3 Other hops close it, and the next run of k opens a new alert
    hops = [PHONE_HOP] * 3 + [PHONE_HOP] * 4 + [OTHER_HOP] * 2 + [PHONE_HOP] * 3 + [OTHER_HOP] * 3 + [PHONE_HOP] * 3
    said = _run(hops)
    opened = [i for i, s in enumerate(said) if isinstance(s, Opened)]
    assert opened == [2, len(hops) - 1]
    assert [i for i, s in enumerate(said) if s == "closed"] == [14]
    assert StreamParams(hop_s=0.48, close_after_s=1.0).close_hops == 3
    assert StreamParams(hop_s=0.24, close_after_s=0.48).close_hops == 2  # exact multiples are not rounded up
    assert StreamParams(close_after_s=0.0).close_hops == 1


def test_no_alert_opens_on_the_hop_that_closes_an_event_and_the_any_score_counts_every_distraction():
    said = _run([PHONE_HOP] * 3 + [OTHER_HOP] * 3 + [PHONE_HOP] * 3, close_after_s=1.0)
    assert said[5] == "closed" and isinstance(said[8], Opened)
    split = _p(Phone=0.4, Texting=0.4)  # top 0.4 < 0.7, but 1 - P(Other) = 0.8
    assert all(s is None for s in _run([split] * 3))
    assert isinstance(_run([split] * 3, score="any")[-1], Opened)


# ---------------------------------------------------------------------------- the loop: steps, windows, hops


class Windows:
    """Stands in for StreamModel: 'Phone' when the window's last second moves on x, else Other; records every
    window it is given (a copy: the loop reuses its buffers)."""

    classes = CLASSES
    name, precision, entry, step_model = "stand-in", "fp32", {}, None

    def __init__(self):
        self.seen = []

    def classify_window(self, window):
        self.seen.append(window.copy())
        return np.asarray(PHONE_HOP if window[-25:, 0].mean() > 3.0 else OTHER_HOP, np.float32)


def _moves(n, spans, rest=(0.0, 0.0, 9.81)):
    """n samples at 100 Hz at rest, +6 m/s^2 on x in each (start, end) sample span, a little noise."""
    acc = np.tile(np.asarray(rest, np.float32), (n, 1)) + np.random.default_rng(0).normal(0, 0.05, (n, 3)).astype(np.float32)
    for a, b in spans:
        acc[a:b, 0] += 6.0
    return acc


def test_a_decision_every_hop_on_the_last_window_of_25_hz_means():
    acc = _moves(2000, [])
    clf = Windows()
    StreamLoop(clf, StreamParams(window_s=1.0, hop_s=0.2)).feed(ImuBlock(0.0, acc))
    steps = acc.astype(np.float64).reshape(-1, 4, 3).sum(1) / 4  # 500 steps of 25 Hz
    assert len(clf.seen) == (500 - 25) // 5 + 1  # the first when 1 s is there, then every 5 steps
    for k, w in enumerate(clf.seen):
        end = 25 + 5 * k
        np.testing.assert_array_equal(w, steps[end - 25:end].astype(np.float32))


def test_a_live_source_s_few_samples_decide_as_one_block():
    acc = _moves(6000, [(1000, 1800), (3000, 3300), (4500, 5600)])
    whole, pieces = Windows(), Windows()
    a = StreamLoop(whole).feed(ImuBlock(0.0, acc))
    b = []
    loop = StreamLoop(pieces)
    for i in range(0, len(acc), 5):  # a live source's blocks: 5 samples every 50 ms
        b += loop.feed(ImuBlock(i / 100, acc[i:i + 5]))
    assert [d.to_json() | {"compute_us": 0} for d in a] == [d.to_json() | {"compute_us": 0} for d in b]
    assert len(whole.seen) == len(pieces.seen) and all(np.array_equal(x, y) for x, y in zip(whole.seen, pieces.seen))
    assert [d.label for d in a] == ["Phone"] * 3


def test_alerts_carry_the_event_start_and_times_of_the_stream():
    (d,) = StreamLoop(Windows(), StreamParams(**RULE_PARAMS)).feed(ImuBlock(100.0, _moves(3000, [(1000, 2000)])))
    # x moves from 110 s; hops every 0.48 s from 103.99 s; the last second's mean passes 3 m/s^2 after 0.5 s
    assert d.status == "alert" and d.alerted and d.steps == STREAM_STEPS and d.label == "Phone"
    assert d.event_start_s == d.t_trigger_s and round(d.t_alert_s - d.t_trigger_s, 3) == 0.96  # k = 3 hops
    assert 110.5 <= d.t_trigger_s <= 111.0 and round((d.t_alert_s - 103.99) / 0.48, 6) % 1 == 0
    assert list(d.to_json()) == DECISION_KEYS


def test_a_gap_or_a_hole_restarts_the_stream_and_ends_the_event():
    acc = _moves(4000, [(1000, 3500)])
    clf = Windows()
    loop = StreamLoop(clf)
    first = loop.feed(ImuBlock(0.0, acc[:2000]))
    # the same motion goes on after a gap: no window spans it, and the event it had open is over
    again = loop.feed(ImuBlock(30.0, acc[2000:], continuous=False))
    assert len(first) == 1 and len(again) == 1 and again[0].t_trigger_s == 30.0 + 3.99  # the first hop of the new stretch
    holes = acc.copy()
    holes[2000:2010] = np.nan
    loop = StreamLoop(Windows())
    out = loop.feed(ImuBlock(0.0, holes))
    assert len(out) == 2 and out[1].t_trigger_s == round(20.1 + 3.99, 3)
    counts = loop.status.counts()
    assert (counts.samples, counts.non_finite, counts.detector_restarts) == (4000, 10, 1)


# ---------------------------------------------------------------------------- the alert path


def test_stream_alerts_go_out_as_the_capture_paths_do_one_alertseq_per_event():
    bus = can.Bus(interface="virtual", channel="stream-alerts", receive_own_messages=False)
    rx = can.Bus(interface="virtual", channel="stream-alerts")
    pub = AlertPublisher(bus, clock=Clock.DATA)
    try:
        loop = StreamLoop(Windows(), StreamParams(**RULE_PARAMS), publisher=pub)
        acc = _moves(6000, [(1000, 1800), (3000, 3300), (4500, 5600)])
        decisions = []
        for i in range(0, len(acc), 500):
            pub.advance_to(i / 100)
            decisions += loop.feed(ImuBlock(i / 100, acc[i:i + 500]))
        pub.advance_to(60.0)
        enc = AlertEncoder()
        frames = []
        while (m := rx.recv(timeout=0.2)) is not None:
            if m.arbitration_id == enc.alert_msg.frame_id:
                frames.append(enc.decode(m))
    finally:
        pub.close()
        rx.shutdown()
    assert [d.alert_seq for d in decisions] == [0, 1, 2] and all(d.alerted for d in decisions)
    seqs = sorted({f["AlertSeq"] for f in frames})
    assert seqs == [0, 1, 2] and {str(f["Status"]) for f in frames} == {"alert"}
    assert {str(f["Class"]) for f in frames} == {"Phone"}
    assert all(960 <= f["TimeSinceTrigger"] < 1300 for f in frames)  # k hops after the first, and the copies


# ---------------------------------------------------------------------------- configuration


def test_the_default_configuration_runs_the_streaming_decider_and_the_capture_path_on_request():
    cfg = config.box_config_type()()
    assert cfg.alerts.decision == "stream"
    loop = command.make_loop(cfg, Windows(), None)
    assert isinstance(loop, StreamLoop) and loop.params == StreamParams()
    for mode in ("early", "full_window"):
        capture = command.make_loop(config.override(cfg, "alerts", decision=mode), Windows(), None)
        assert isinstance(capture, WearableLoop) and capture.policy.decision == mode


def test_the_capture_loop_refuses_the_stream_decision_and_decides_early_when_given_no_policy():
    with pytest.raises(ConfigError, match=r"\[alerts\] decision = 'stream': the capture loop \(WearableLoop\) decides "
                                          r"'early' or 'full_window' only"):
        WearableLoop(Windows(), policy=config.box_config_type()().alerts)
    assert WearableLoop(Windows()).policy.decision == "early"


def test_the_default_configuration_loads_the_shipped_stream_model():
    """What the box loads as shipped: the int8 streaming classifier of the manifest, for the [stream] window."""
    cfg = config.box_config_type()()
    model = command._load_classifier(cfg)
    assert isinstance(model, StreamModel) and (model.name, model.precision) == ("stream-int8", "int8")
    assert model.entry["arch"] == "stream" and model._x.shape == (1, StreamParams().window_steps, 3)
    assert isinstance(command.make_loop(cfg, model, None), StreamLoop)


def test_the_wearable_command_refuses_a_bad_stream_setting_in_one_line_with_status_2(tmp_path, capsys):
    p = tmp_path / "box.toml"
    p.write_text('[alerts]\ndecision = "stream"\n[stream]\nclose_after_s = -1\n')
    assert table.main(["wearable", "--config", str(p), "--print-config"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "[stream] close_after_s" in err[0] and str(p) in err[0]
    p.write_text('[alerts]\ndecision = "stream"\n')
    assert table.main(["wearable", "--config", str(p), "--print-config"]) == 0
    assert 'decision = "stream"' in capsys.readouterr().out


def test_the_stream_decider_needs_100_hz():
    with pytest.raises(ConfigError, match=r"\[imu\] sample_rate_hz: the streaming decider needs 100 Hz"):
        StreamLoop(Windows(), sample_rate_hz=50)


def test_a_stream_replay_writes_the_alerts_log_with_the_capture_paths_fields(tmp_path, monkeypatch):
    cfg = config.override(config.box_config_type()(), "alerts", decision="stream")
    lines = []
    command.replay(cfg, Windows(), _moves(4000, [(1000, 2500)]), outputs=[lambda d: lines.append(json.dumps(d.to_json()))])
    (d,) = [json.loads(line) for line in lines]
    assert list(d) == DECISION_KEYS and d["status"] == "alert" and d["alert_seq"] == 0 and d["steps"] == 0


@pytest.mark.parametrize("flags", [[], ["--decision", "stream"]], ids=["default", "asked"])
def test_the_wearable_command_replays_with_the_shipped_stream_model(tmp_path, capsys, flags):
    acc = _moves(3000, [(1000, 2000)])
    csv, log = tmp_path / "r.csv", tmp_path / "alerts.jsonl"
    csv.write_text("t,ax,ay,az\n" + "".join(f"{i / 100:.2f},{a:.4f},{b:.4f},{c:.4f}\n" for i, (a, b, c) in enumerate(acc)))
    assert table.main(["wearable", "--replay", str(csv), *flags, "--alerts", str(log), "--quiet"]) == 0
    out = capsys.readouterr().out
    # 750 steps of 25 Hz: a decision at the 100th and every 6th after it (the defaults: W 4 s, hop 0.24 s)
    assert "model stream-int8 (int8)" in out and "hops 109 (stream decisions every 0.24 s on the last 4 s" in out
    assert all(list(json.loads(line)) == DECISION_KEYS for line in log.read_text().splitlines())
