"""A calibration file -> Calibration.load's checks -> the robot frame a skeleton lands in.

An input is a real calibration (made by the 3-marker fit on a simulated recording) with a
few of its fields, at any depth, replaced by hostile values (strings where numbers belong,
``"false"`` for a boolean, NaN/Infinity literals, 1e400, 400-digit integers, wrong list
shapes), deleted or deeply nested, then possibly damaged at the byte level. A refusal must
be the documented CalibrationError; an accepted calibration must map a standing worker to
finite robot-frame joints and carry parameters of the right types.
:func:`mutated_json` is shared with the manifest's target.
"""
from __future__ import annotations

import functools
import json

import numpy as np
from hypothesis import strategies as st

from edge_runtime.core import strict_json
from edge_runtime.robot.calibration import Calibration, CalibrationError, fit
from fuzz.harness import SilentAcceptance

NAME = "calibration_json"
DOCUMENTED = (CalibrationError,)

HOSTILE = st.one_of(st.floats(), st.sampled_from([1e308, 10**400, -(10**30), "false", "true", "1.7", "", None,
                                                  True, False, [], {}, [[]], [1, 2], {"a": 1}]),
                    st.text(max_size=4), st.integers())
LITERALS = [b"NaN", b"Infinity", b"-Infinity", b"1e400", b"9" * 400, b"[" * 3000 + b"]" * 3000]


def _paths(obj, prefix=()):
    """Every (path) into a JSON object: keys of dicts, indices of lists."""
    yield prefix
    items = obj.items() if isinstance(obj, dict) else enumerate(obj) if isinstance(obj, list) else ()
    for k, v in items:
        yield from _paths(v, prefix + (k,))


def _replace(obj, path, value, delete=False):
    if not path:
        return value
    out = dict(obj) if isinstance(obj, dict) else list(obj)
    if len(path) == 1 and delete and isinstance(out, dict):
        out.pop(path[0], None)
    else:
        out[path[0]] = _replace(out[path[0]], path[1:], value, delete)
    return out


@st.composite
def mutated_json(draw, valid) -> bytes:
    """``valid`` (a JSON object) with 1-3 fields replaced or deleted, as bytes, maybe damaged."""
    obj = valid
    for _ in range(draw(st.integers(1, 3))):
        path = draw(st.sampled_from(list(_paths(obj))))
        obj = _replace(obj, path, draw(HOSTILE), delete=draw(st.integers(0, 4)) == 2)
    text = bytearray(json.dumps(obj).encode())
    roll = draw(st.integers(0, 19))
    if roll == 7:  # a literal Python's json accepts but JSON does not, or deep nesting
        i = draw(st.integers(0, len(text)))
        text[i:i] = b": " + draw(st.sampled_from(LITERALS))
    elif roll == 11:
        text[draw(st.integers(0, len(text) - 1))] = draw(st.integers(0x80, 0xFF))
    elif roll == 13:
        text = text[:draw(st.integers(0, len(text)))]
    return bytes(text)


@functools.lru_cache(maxsize=1)
def seed() -> dict:
    """A real calibration: the fit on exact head and ankle positions of a camera 7 m away."""
    heads = np.array([[0.0, -0.8, 6.0], [1.0, -0.8, 6.0], [0.0, -0.8, 7.0]])
    return fit(heads, heads + [0.0, 1.7, 0.0]).to_json()


STANDING = np.tile(np.array([0.0, 0.0, 6.5]), (17, 1)) + np.linspace(-0.8, 0.9, 17)[:, None] * [0, 1, 0]


def strategy():
    return mutated_json(seed())


def run(raw: bytes) -> None:
    cal = Calibration.from_json(strict_json.loads(raw, "cal.json", CalibrationError), "cal.json")
    if not isinstance(cal.params.ground_anchor, bool) or not isinstance(cal.params.scale, bool):
        raise SilentAcceptance(f"ground_anchor {cal.params.ground_anchor!r}, scale {cal.params.scale!r}")
    robot = cal.to_robot(STANDING)
    if not np.isfinite(robot).all():
        raise SilentAcceptance(f"a standing worker lands at non-finite robot-frame joints {robot[0]}")
