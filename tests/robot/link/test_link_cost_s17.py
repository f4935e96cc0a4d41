"""Session 17 (perf7): ``check_target`` on Python floats pinned to the numpy form it replaced: the same
answer (position bit for bit, pitch, yaw) or the same ValueError message, on random and edge inputs."""
from __future__ import annotations

import math

import numpy as np
import pytest

from edge_runtime.robot.link.protocol import POSITION_LIMIT_M, check_target, wrap_angle

EDGE = (math.nan, math.inf, -math.inf, 0.0, -0.0, POSITION_LIMIT_M, -POSITION_LIMIT_M,
        math.nextafter(POSITION_LIMIT_M, math.inf), 1e300, -1e-300)


def session16_check_target(position_m, pitch_rad, yaw_rad):
    """check_target as session 16 left it (numpy on the three values)."""
    p = np.asarray(position_m, dtype=float).reshape(-1)
    if p.shape != (3,) or not np.all(np.isfinite(p)):
        raise ValueError(f"position_m must be 3 finite numbers (m), got {position_m!r}")
    if np.any(np.abs(p) > POSITION_LIMIT_M):
        raise ValueError(f"position_m {tuple(np.round(p, 3))} is outside +-{POSITION_LIMIT_M} m of the robot base")
    if not math.isfinite(pitch_rad) or abs(pitch_rad) > math.pi / 2 + 1e-9:
        raise ValueError(f"pitch_rad must lie in [-pi/2, pi/2], got {pitch_rad!r}")
    if not math.isfinite(yaw_rad):
        raise ValueError(f"yaw_rad must be finite, got {yaw_rad!r}")
    return p, max(-math.pi / 2, min(math.pi / 2, float(pitch_rad))), wrap_angle(yaw_rad)


def outcome(fn, *args):
    try:
        p, pitch, yaw = fn(*args)
    except ValueError as e:
        return ("error", str(e))
    return ("ok", p.dtype.str, p.shape, p.tobytes(), repr(pitch), repr(yaw))


def positions(rng):
    for _ in range(3000):
        p = rng.uniform(-4, 4, 3) * rng.choice([1e-3, 0.3, 1.0])
        hit = rng.random(3) < 0.15
        p[hit] = rng.choice(EDGE, int(hit.sum()))
        forms = (p, p.tolist(), tuple(p.tolist()), p.reshape(3, 1), p.astype(np.float32))
        yield forms[int(rng.integers(len(forms)))]
    yield from ([1, 2], [0.1, 0.2, 0.3, 0.4], [[0.1, 0.2, 0.3]], np.zeros((3, 1)), [np.inf, 5.0, 0.0], [5.0, np.nan, 0.0],
                [True, 0, 1], np.array([3.2, -3.2, 0.0]))


def test_check_target_is_session16s():
    rng = np.random.default_rng(17)
    for p in positions(rng):
        pitch = float(rng.choice([rng.uniform(-1.6, 1.6), math.pi / 2 + 1e-10, math.nan, -math.inf]))
        yaw = float(rng.choice([rng.uniform(-7, 7), math.inf, math.nan, -0.0]))
        assert outcome(check_target, p, pitch, yaw) == outcome(session16_check_target, p, pitch, yaw)


@pytest.mark.parametrize("bad", ["abc", None, [0.1, "x", 0.2]])
def test_check_target_refuses_what_it_refused(bad):
    for fn in (check_target, session16_check_target):
        with pytest.raises((ValueError, TypeError)) as e:
            fn(bad, 0.0, 0.0)
        if fn is check_target:
            got = (e.type, str(e.value))
        else:
            assert (e.type, str(e.value)) == got
