"""The box's configuration: one TOML file, validated at start.

Every key has a default, so an empty file (or none) is a valid configuration;
a file names only what differs. Unknown sections or keys, wrong types and
out-of-range values are refused with one line naming the file and the key::

    box.toml: [can] bitrat: unknown key (known: interface, channel, bitrate, ...)

``python -m edge_runtime wearable --print-config`` prints the effective values
in the same TOML form, ready to be saved and edited. An example with every key
is ``edge_runtime/box.example.toml``.
"""
from __future__ import annotations

import math
import tomllib
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any


BUS_INTERFACES = ("virtual", "socketcand", "socketcan", "slcan", "pcan", "kvaser", "vector", "ixxat", "gs_usb",
                  "canalystii", "seeedstudio", "serial")
"""python-can interfaces a box may use: a vehicle bus adapter, the socketcand hub, or the
in-process virtual bus. Interfaces that are not a CAN bus (network broadcasts) are refused."""


class ConfigError(ValueError):
    """An invalid configuration; the message names the file and the key."""


@dataclass(frozen=True)
class ImuSection:
    sample_rate_hz: int = 100
    """Rate the detector and model expect; recordings at other rates are resampled to it."""
    range_mps2: float = 156.9
    """Accelerometer full scale (m/s^2, 16 g); readings at or beyond it count as saturated."""
    silence_timeout_s: float = 0.15
    """No sample for this long: the sensor is silent. WEARABLE_STATUS says so at once (an
    extra heartbeat on every change of state), so within 200 ms of the last sample."""


@dataclass(frozen=True)
class DetectorSection:
    threshold_mps2: float = 5.0
    """Trigger when |ax[T] - ax[T-199]| exceeds this (m/s^2)."""
    window_frames: int = 200
    pre_frames: int = 100
    post_frames: int = 600


@dataclass(frozen=True)
class ModelSection:
    assets: str = ""
    """Directory with manifest.json; empty = the models shipped inside edge_runtime."""
    name: str = "int8"
    """Manifest entry: a model name, or a precision (int8, fp32)."""
    threads: int = 1
    """onnxruntime intra-op threads."""


@dataclass(frozen=True)
class AlertsSection:
    min_confidence: float = 0.6
    """Below this top-class probability a decision is 'uncertain' and not alerted."""
    never_alert: tuple[str, ...] = ("Other",)
    """Classes that are logged but never alerted."""


@dataclass(frozen=True)
class CanSection:
    interface: str = "virtual"
    """python-can interface: virtual (in-process), socketcand (the simulated hub), socketcan, slcan, ..."""
    channel: str = "vcan0"
    bitrate: int = 500_000
    host: str = "127.0.0.1"
    """socketcand only: the hub's address."""
    port: int = 29536
    """socketcand only: the hub's TCP port."""
    heartbeat_period_s: float = 0.1
    """WEARABLE_STATUS period (s): 10 Hz."""


@dataclass(frozen=True)
class BoxConfig:
    imu: ImuSection = field(default_factory=ImuSection)
    detector: DetectorSection = field(default_factory=DetectorSection)
    model: ModelSection = field(default_factory=ModelSection)
    alerts: AlertsSection = field(default_factory=AlertsSection)
    can: CanSection = field(default_factory=CanSection)

    def to_toml(self) -> str:
        out = []
        for sec in fields(self):
            out.append(f"[{sec.name}]")
            for k, v in asdict(getattr(self, sec.name)).items():
                out.append(f"{k} = {_toml_value(v)}")
            out.append("")
        return "\n".join(out)


_CHECKS: dict[tuple[str, str], tuple[str, Any]] = {
    # (section, key): (requirement in words, predicate)
    ("imu", "sample_rate_hz"): ("100 (the rate the shipped classifier was trained at)", lambda v: v == 100),
    ("imu", "range_mps2"): ("a positive number", lambda v: v > 0),
    ("imu", "silence_timeout_s"): ("a positive number", lambda v: v > 0),
    ("detector", "threshold_mps2"): ("a positive number", lambda v: v > 0),
    ("detector", "window_frames"): ("an integer of at least 2", lambda v: v >= 2),
    ("detector", "pre_frames"): ("a non-negative integer", lambda v: v >= 0),
    ("detector", "post_frames"): ("a positive integer", lambda v: v > 0),
    ("model", "threads"): ("an integer of at least 1", lambda v: v >= 1),
    ("model", "name"): ("a non-empty string", lambda v: bool(v)),
    ("alerts", "min_confidence"): ("a number in [0, 1]", lambda v: 0.0 <= v <= 1.0),
    ("can", "interface"): ("one of " + ", ".join(BUS_INTERFACES), lambda v: v in BUS_INTERFACES),
    ("can", "bitrate"): ("a positive integer", lambda v: v > 0),
    ("can", "port"): ("an integer in 1..65535", lambda v: 1 <= v <= 65535),
    ("can", "heartbeat_period_s"): ("a number in [0.01, 10]", lambda v: 0.01 <= v <= 10),
}


def _toml_value(v: Any) -> str:
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, float)):
        return repr(v)
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(_toml_value(x) for x in v) + "]"
    return '"' + str(v).replace("\\", "\\\\").replace('"', '\\"') + '"'


def _coerce(where: str, default: Any, value: Any) -> Any:
    """The value as the default's type, or a ConfigError naming ``where``."""
    if isinstance(default, bool):
        ok = isinstance(value, bool)
    elif isinstance(default, int):
        ok = isinstance(value, int) and not isinstance(value, bool)
    elif isinstance(default, float):
        ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
        value = float(value) if ok else value
    elif isinstance(default, tuple):
        ok = isinstance(value, list) and all(isinstance(x, str) for x in value)
        value = tuple(value) if ok else value
    else:
        ok = isinstance(value, str)
    if not ok:
        kind = {bool: "true/false", int: "an integer", float: "a number", tuple: "a list of strings", str: "a string"}
        raise ConfigError(f"{where}: expected {kind[type(default)]}, got {value!r}")
    return value


def from_dict(data: dict, source: str = "<config>") -> BoxConfig:
    sections = {}
    known_sections = {f.name: f for f in fields(BoxConfig)}
    for name, table in data.items():
        if name not in known_sections:
            raise ConfigError(f"{source}: [{name}]: unknown section (known: {', '.join(known_sections)})")
        if not isinstance(table, dict):
            raise ConfigError(f"{source}: {name}: expected a [{name}] table")
        cls = known_sections[name].default_factory
        default = cls()
        keys = {f.name for f in fields(cls)}
        values = {}
        for key, value in table.items():
            where = f"{source}: [{name}] {key}"
            if key not in keys:
                raise ConfigError(f"{where}: unknown key (known: {', '.join(sorted(keys))})")
            value = _coerce(where, getattr(default, key), value)
            check = _CHECKS.get((name, key))
            if check and not check[1](value):
                raise ConfigError(f"{where}: must be {check[0]}, got {value!r}")
            values[key] = value
        sections[name] = cls(**values)
    cfg = BoxConfig(**sections)
    d = cfg.detector
    if d.pre_frames > d.window_frames - 1:
        raise ConfigError(f"{source}: [detector] pre_frames: must be below window_frames ({d.window_frames})")
    return cfg


def load(path: str | Path | None) -> BoxConfig:
    """The configuration in ``path`` (TOML), or the defaults when ``path`` is None."""
    if path is None:
        return BoxConfig()
    p = Path(path)
    try:
        raw = p.read_bytes()
    except OSError as e:
        raise ConfigError(f"{p}: cannot read ({e.strerror or e})") from None
    try:
        data = tomllib.loads(raw.decode("utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise ConfigError(f"{p}: not valid TOML ({e})") from None
    return from_dict(data, str(p))


def override(cfg: BoxConfig, section: str, **values: Any) -> BoxConfig:
    """A copy with the given keys of one section replaced (None values are ignored),
    validated like the file: command-line flags go through here."""
    given = {k: v for k, v in values.items() if v is not None}
    if not given:
        return cfg
    merged = asdict(cfg)
    merged[section].update({k: list(v) if isinstance(v, tuple) else v for k, v in given.items()})
    for sec in merged.values():
        for k, v in sec.items():
            if isinstance(v, tuple):
                sec[k] = list(v)
    return from_dict(merged, "command line")
