"""The box's configuration: one TOML file, validated at start.

Every key has a default, so an empty file (or none) is a valid configuration;
a file names only what differs. Unknown sections or keys, wrong types and
out-of-range values are refused with one line naming the file and the key::

    box.toml: [can] bitrat: unknown key (known: interface, channel, bitrate, ...)

This module is the machinery only and imports no feature. Each section's schema
is the frozen dataclass of the component it configures (``DetectorConfig``,
``ZoneParams``, ...), declared there with :func:`section`; a field's limits ride on
the field (:func:`setting`), cross-field rules in the dataclass's ``__post_init__``.
A command validates the sections of the components it imports; the other sections
of the box's one file (another product's) are accepted as written and validated
by the command that uses them. ``BOX_SECTIONS`` names every section a file may
hold, so a misspelt one is still refused.

``python -m edge_runtime wearable --print-config`` prints the effective values of
the command's sections in the same TOML form, ready to be saved and edited. An
example with every key is ``edge_runtime/box.example.toml``
(``python -m edge_runtime.config > edge_runtime/box.example.toml`` regenerates it).
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import MISSING, asdict, field, fields, is_dataclass, make_dataclass
from pathlib import Path
from typing import Any, Callable

from edge_runtime.errors import ConfigError

BOX_SECTIONS: tuple[str, ...] = (
    "imu", "detector", "model", "alerts", "stream", "can",              # the wearable
    "robot_link", "camera", "camera_source", "people", "calibration", "tracker",  # the robot side
    "zones", "robot_loop", "lifter",
    "cap", "gola",                                                      # posture
)
"""Every section a box file may hold, in file order. Each is declared by its component
(:func:`section`); a test checks that the two agree."""

_SECTIONS: dict[str, type] = {}

Check = tuple[str, Callable[[Any], bool]]
"""(the requirement in words, a predicate on the coerced value)."""

POSITIVE: Check = ("a positive number", lambda v: v > 0)
NON_NEGATIVE: Check = ("a non-negative number", lambda v: v >= 0)
PROBABILITY: Check = ("a number in [0, 1]", lambda v: 0.0 <= v <= 1.0)
AT_LEAST_1: Check = ("an integer of at least 1", lambda v: v >= 1)
TCP_PORT: Check = ("an integer in 1..65535", lambda v: 1 <= v <= 65535)


def within(lo: float, hi: float, unit: str = "") -> Check:
    """A number in [lo, hi] (``unit`` is only for the message)."""
    return (f"a number in [{lo:g}, {hi:g}]{(' ' + unit) if unit else ''}", lambda v: lo <= v <= hi)


def one_of(*choices: Any) -> Check:
    words = " or ".join(map(str, choices)) if len(choices) <= 2 else "one of " + ", ".join(map(str, choices))
    return (words, lambda v: v in choices)


def setting(default: Any, check: Check | None = None) -> Any:
    """A dataclass field with a default and the limit :func:`load` enforces on it."""
    return field(default=default, metadata={"check": check} if check else {})


def section(name: str):
    """Class decorator: ``cls`` (a frozen dataclass) is the schema of the box file's ``[name]``."""
    if name not in BOX_SECTIONS:
        raise ValueError(f"[{name}] is not a box section; add it to edge_runtime.config.BOX_SECTIONS")

    def register(cls: type) -> type:
        if not (is_dataclass(cls) and cls.__dataclass_params__.frozen):
            raise TypeError(f"[{name}]: {cls.__name__} must be a frozen dataclass")
        if any(f.default is MISSING and f.default_factory is MISSING for f in fields(cls)):
            raise TypeError(f"[{name}]: every field of {cls.__name__} needs a default")
        known = _SECTIONS.setdefault(name, cls)
        if known is not cls and (known.__module__, known.__qualname__) != (cls.__module__, cls.__qualname__):
            raise ValueError(f"[{name}] is declared twice: {known.__qualname__} and {cls.__qualname__}")
        _SECTIONS[name] = cls  # a reloaded module's class replaces its earlier self
        return cls
    return register


def registered() -> dict[str, type]:
    """The sections this process has loaded, in file order: section name -> dataclass."""
    return {name: _SECTIONS[name] for name in BOX_SECTIONS if name in _SECTIONS}


_BOX_TYPES: dict[tuple[type, ...], type] = {}


def box_config_type() -> type:
    """The configuration class of this process: one attribute per registered section."""
    sections = registered()
    key = tuple(sections.values())
    if key not in _BOX_TYPES:
        _BOX_TYPES[key] = make_dataclass(
            "BoxConfig", [(name, cls, field(default_factory=cls)) for name, cls in sections.items()],
            frozen=True, namespace={"to_toml": _to_toml, "__module__": __name__,
                                    "__doc__": "The box configuration: one attribute per registered section."})
    return _BOX_TYPES[key]


def __getattr__(name: str):
    if name == "BoxConfig":  # the class of the sections loaded so far
        return box_config_type()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _to_toml(self) -> str:
    out = []
    for sec in fields(self):
        out.append(f"[{sec.name}]")
        out += [f"{k} = {_toml_value(v)}" for k, v in asdict(getattr(self, sec.name)).items()]
        out.append("")
    return "\n".join(out)


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return '"' + _redact(str(v)).replace("\\", "\\\\").replace('"', '\\"') + '"'


def _redact(text: str) -> str:
    """A signing key written inline (``serial:PATH?key=HEX``) is never printed (``--print-config``)."""
    from edge_runtime.core.serial_line import redact

    return redact(text)


# ---------------------------------------------------------------------------------------------- validation

INT_LIMIT = 2**63
"""An integer setting beyond 64 bits is refused by its type check (TOML allows any length)."""


def _is_int(x: Any) -> bool:
    return isinstance(x, int) and not isinstance(x, bool) and -INT_LIMIT <= x < INT_LIMIT


def _is_number(x: Any) -> bool:
    if isinstance(x, int):
        return _is_int(x)
    return isinstance(x, float) and math.isfinite(x)


def _coerce(where: str, default: Any, value: Any) -> Any:
    """The value as the default's type, or a ConfigError naming ``where``."""
    if isinstance(default, bool):
        ok = isinstance(value, bool)
    elif isinstance(default, int):
        ok = _is_int(value)
    elif isinstance(default, float):
        ok = _is_number(value)
        value = float(value) if ok else value
    elif isinstance(default, tuple):
        ok, value = _coerce_list(default, value)
    else:
        ok = isinstance(value, str)
    if not ok:
        kind = {bool: "true/false", int: "an integer", float: "a number", str: "a string"}
        expected = _list_kind(default) if isinstance(default, tuple) else kind[type(default)]
        raise ConfigError(f"{where}: expected {expected}, got {_short(value)}")
    return value


def _short(value: Any, limit: int = 60) -> str:
    """A value for a one-line message: a 400-digit integer or a deep list is cut short."""
    try:
        text = repr(value)
    except (ValueError, RecursionError):  # an int past Python's str() digit limit, a deep list
        text = f"<{type(value).__name__}>"
    return text if len(text) <= limit else text[:limit] + "..."


def _list_kind(default: tuple) -> str:
    first = default[0] if default else ""
    if isinstance(first, tuple):
        return f"a list of [{', '.join('number' for _ in first)}] lists"
    if isinstance(first, int) and not isinstance(first, bool):
        return "a list of integers"
    return "a list of numbers" if _is_number(first) else "a list of strings"


def _coerce_list(default: tuple, value: Any) -> tuple[bool, Any]:
    """A TOML array as the default's kind of tuple: of strings, of numbers, or of
    fixed-length number lists (e.g. waypoints)."""
    if not isinstance(value, list):
        return False, value
    first = default[0] if default else ""
    if isinstance(first, tuple):
        ok = all(isinstance(r, list) and len(r) == len(first) and all(map(_is_number, r)) for r in value)
        return ok, tuple(tuple(float(x) for x in r) for r in value) if ok else value
    if isinstance(first, int) and not isinstance(first, bool):
        ok = all(map(_is_int, value))
        return ok, tuple(value) if ok else value
    if _is_number(first):
        ok = all(map(_is_number, value))
        return ok, tuple(float(x) for x in value) if ok else value
    ok = all(isinstance(x, str) for x in value)
    return ok, tuple(value) if ok else value


def _section_from_table(name: str, cls: type, table: Any, source: str) -> Any:
    if not isinstance(table, dict):
        raise ConfigError(f"{source}: {name}: expected a [{name}] table")
    default = cls()
    known = {f.name: f for f in fields(cls)}
    values = {}
    for key, value in table.items():
        where = f"{source}: [{name}] {key}"
        if key not in known:
            raise ConfigError(f"{where}: unknown key (known: {', '.join(sorted(known))})")
        value = _coerce(where, getattr(default, key), value)
        check = known[key].metadata.get("check")
        if check and not check[1](value):
            raise ConfigError(f"{where}: must be {check[0]}, got {_short(value)}")
        values[key] = value
    try:
        return cls(**values)
    except (ValueError, TypeError) as e:  # the section's own cross-field checks
        msg = str(e)
        raise ConfigError(f"{source}: {msg}" if msg.startswith("[") else f"{source}: [{name}] {msg}") from None


def from_dict(data: dict, source: str = "<config>"):
    """A configuration from parsed TOML: the registered sections validated, the box's other
    sections accepted as written, anything else refused."""
    sections = registered()
    values = {}
    for name, table in data.items():
        if name in sections:
            values[name] = _section_from_table(name, sections[name], table, source)
        elif name not in BOX_SECTIONS:
            raise ConfigError(f"{source}: [{name}]: unknown section (known: {', '.join(BOX_SECTIONS)})")
        elif not isinstance(table, dict):
            raise ConfigError(f"{source}: {name}: expected a [{name}] table")
    return box_config_type()(**values)


SYSTEM_PATH = Path("/etc/edge-safety/box.toml")
"""Where an installed box keeps its configuration (docs/install.md); ``--config`` overrides it."""


def load(path: str | Path | None):
    """The configuration in ``path`` (TOML); when ``path`` is None, the box's own
    (:data:`SYSTEM_PATH`) if it has one, else the defaults."""
    if path is None and SYSTEM_PATH.is_file():
        path = SYSTEM_PATH
    if path is None:
        return box_config_type()()
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as e:
        raise ConfigError(f"{p}: cannot read ({e.strerror or e})") from None
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except UnicodeDecodeError as e:
        raise ConfigError(f"{p}: not UTF-8 (byte {e.start}); a TOML file is UTF-8 text") from None
    except tomllib.TOMLDecodeError as e:
        raise ConfigError(f"{p}: not valid TOML ({e})") from None
    except (RecursionError, ValueError) as e:  # nesting too deep; an integer past Python's digit limit
        raise ConfigError(f"{p}: not a usable TOML file ({type(e).__name__}: {str(e)[:80]})") from None
    return from_dict(data, str(p))


def _as_lists(v: Any) -> Any:
    """Tuples (at any depth) as lists, the way TOML gives them."""
    if isinstance(v, dict):
        return {k: _as_lists(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_as_lists(x) for x in v]
    return v


def override(cfg, section_name: str, **values: Any):
    """A copy with the given keys of one section replaced (None values are ignored),
    validated like the file: command-line flags go through here."""
    given = {k: v for k, v in values.items() if v is not None}
    if not given:
        return cfg
    merged = _as_lists(asdict(cfg))
    merged[section_name].update(_as_lists(given))
    return from_dict(merged, "command line")


# ---------------------------------------------------------------------------------------------- the example file

EXAMPLE_HEADER = """\
# The edge box configuration (TOML). Every key is optional; these are the defaults.
# Validate and show the effective values:  python -m edge_runtime wearable --config BOX.toml --print-config
# (or: python -m edge_runtime robot --config BOX.toml --print-config; the same file serves both)
# This file is generated from the sections' dataclasses:  python -m edge_runtime.config > box.example.toml
"""


def _field_docs(cls: type) -> dict[str, str]:
    """The docstring under each field of a dataclass (read from its source)."""
    import ast
    import inspect
    import textwrap

    try:
        body = ast.parse(textwrap.dedent(inspect.getsource(cls))).body[0].body
    except (OSError, TypeError, SyntaxError, IndexError):
        return {}
    docs = {}
    for node, after in zip(body, body[1:]):
        if isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name) and isinstance(after, ast.Expr) \
                and isinstance(after.value, ast.Constant) and isinstance(after.value.value, str):
            docs[node.target.id] = " ".join(after.value.value.split())
    return docs


def example_toml(width: int = 96) -> str:
    """box.example.toml: every section and key with its default and its documentation.
    Every section of BOX_SECTIONS must be registered (see ``python -m edge_runtime.config``)."""
    import textwrap

    sections = registered()
    missing = [name for name in BOX_SECTIONS if name not in sections]
    if missing:
        raise ConfigError(f"sections not loaded: {', '.join(missing)} (import the products that declare them)")
    out = [EXAMPLE_HEADER]
    for name, cls in sections.items():
        title = (cls.__doc__ or "").strip().splitlines()
        if title and not title[0].startswith(cls.__name__ + "("):  # not the dataclass's generated signature
            out.append(f"# {title[0]}")
        out.append(f"[{name}]")
        docs = _field_docs(cls)
        for k, v in asdict(cls()).items():
            out += [f"# {line}" for line in textwrap.wrap(docs.get(k, ""), width - 2)]
            out.append(f"{k} = {_toml_value(v)}")
        out.append("")
    return "\n".join(out)


if __name__ == "__main__":
    # The command table knows every product; config itself imports none of them. Run as a
    # script this file is ``__main__``: the sections register with ``edge_runtime.config``.
    from edge_runtime import config as _config
    from edge_runtime.__main__ import load_all_sections

    load_all_sections()
    print(_config.example_toml(), end="")
