"""The floor anchoring's per-frame path of session 16 pinned to what it replaced, to the bit: anchor_factor's
two ankle rays in Python floats (numpy's log and exp kept) and FloorAnchor's "given again" check in one
comparison, on random and edge inputs (NaN, +-inf, +-0, flat and upward rays, a camera below the floor, the
lifter-depth fusion on and off)."""
import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest

from edge_runtime.robot import calibration as cal
from edge_runtime.robot.calibration import CalibrationParams, FloorAnchor, _AnchorTrack, anchor_factor


def _session_15_reference():
    """anchor_factor before session 16, every step on numpy arrays: the reference session 15 pinned its
    round-2 form to (tests/robot/test_tracking_fast.py's ``old_anchor_factor``), loaded from there so that
    there is one copy of it."""
    path = Path(__file__).with_name("test_tracking_fast.py")
    spec = importlib.util.spec_from_file_location("session_15_tracking_reference", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.old_anchor_factor


textbook_anchor_factor = _session_15_reference()


def bits(x) -> bytes:
    return np.float64(x).tobytes()


ODD = [np.nan, np.inf, -np.inf, 0.0, -0.0, 1e-300, 1e300]


def _case(rng, case: int):
    c, s = math.cos(rng.uniform(-0.3, 1.2)), math.sin(rng.uniform(-0.3, 1.2))
    A = np.array([[1.0, 0.0, 0.0], [0.0, c, -s], [0.0, s, c]])
    if case % 11 == 0:
        A = A @ np.diag(rng.choice([-1.0, 1.0, -0.0, 2.5], 3))
    b = np.array([rng.normal(), rng.uniform(-1.5, 4.0), rng.normal()])
    j = np.column_stack([rng.normal(0, 0.5, 17), rng.normal(0.8, 0.6, 17), rng.uniform(0.5, 8, 17)])
    if case % 4 == 0:  # both feet level: both rays count
        j[cal.R_ANKLE] = j[cal.L_ANKLE] + rng.normal(0, 0.02, 3)
    r = rng.random()
    if r < 0.25:
        j[rng.choice([cal.L_ANKLE, cal.R_ANKLE]), rng.integers(3)] = rng.choice(ODD)
    elif r < 0.3:
        j[[cal.L_ANKLE, cal.R_ANKLE], rng.integers(3)] = rng.choice(ODD)
    elif r < 0.35:
        j[cal.L_ANKLE] = j[cal.R_ANKLE]  # the same ray twice: a tie for the lower one
    elif r < 0.4:
        j[rng.choice([cal.L_ANKLE, cal.R_ANKLE]), 1] = 0.0  # a level ray
    observed = None if case % 3 == 0 else rng.random(17) < rng.choice([0.2, 0.8, 1.0])
    return j, A, b, observed


PARAMS = [CalibrationParams(), CalibrationParams(anchor_min_scale=0.95, anchor_max_scale=1.05),
          CalibrationParams(anchor_min_ray_deg=0.0, anchor_min_camera_height_m=0.0),
          CalibrationParams(anchor_min_ray_deg=40.0, ankle_height_m=0.0)]


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # the old and the new divide by zero alike
@pytest.mark.parametrize("fused", [False, True])
@pytest.mark.parametrize("params", PARAMS, ids=range(len(PARAMS)))
def test_anchor_factor_is_the_old_one(params, fused, monkeypatch):
    if fused:
        monkeypatch.setattr(cal, "ANCHOR_LIFTER_DEPTH_SD", cal.ANCHOR_LIFTER_DEPTH_SD_FUSED)
    rng = np.random.default_rng(1630 + 2 * PARAMS.index(params) + fused)
    reasons = set()
    for case in range(4000):
        j, A, b, observed = _case(rng, case)
        want = textbook_anchor_factor(j, A, b, params, observed)
        got = anchor_factor(j, A, b, params, observed)
        assert got[1] == want[1] and type(got[0]) is float and bits(got[0]) == bits(want[0]), case
        reasons.add(want[1])
    assert {None, cal.ANCHOR_NO_ANKLE, cal.ANCHOR_RAY_FLAT} <= reasons
    assert params.anchor_min_camera_height_m == 0.0 or cal.ANCHOR_CAMERA_LOW in reasons


def test_given_again_is_array_equal():
    """FloorAnchor._given_before against np.array_equal track by track: a skeleton with a NaN is never given
    again, -0.0 equals 0.0, the first matching track wins, tracks without a last skeleton never match."""
    rng = np.random.default_rng(1640)
    anchor = FloorAnchor(None)
    hits = 0
    for case in range(2000):
        pool = rng.normal(0, 1, (4, 17, 3))
        pool[1] = pool[0]  # two tracks saw the same skeleton: the first wins
        pool[2, rng.integers(17), rng.integers(3)] = rng.choice([np.nan, np.inf, 0.0])
        anchor.tracks = [_AnchorTrack(None, 1.0, np.zeros(3), last_in=None if rng.random() < 0.2 else p.copy())
                         for p in pool[:rng.integers(0, 5)]]
        flat = pool[rng.integers(0, 4, size=rng.integers(0, 4))].copy()
        for f in flat:
            r = rng.random()
            if r < 0.2:
                f[f == 0] = -0.0
                f[rng.integers(17), rng.integers(3)] = 0.0 if rng.random() < 0.5 else -0.0
            elif r < 0.3:
                f[rng.integers(17), rng.integers(3)] += 1e-12
        want = [next((n for n, t in enumerate(anchor.tracks) if t.last_in is not None and np.array_equal(t.last_in, f)),
                     None) for f in flat]
        assert anchor._given_before(flat) == want, case
        hits += sum(w is not None for w in want)
    assert hits > 500
