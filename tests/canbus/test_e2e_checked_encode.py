"""E2EProtector's quick strict check (session 16, perf5) against cantools' strict encoding, byte for byte:
every message of both DBCs, random and edge values (the limits, just beyond cantools' tolerance, NaN, inf,
choice names known and unknown, bools, numpy scalars, missing and extra signals). Whatever cantools'
``encode(strict=True)`` refuses is still refused, with cantools' own error."""
from __future__ import annotations

import functools
import math

import numpy as np
import pytest

from edge_runtime.canbus.dbc import load_dbc
from edge_runtime.canbus.e2e import E2EProtector, strict_checks
from edge_runtime.core.manifest import ASSETS_DIR

DBCS = ("robot_link.dbc", "vehicle_alerts.dbc")


def _outcome(fn, *args):
    try:
        return "bytes", bytes(fn(*args))
    except Exception as exc:  # noqa: BLE001 - the kind of refusal is what is compared
        return "raises", type(exc).__name__


def _values(signal, rng) -> list:
    """Edge and random values for one signal."""
    tol = abs(signal.conversion.scale) * 1e-6
    lo = signal.minimum if signal.minimum is not None else -1e6
    hi = signal.maximum if signal.maximum is not None else 1e6
    out = [lo, hi, lo - tol / 2, hi + tol / 2, lo - 3 * tol, hi + 3 * tol, lo - abs(signal.conversion.scale),
           hi + abs(signal.conversion.scale), math.nan, math.inf, -math.inf, 0, 0.0, -0.0, True, np.float64(lo),
           np.int64(1), int(lo), int(hi), int(hi) + 1, "no such choice", 1e300, -1e300]
    out += [float(v) for v in rng.uniform(lo, hi, 6)] + [int(v) for v in rng.integers(int(lo), int(hi) + 1, 3)]
    if signal.conversion.choices:
        out += [str(v) for v in signal.conversion.choices.values()] + list(signal.conversion.choices)
    return out


@pytest.mark.parametrize("dbc", DBCS)
def test_quick_check_encodes_and_refuses_as_cantools_strict(dbc):
    db = load_dbc(ASSETS_DIR / dbc)
    rng = np.random.default_rng(16)
    n_refused = n_encoded = 0
    for message in db.messages:
        assert strict_checks(message) is not None  # no multiplexed or container message: the quick path is used
        base = {s.name: (s.minimum if s.minimum is not None else 0) for s in message.signals}
        cases = [dict(base)]
        for signal in message.signals:
            for value in _values(signal, rng):
                cases.append(dict(base, **{signal.name: value}))
        for _ in range(200):  # every signal random at once
            cases.append({s.name: rng.choice(np.array(_values(s, rng), dtype=object)) for s in message.signals})
        first = message.signals[0].name
        cases.append({k: v for k, v in base.items() if k != first})  # a signal missing
        cases.append(dict(base, NotASignal=1))  # an unknown signal
        for case in cases:
            want = _outcome(functools.partial(message.encode, strict=True), dict(case))
            got = _outcome(E2EProtector()._encode_checked, message, dict(case))
            assert got == want, (message.name, case)
            n_refused += want[0] == "raises"
            n_encoded += want[0] == "bytes"
    assert n_refused > 50 and n_encoded > 200


def test_a_bad_value_is_still_refused_on_the_robot_link():
    from edge_runtime.robot.link.protocol import RobotCanCodec

    codec = RobotCanCodec()
    for bad in (1e9, -1.0, math.nan, math.inf):
        with pytest.raises(Exception):  # noqa: B017,PT011 - cantools' EncodeError or the conversion's own error
            codec.encode("ROBOT_SPEED_CMD", Seq=1, SpeedLimit=bad)
    with pytest.raises(Exception):  # noqa: B017,PT011
        codec.encode("ROBOT_TARGET_ORIENT", Kind="teleport", Seq=1, Pitch=0.0, Yaw=0.0)
    with pytest.raises(Exception):  # noqa: B017,PT011
        codec.encode("ROBOT_TARGET_POS", SeqCheck=1, X=1e7, Y=0.0, Z=0.0)
    assert codec.decode(codec.encode("ROBOT_SPEED_CMD", Seq=1, SpeedLimit=300.0))[2]["SpeedLimit"] == 300.0
