"""Session 24: a frame's signals that certainly pass cantools' strict check are encoded without it
(edge_runtime.canbus.e2e._checked_payload). Pinned against cantools' own strict encoding on random signal sets, in
range and not: the same bytes, or the same error."""
from __future__ import annotations

import math

import numpy as np
import pytest

from edge_runtime.canbus import e2e
from edge_runtime.canbus.dbc import load_dbc
from edge_runtime.core.manifest import ASSETS_DIR

DBCS = ("robot_link.dbc", "vehicle_alerts.dbc")


def strict(message, signals: dict):
    """What the encoding was before session 24: cantools' strict encode, or its error."""
    try:
        return message.encode(dict(signals, E2E_CRC=0, AliveCounter=0), strict=True)
    except Exception as e:  # noqa: BLE001 - the error itself is compared
        return type(e), str(e)


def ours(message, signals: dict):
    try:
        return e2e._checked_payload(message, signals)
    except Exception as e:  # noqa: BLE001
        return type(e), str(e)


def value(signal, rng: np.random.Generator):
    """A value for ``signal``: mostly valid, sometimes at or past a limit, not finite, or of another type."""
    r = rng.random()
    if signal.choices and r < 0.6:
        names = [str(c) for c in signal.choices.values()]
        return names[rng.integers(len(names))] if r < 0.5 else "no such value"
    lo, hi = signal.minimum, signal.maximum
    lo = -1e3 if lo is None else lo
    hi = 1e3 if hi is None else hi
    step = abs(signal.scale)
    pick = rng.integers(12)
    if pick == 0:
        return lo
    if pick == 1:
        return hi
    if pick == 2:
        return hi + step * 1e-7  # beyond the limit, within cantools' allowance
    if pick == 3:
        return lo - step * 1e-5  # beyond it
    if pick == 4:
        return [math.nan, math.inf, -math.inf][rng.integers(3)]
    if pick == 5:
        return bool(rng.integers(2))
    if pick == 6:
        return int(rng.integers(int(lo), int(hi) + 1))
    if pick == 7:
        return hi + step * rng.uniform(1, 100)
    return float(rng.uniform(lo, hi))


@pytest.mark.parametrize("dbc", DBCS)
def test_fast_encoding_gives_the_strict_bytes_or_its_error(dbc):
    db = load_dbc(ASSETS_DIR / dbc)
    rng = np.random.default_rng(24)
    fast = 0
    for message in db.messages:
        signals = [s for s in message.signals if s.name not in ("E2E_CRC", "AliveCounter")]
        for _ in range(400):
            data = {s.name: value(s, rng) for s in signals}
            if rng.random() < 0.05 and data:
                del data[next(iter(data))]  # a signal missing
            elif rng.random() < 0.05:
                data["NoSuchSignal"] = 1  # one too many
            assert ours(message, data) == strict(message, data), (message.name, data)
            fast += e2e._surely_encodable(message, dict(data, E2E_CRC=0, AliveCounter=0))
    assert fast > 20  # the fast way was taken, and gave the same


def test_a_signal_out_of_range_is_still_refused():
    db = load_dbc(ASSETS_DIR / "robot_link.dbc")
    speed = db.get_message_by_name("ROBOT_SPEED_CMD")
    assert e2e._surely_encodable(speed, {"E2E_CRC": 0, "AliveCounter": 0, "Seq": 3, "SpeedLimit": 600.0})
    assert not e2e._surely_encodable(speed, {"E2E_CRC": 0, "AliveCounter": 0, "Seq": 3, "SpeedLimit": 1500.5})
    with pytest.raises(Exception, match="SpeedLimit"):
        e2e._checked_payload(speed, {"Seq": 3, "SpeedLimit": 1600.0})
