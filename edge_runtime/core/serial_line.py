"""Serial-line specs, MAVLink 2 signing keys and the signed MAVLink endpoint, shared by every
MAVLink link on the box (the wrist IMU source and the robot link), so both read
``serial:PATH?key=HEX`` the same way and refuse forged packets the same way."""
from __future__ import annotations

import os
import re
from dataclasses import dataclass, field
from pathlib import Path

MAVLINK_EPOCH_UNIX_S = 1420070400
"""MAVLink signing timestamps count 10 us since 2015-01-01 00:00 UTC."""


KEY_FORMS = "key=@FILE (a file holding the 64 hex digits) or key=env:NAME (an environment variable)"
_INLINE_KEY = re.compile(r"(key=)(?!@|env:)[^&\s\"']*")


def redact(text: str) -> str:
    """``text`` with every inline ``key=HEX`` replaced by ``key=<redacted>`` (a key's file or
    variable name is not secret and stays): for messages and ``--print-config``."""
    return _INLINE_KEY.sub(r"\1<redacted>", text)


def parse_signing_key(text: str, what: str = "signing key") -> bytes:
    """A MAVLink 2 signing key from 64 hex digits; ValueError names ``what``, never the key."""
    try:
        key = bytes.fromhex(text.strip())
    except ValueError:
        raise ValueError(f"{what} is not 64 hex digits") from None
    if len(key) != 32:
        raise ValueError(f"{what} must be 32 bytes (64 hex digits), got {len(key)}")
    return key


def read_signing_key(value: str, what: str = "signing key") -> bytes:
    """A key given as ``@FILE``, ``env:NAME`` or (in a configuration file) 64 hex digits."""
    if value.startswith("@"):
        try:
            text = Path(value[1:]).read_text()
        except (OSError, UnicodeDecodeError) as e:
            raise ValueError(f"{what}: cannot read the key file {value[1:]} ({getattr(e, 'strerror', None) or e})") from None
        return parse_signing_key(text, f"{what} (file {value[1:]})")
    if value.startswith("env:"):
        text = os.environ.get(value[4:])
        if text is None:
            raise ValueError(f"{what}: the environment variable {value[4:]} is not set")
        return parse_signing_key(text, f"{what} (variable {value[4:]})")
    return parse_signing_key(value, what)


@dataclass(frozen=True)
class SerialSpec:
    """A MAVLink serial line as the box names it: ``serial:PATH[?key=...|unsigned=yes]``."""

    path: str
    key: bytes | None = field(default=None, repr=False)
    unsigned: bool = False
    """The spec says an unsigned line is intended (``unsigned=yes``)."""
    key_inline: bool = False
    """The key's hex digits are in the spec itself (not ``@FILE`` or ``env:NAME``)."""


def parse_link_spec(spec: str) -> SerialSpec:
    """``serial:PATH[?key=@FILE|key=env:NAME|key=HEX|unsigned=yes]``; ValueError never shows a key."""
    shown = redact(spec)
    if not spec.startswith("serial:") or len(spec) == len("serial:"):
        raise ValueError(f"serial line must be serial:PATH[?key=...], got {shown!r}")
    path, _, query = spec[len("serial:"):].partition("?")
    key, unsigned, inline = None, False, False
    for item in filter(None, query.split("&")):
        name, _, value = item.partition("=")
        if name == "key":
            key, inline = read_signing_key(value, "serial line key"), not value.startswith(("@", "env:"))
        elif name == "unsigned" and value in ("yes", "true", "1"):
            unsigned = True
        else:
            raise ValueError(f"serial line {shown!r}: unknown option {name!r} ({KEY_FORMS}, or unsigned=yes)")
    if key is not None and unsigned:
        raise ValueError(f"serial line {shown!r}: a key and unsigned=yes contradict each other")
    return SerialSpec(path, key, unsigned, inline)


def parse_serial_spec(spec: str, signing_key: bytes | None = None) -> tuple[str, bytes | None]:
    """``serial:PATH[?key=...]`` (the box configuration's form) -> (path, signing key)."""
    parsed = parse_link_spec(spec)
    return parsed.path, parsed.key if parsed.key is not None else signing_key
