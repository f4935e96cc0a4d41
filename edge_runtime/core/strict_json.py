"""JSON input files of the box, read strictly: one error naming the file, line or field.

Python's ``json`` accepts what no JSON writer of ours produces and hands back values the
readers then trip over: ``NaN`` and ``Infinity`` literals, ``1e400`` (read as inf), integers
of thousands of digits (``float()`` of one raises OverflowError), and nesting deep enough
to raise RecursionError. Every reader of a JSON input (keypoint and joint lines, a
calibration, the manifest, a camera file) goes through :func:`loads`, then checks each
field it uses with :func:`number` / :func:`integer` / :func:`number_array`, so a bad
value is one line (``InputError`` or the reader's own subclass), never a traceback and
never a value outside its range handed on.
"""
from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import numpy as np

MAX_DEPTH = 64
"""Deeper nesting than this is refused (no input of ours nests more than 4 levels)."""


def _refuse_constant(name: str):
    raise ValueError(f"{name} is not JSON (a number must be finite)")


def _depth(obj: Any, limit: int) -> int:
    """Nesting depth of ``obj``, stopping once it exceeds ``limit``."""
    depth, level = 0, [obj]
    while level and depth <= limit:
        depth += 1
        level = [v for x in level if isinstance(x, (list, dict))
                 for v in (x.values() if isinstance(x, dict) else x)]
    return depth


def loads(text: str | bytes, where: str, error: type[Exception]) -> Any:
    """Parse ``text`` (bytes must be UTF-8); any problem raises ``error("WHERE: why")``."""
    if isinstance(text, (bytes, bytearray)):
        try:
            text = bytes(text).decode("utf-8")
        except UnicodeDecodeError as e:
            raise error(f"{where}: not UTF-8 text (byte {e.start + 1})") from None
    try:
        obj = json.loads(text, parse_constant=_refuse_constant)
    except json.JSONDecodeError as e:
        raise error(f"{where}: not valid JSON ({e.msg} at character {e.pos + 1})") from None
    except RecursionError:
        raise error(f"{where}: nested more than {MAX_DEPTH} levels deep") from None
    except ValueError as e:  # a NaN/Infinity literal, or an integer over Python's digit limit
        raise error(f"{where}: {' '.join(str(e).split())}") from None
    if _depth(obj, MAX_DEPTH) > MAX_DEPTH:
        raise error(f"{where}: nested more than {MAX_DEPTH} levels deep")
    return obj


def _short(value: Any) -> str:
    r = repr(value)
    return r if len(r) <= 40 else r[:37] + "..."


def number(value: Any, where: str, error: type[Exception], lo: float = -math.inf, hi: float = math.inf) -> float:
    """``value`` as a finite float in [lo, hi], else ``error("WHERE: expected ...")``."""
    ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    if ok and isinstance(value, int) and not -1e300 < value < 1e300:  # float() of it would overflow
        ok = False
    if not ok or not math.isfinite(value) or not lo <= value <= hi:
        rng = "" if (lo, hi) == (-math.inf, math.inf) else f" in [{lo:g}, {hi:g}]"
        raise error(f"{where}: expected a finite number{rng}, got {_short(value)}")
    return float(value)


def integer(value: Any, where: str, error: type[Exception], lo: int, hi: int) -> int:
    """``value`` as an integer in [lo, hi], else ``error``."""
    if isinstance(value, bool) or not isinstance(value, int) or not lo <= value <= hi:
        raise error(f"{where}: expected an integer in [{lo}, {hi}], got {_short(value)}")
    return value


def number_array(value: Any, shape: tuple[int, ...], where: str, error: type[Exception],
                 lo: float = -math.inf, hi: float = math.inf, nulls: bool = False) -> np.ndarray:
    """A nested list of numbers of exactly ``shape`` as float64, every entry checked by
    :func:`number` (``null`` allowed and read as NaN when ``nulls``)."""
    import numpy as np  # here: the manifest's reader (standard library only) shares this module

    def walk(v: Any, dims: tuple[int, ...], path: str):
        if not dims:
            return math.nan if (nulls and v is None) else number(v, f"{where}{path}", error, lo, hi)
        if not isinstance(v, list) or len(v) != dims[0]:
            raise error(f"{where}{path}: expected a list of {dims[0]}, got {_short(v)}")
        return [walk(x, dims[1:], f"{path}[{i}]") for i, x in enumerate(v)]

    return np.array(walk(value, shape, ""), dtype=np.float64).reshape(shape)
