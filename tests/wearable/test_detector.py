"""The streaming detector equals the whole-recording reference, however the stream is cut."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from edge_runtime.wearable.detector import (
    DetectorConfig,
    StreamingDetector,
    detect_triggers,
    extract_captures,
    p3_series,
)


def _signal(seed: int, n: int) -> np.ndarray:
    """A random walk plus a few sharp steps on x: triggers close together and far apart."""
    rng = np.random.default_rng(seed)
    x = np.cumsum(rng.normal(0, 0.25, size=(n, 3)), axis=0).astype(np.float32)
    for t in rng.integers(0, n, size=max(1, n // 800)):
        x[t:, 0] += rng.choice([-7.0, 7.0])
    return x


def _stream(x: np.ndarray, cuts: list[int], det: StreamingDetector | None = None, as_floats: bool = False):
    """``x`` pushed in the blocks ``cuts`` makes; with ``as_floats`` a one-sample block goes in as
    the 100 Hz loop gives it (:meth:`StreamingDetector.push_sample`)."""
    det = det or StreamingDetector()
    caps = []
    edges = [0, *sorted(set(c for c in cuts if 0 < c < len(x))), len(x)]
    for a, b in zip(edges[:-1], edges[1:]):
        if as_floats and b - a == 1:
            cap = det.push_sample(*x[a].tolist())
            caps += [cap] if cap is not None else []
        else:
            caps += det.push(x[a:b])
    return det, caps


@settings(max_examples=60, deadline=None)
@given(seed=st.integers(0, 10_000), n=st.integers(150, 6000), data=st.data())
def test_streaming_matches_reference_for_any_block_split(seed, n, data):
    x = _signal(seed, n)
    cuts = data.draw(st.lists(st.integers(1, n - 1), max_size=40))
    if data.draw(st.booleans()):  # a stretch sample by sample, as floats, between blocks
        a = data.draw(st.integers(0, n - 1))
        cuts += list(range(a, min(n, a + data.draw(st.integers(1, 1500)))))
    ref_triggers = detect_triggers(x)
    ref_caps = extract_captures(x, ref_triggers)
    det, caps = _stream(x, cuts, as_floats=data.draw(st.booleans()))
    assert det.triggers == ref_triggers.tolist()
    assert [c.trigger_index for c in caps] == [c.trigger_index for c in ref_caps]
    for c, r in zip(caps, ref_caps):
        assert c.start_index == r.start_index == c.trigger_index - 100
        np.testing.assert_array_equal(c.data, r.data)


def test_sample_by_sample_equals_one_block():
    x = _signal(3, 5000)
    one, caps_one = _stream(x, [])
    each, caps_each = _stream(x, list(range(1, len(x))))
    floats, caps_floats = _stream(x, list(range(1, len(x))), as_floats=True)
    assert one.triggers == each.triggers == floats.triggers and len(one.triggers) >= 3
    assert len(caps_one) == len(caps_each) == len(caps_floats)
    for a, b in zip(caps_one, caps_floats):
        assert a.trigger_index == b.trigger_index and np.array_equal(a.data, b.data)


def test_trigger_rule_window_capture_and_pause():
    """A single step of 6 m/s^2 at frame 1000 triggers at 1000 (|ax[T]-ax[T-199]| > 5),
    the capture is frames 900..1599, and a second step 300 frames later is ignored
    because the detector pauses until the capture ends."""
    x = np.zeros((4000, 3), np.float32)
    x[:, 2] = 9.81
    x[1000:, 0] += 6.0
    x[1300:, 0] += 6.0  # inside the pause
    x[2500:, 0] -= 6.0  # after the pause: triggers again
    trig = detect_triggers(x)
    assert trig.tolist() == [1000, 2500]
    (cap, cap2) = extract_captures(x, trig)
    assert cap.data.shape == (700, 3) and cap.start_index == 900
    assert cap.data[99, 0] == 0.0 and cap.data[100, 0] == 6.0


def test_threshold_is_strict_and_configurable():
    x = np.zeros((1000, 3), np.float32)
    x[500:, 0] = 5.0
    assert detect_triggers(x).size == 0  # exactly 5 m/s^2 does not exceed 5
    assert detect_triggers(x, DetectorConfig(threshold_mps2=4.9)).tolist() == [500]


def test_p3_is_newest_minus_oldest_of_the_window():
    ax = np.arange(400, dtype=np.float64)
    p3 = p3_series(ax)
    assert np.isnan(p3[:199]).all() and np.allclose(p3[199:], 199.0)


def test_no_trigger_before_the_window_is_full_and_nans_never_trigger():
    x = np.zeros((600, 3), np.float32)
    x[50:, 0] = 20.0  # the window reaches back to frame 0 only from frame 199
    x[300:320, 0] = np.nan
    det, _ = _stream(x, [17, 250])
    assert det.triggers == detect_triggers(x).tolist() == [199]


def test_capture_at_end_of_stream_is_not_emitted_incomplete():
    x = np.zeros((1000, 3), np.float32)
    x[700:, 0] = 9.0
    det, caps = _stream(x, [333])
    assert det.triggers == [700] and caps == [] and det.capturing


def test_reset_drops_capture_and_refills_window():
    x = np.zeros((3000, 3), np.float32)
    x[400:, 0] = 8.0
    det = StreamingDetector()
    det.push(x[:500])
    assert det.triggers == [400] and det.capturing
    det.reset()
    assert not det.capturing
    # after a reset at frame 500 the first possible trigger is 500 + 199, even though
    # the old samples would have produced a difference
    y = x.copy()
    y[500:, 0] = 0.0
    y[750:, 0] = 8.0
    caps = det.push(y[500:])
    assert det.triggers == [400, 750] and [c.trigger_index for c in caps] == [750]
    np.testing.assert_array_equal(caps[0].data, y[650:1350])


@pytest.mark.parametrize("bad", [dict(window_frames=1), dict(threshold_mps2=0), dict(pre_frames=300)])
def test_config_is_validated(bad):
    with pytest.raises(ValueError):
        DetectorConfig(**bad)


def test_skip_keeps_stream_indices_and_refills_the_window():
    det = StreamingDetector()
    det.push(np.zeros((300, 3), np.float32))
    det.skip(50)  # 50 unusable samples: frames 300..349
    y = np.zeros((700, 3), np.float32)
    y[250:, 0] = 8.0  # stream frame 600; a full window after the hole starts at 350 + 199 = 549
    det.push(y)
    assert det.n_seen == 1050 and det.triggers == [600]


def test_blocks_longer_than_the_buffer_after_history_and_a_capture_seen_while_it_fills():
    x = _signal(11, 14000)
    ref = extract_captures(x, detect_triggers(x))
    det, caps = _stream(x, [150, 150 + 9000])  # a short block, then one longer than the buffer's room
    assert [c.trigger_index for c in caps] == [c.trigger_index for c in ref]
    for c, r in zip(caps, ref):
        np.testing.assert_array_equal(c.data, r.data)
    det = StreamingDetector()
    t = ref[0].trigger_index
    det.push(x[: t + 50])
    trigger, so_far = det.filling
    assert trigger == t and len(so_far) == 150 and not so_far.flags.writeable
    np.testing.assert_array_equal(so_far, ref[0].data[:150])
    det.reset()
    assert det.filling is None
