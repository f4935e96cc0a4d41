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

import importlib
import importlib.util
import math
import tomllib
from dataclasses import asdict, dataclass, field, fields, make_dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

from edge_runtime.canbus.bus import BUS_INTERFACES
from edge_runtime.errors import ConfigError

if TYPE_CHECKING:  # the real class is made from SECTIONS at run time (see _registry)
    BoxConfig = Any




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
class RobotLinkSection:
    """The link to the arm's controller (``edge_runtime.robot.link.base``)."""

    kind: str = "can"
    """"can" (robot_link.dbc frames, E2E-protected) or "mavlink" (MAVLink 2, signed)."""
    interface: str = "socketcand"
    """CAN only: python-can interface (socketcand for the simulated hub, socketcan/slcan on a box)."""
    channel: str = "can0"
    """CAN only: python-can channel."""
    bitrate: int = 500_000
    """CAN only: bit rate (bit/s)."""
    host: str = "127.0.0.1"
    """CAN socketcand only: the hub's address."""
    port: int = 29536
    """CAN socketcand only: the hub's TCP port."""
    serial: str = ""
    """MAVLink only: ``serial:PATH[?key=HEX]``, the serial line and the 32-byte signing key."""
    baud: int = 921_600
    """MAVLink only: serial baud rate."""


@dataclass(frozen=True)
class CameraSection:
    """The camera and keypoint input of the robot loop."""

    device: str = ""
    """The robot loop's camera when no input flag is given: an OpenCV device index ("0"), a
    video file or a stream URL; empty = none configured."""
    rate_hz: float = 30.0
    """Frames per second the camera delivers and the loop expects."""
    keypoint_format: str = "coco"
    """2D keypoint layout of the input: "coco" (COCO-17) or "h36m"."""
    intrinsics: str = ""
    """JSON file with the camera model (K, distortion, size); empty = the lifter's own camera."""
    pose_model: str = ""
    """ONNX 2D pose model for --camera; empty = none configured."""


SECTIONS: tuple[tuple[str, type | str], ...] = (
    # (TOML section, its frozen dataclass) -- one line per section; "module:Class" names a
    # module that may not be installed yet (its section is left out until it is)
    ("imu", ImuSection),
    ("detector", DetectorSection),
    ("model", ModelSection),
    ("alerts", AlertsSection),
    ("can", CanSection),
    ("robot_link", RobotLinkSection),
    ("camera", CameraSection),
    ("camera_source", "edge_runtime.robot.camera_source:CameraSourceParams"),
    ("calibration", "edge_runtime.robot.calibration:CalibrationParams"),
    ("tracker", "edge_runtime.robot.hazard:TrackerParams"),
    ("zones", "edge_runtime.robot.hazard:ZoneParams"),
    ("robot_loop", "edge_runtime.robot.loop:LoopParams"),
    ("lifter", "edge_runtime.robot.lifter:LifterParams"),
    ("cap", "edge_runtime.posture.cap:CapParams"),
    ("gola", "edge_runtime.posture.gola:GolaParams"),
)
"""Every section of the box configuration, in file order. Their modules must not import
``edge_runtime.config`` at top level (this module imports them)."""


def _resolve(spec: type | str) -> type | None:
    """The dataclass of a SECTIONS entry; None when its module is not there (yet)."""
    if not isinstance(spec, str):
        return spec
    module, _, name = spec.partition(":")
    if importlib.util.find_spec(module) is None:
        return None
    return getattr(importlib.import_module(module), name)


def _to_toml(self) -> str:
    out = []
    for sec in fields(self):
        out.append(f"[{sec.name}]")
        for k, v in asdict(getattr(self, sec.name)).items():
            out.append(f"{k} = {_toml_value(v)}")
        out.append("")
    return "\n".join(out)


def _build_registry() -> tuple[dict[str, type], tuple[str, ...], type]:
    types = {name: cls for name, cls in ((n, _resolve(spec)) for n, spec in SECTIONS) if cls}
    missing = tuple(n for n, _ in SECTIONS if n not in types)
    box = make_dataclass(
        "BoxConfig", [(name, cls, field(default_factory=cls)) for name, cls in types.items()],
        frozen=True, namespace={"to_toml": _to_toml, "__module__": __name__,
                                "__doc__": "The whole box configuration: one attribute per section (see SECTIONS)."})
    return types, missing, box


_REGISTRY: tuple[dict[str, type], tuple[str, ...], type] | None = None


def _registry() -> tuple[dict[str, type], tuple[str, ...], type]:
    """(SECTION_TYPES, MISSING_SECTIONS, BoxConfig), built on first use: the section modules
    (numpy, the lifter's onnxruntime...) are imported only when a configuration is made, not
    by modules that just need a constant from here (e.g. can_link's BUS_INTERFACES)."""
    global _REGISTRY
    if _REGISTRY is None:
        _REGISTRY = _build_registry()
    return _REGISTRY


def __getattr__(name: str):
    """``SECTION_TYPES`` (section -> dataclass), ``MISSING_SECTIONS`` (sections whose module
    is not installed yet) and ``BoxConfig`` (the whole configuration), built lazily."""
    index = {"SECTION_TYPES": 0, "MISSING_SECTIONS": 1, "BoxConfig": 2}.get(name)
    if index is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    return _registry()[index]


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
    ("robot_link", "kind"): ("can or mavlink", lambda v: v in ("can", "mavlink")),
    ("robot_link", "interface"): ("one of " + ", ".join(BUS_INTERFACES), lambda v: v in BUS_INTERFACES),
    ("robot_link", "bitrate"): ("a positive integer", lambda v: v > 0),
    ("robot_link", "port"): ("an integer in 1..65535", lambda v: 1 <= v <= 65535),
    ("robot_link", "serial"): ("empty or serial:PATH[?key=HEX]", lambda v: v == "" or v.startswith("serial:")),
    ("robot_link", "baud"): ("a positive integer", lambda v: v > 0),
    ("camera", "rate_hz"): ("a number in (0, 240]", lambda v: 0 < v <= 240),
    ("camera", "keypoint_format"): ("coco or h36m", lambda v: v in ("coco", "h36m")),
    **{("zones", k): ("a positive number", lambda v: v > 0) for k in (
        "predict_s", "worker_speed_mps", "retract_time_s", "iso_human_speed_mps", "stale_after_s",
        "level1_tone_hz", "level2_tone_hz")},
    **{("zones", k): ("a non-negative number", lambda v: v >= 0) for k in (
        "margin2_m", "margin1_m", "iso_robot_speed_mps", "iso_reaction_time_s", "iso_stop_time_s",
        "iso_stop_distance_m", "iso_intrusion_m", "iso_sensing_uncertainty_m", "iso_robot_uncertainty_m",
        "hysteresis_m", "dwell_s", "lost_hold_s", "retract_weight_away_m", "retract_weight_path_m",
        "level1_tone_db", "level2_tone_db")},
    ("zones", "stale_after_s"): ("a number in (0, 1]", lambda v: 0 < v <= 1),
    ("tracker", "window_s"): ("a positive number", lambda v: v > 0),
    ("tracker", "min_samples"): ("an integer of at least 2", lambda v: v >= 2),
    ("tracker", "max_speed_mps"): ("a positive number", lambda v: v > 0),
    ("tracker", "jump_m"): ("a positive number", lambda v: v > 0),
    ("calibration", "base_height_m"): ("a positive number", lambda v: v > 0),
    ("calibration", "worker_height_m"): ("0 (measure) or a number in [1, 2.5]", lambda v: v == 0 or 1 <= v <= 2.5),
    ("calibration", "ankle_height_m"): ("a number in [0, 0.2]", lambda v: 0 <= v <= 0.2),
    ("calibration", "min_frames"): ("an integer of at least 1", lambda v: v >= 1),
    ("calibration", "anchor_min_ray_deg"): ("a number in [0, 45]", lambda v: 0 <= v <= 45),
    ("calibration", "anchor_min_camera_height_m"): ("a non-negative number", lambda v: v >= 0),
    ("calibration", "min_move_m"): ("a positive number", lambda v: v > 0),
    ("calibration", "still_speed_mps"): ("a positive number", lambda v: v > 0),
    ("calibration", "still_min_s"): ("a positive number", lambda v: v > 0),
    ("robot_loop", "heartbeat_period_s"): ("a number in [0.005, 0.15] (the arm's watchdog is 200 ms)",
                                           lambda v: 0.005 <= v <= 0.15),
    ("robot_loop", "link_retry_s"): ("a positive number", lambda v: v > 0),
    ("robot_loop", "task_waypoints_m"): ("at least one [x, y, z] waypoint", lambda v: len(v) >= 1),
    ("robot_loop", "waypoint_tolerance_m"): ("a positive number", lambda v: v > 0),
    ("robot_loop", "records"): ("an integer of at least 1", lambda v: v >= 1),
    ("robot_loop", "retract_min_radius_m"): ("a non-negative number", lambda v: v >= 0),
    ("robot_loop", "retract_max_turn_deg"): ("a number in [0, 180]", lambda v: 0 <= v <= 180),
    ("robot_loop", "re_retract_m"): ("a positive number", lambda v: v > 0),
    ("robot_loop", "retract_max_radius_m"): ("a positive number", lambda v: v > 0),
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
        ok, value = _coerce_list(default, value)
    else:
        ok = isinstance(value, str)
    if not ok:
        kind = {bool: "true/false", int: "an integer", float: "a number", str: "a string"}
        expected = _list_kind(default) if isinstance(default, tuple) else kind[type(default)]
        raise ConfigError(f"{where}: expected {expected}, got {value!r}")
    return value


def _is_number(x: Any) -> bool:
    return isinstance(x, (int, float)) and not isinstance(x, bool) and math.isfinite(x)


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
        ok = all(isinstance(x, int) and not isinstance(x, bool) for x in value)
        return ok, tuple(value) if ok else value
    if _is_number(first):
        ok = all(map(_is_number, value))
        return ok, tuple(float(x) for x in value) if ok else value
    ok = all(isinstance(x, str) for x in value)
    return ok, tuple(value) if ok else value


def from_dict(data: dict, source: str = "<config>") -> BoxConfig:
    _, missing, box_config = _registry()
    sections = {}
    known_sections = {f.name: f for f in fields(box_config)}
    for name in set(data) & set(missing):
        raise ConfigError(f"{source}: [{name}]: its module ({dict(SECTIONS)[name].partition(':')[0]}) "
                          "is not installed on this box")
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
        try:
            sections[name] = cls(**values)
        except (ValueError, TypeError) as e:  # the section's own cross-field checks
            msg = str(e)
            raise ConfigError(f"{source}: {msg}" if msg.startswith("[") else f"{source}: [{name}] {msg}") from None
    cfg = box_config(**sections)
    d = cfg.detector
    if d.pre_frames > d.window_frames - 1:
        raise ConfigError(f"{source}: [detector] pre_frames: must be below window_frames ({d.window_frames})")
    return cfg


def load(path: str | Path | None) -> BoxConfig:
    """The configuration in ``path`` (TOML), or the defaults when ``path`` is None."""
    if path is None:
        return _registry()[2]()
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
    """box.example.toml: every section and key with its default and its documentation."""
    import textwrap

    types, _, box_config = _registry()
    cfg = box_config()
    out = [EXAMPLE_HEADER]
    for sec in fields(cfg):
        cls = types[sec.name]
        title = (cls.__doc__ or "").strip().splitlines()
        if title and not title[0].startswith(cls.__name__ + "("):  # not the dataclass's generated signature
            out.append(f"# {title[0]}")
        out.append(f"[{sec.name}]")
        docs = _field_docs(cls)
        for k, v in asdict(getattr(cfg, sec.name)).items():
            out += [f"# {line}" for line in textwrap.wrap(docs.get(k, ""), width - 2)]
            out.append(f"{k} = {_toml_value(v)}")
        out.append("")
    return "\n".join(out)


def _as_lists(v: Any) -> Any:
    """Tuples (at any depth) as lists, the way TOML gives them."""
    if isinstance(v, dict):
        return {k: _as_lists(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [_as_lists(x) for x in v]
    return v


def override(cfg: BoxConfig, section: str, **values: Any) -> BoxConfig:
    """A copy with the given keys of one section replaced (None values are ignored),
    validated like the file: command-line flags go through here."""
    given = {k: v for k, v in values.items() if v is not None}
    if not given:
        return cfg
    merged = _as_lists(asdict(cfg))
    merged[section].update(_as_lists(given))
    return from_dict(merged, "command line")


if __name__ == "__main__":
    print(example_toml(), end="")
