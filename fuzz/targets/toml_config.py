"""A box configuration file (TOML) -> ``config.load`` with the wearable's sections.

Seeds: the example file with every section, and each wearable section alone. A file that
loads must keep the promises README, the DBC and docs/integrator.md make about those
values; one that breaks them and loads is a silent acceptance.
"""
from __future__ import annotations

import functools
from dataclasses import fields
from pathlib import Path

from hypothesis import strategies as st

from edge_runtime import config
from edge_runtime.errors import ConfigError
from edge_runtime.wearable import alerts, classifier, detector, loop, sources  # noqa: F401 - their sections
from edge_runtime.wearable.labels import CLASSES
from fuzz.harness import SilentAcceptance
from fuzz.mutate import GENERIC_TOKENS, mutated
from fuzz.scratch import scratch_file

NAME = "toml_config"
DOCUMENTED = (ConfigError,)
EXAMPLE = Path(config.__file__).with_name("box.example.toml")
TOKENS = GENERIC_TOKENS + (
    b"3600", b"0.2", b"0.21", b"10.0", b"-1", b"0", b"true", b"\"x\"", b"[]", b"{}", b"9e999",
    b"never_alert = [\"Phone\", \"Texting\", \"TouchScreen\", \"Drink\", \"Marker\", \"Other\"]\n",
    b"[" * 300 + b"]" * 300, b"a = " + b"[" * 2000, b"x = {a = {b = {c = {d = 1}}}}\n", b"[imu]\n", b"[can]\n",
)


@functools.lru_cache(maxsize=None)
def seeds() -> list[bytes]:
    text = EXAMPLE.read_bytes()
    sections = [b"[" + part for part in text.split(b"\n[")[1:]]
    return [text, *sections]


VALUES = ("0", "-1", "0.2", "0.21", "3600", "10.0", "1e-9", "1e308", "inf", "nan", "9" * 400, "true", '"x"',
          "[]", '["Other"]', str(list(CLASSES)).replace("'", '"'), "[" * 200 + "]" * 200, "{a = 1}")


@functools.lru_cache(maxsize=None)
def keys() -> list[tuple[str, str]]:
    return [(name, f.name) for name, cls in config.registered().items() for f in fields(cls)]


def assignments() -> st.SearchStrategy[bytes]:
    """A file that sets a few known keys to edge values (reaches the per-field limits directly)."""
    line = st.tuples(st.sampled_from(keys()), st.sampled_from(VALUES))
    return st.lists(line, min_size=1, max_size=3).map(_toml)


def _toml(items: list[tuple[tuple[str, str], str]]) -> bytes:
    tables: dict[str, dict[str, str]] = {}
    for (sec, key), value in items:
        tables.setdefault(sec, {})[key] = value
    return "".join(f"[{sec}]\n" + "".join(f"{k} = {v}\n" for k, v in t.items()) for sec, t in tables.items()).encode()


def strategy() -> st.SearchStrategy[bytes]:
    return st.one_of(mutated(seeds(), TOKENS), assignments())


PROMISES = (
    # README / docs/integrator.md: the sensor going silent is on the bus within 200 ms of its last
    # sample's arrival; the source notices silence at silence_timeout_s after the read that brought
    # it (up to read_period_s after it arrived) plus one 50 ms read.
    ("[imu] silence_timeout_s + read_period_s",
     lambda c: 0 < c.imu.silence_timeout_s and 0 <= c.imu.read_period_s
     and c.imu.silence_timeout_s + c.imu.read_period_s <= 0.15 + 1e-9),
    ("[imu] range_mps2", lambda c: 0 < c.imu.range_mps2 < float("inf")),
    # vehicle_alerts.dbc: WEARABLE_STATUS every 100 ms; missing for 300 ms = wearable unavailable
    ("[can] heartbeat_period_s", lambda c: 0 < c.can.heartbeat_period_s <= 0.1),
    ("[alerts] never_alert", lambda c: not set(CLASSES) <= set(c.alerts.never_alert)),
    ("[alerts] min_confidence", lambda c: 0 <= c.alerts.min_confidence <= 1),
)


def run(data: bytes) -> None:
    cfg = config.load(scratch_file("box.toml", data))
    for what, holds in PROMISES:
        if not holds(cfg):
            raise SilentAcceptance(f"{what}: a value that breaks its promise was accepted")
