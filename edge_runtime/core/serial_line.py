"""Serial-line specs and MAVLink 2 signing keys, shared by every MAVLink link on the box
(the wrist IMU source and the robot link), so both read ``serial:PATH?key=HEX`` the same way."""
from __future__ import annotations


def parse_signing_key(text: str, what: str = "signing key") -> bytes:
    """A MAVLink 2 signing key from 64 hex digits; ValueError names ``what``."""
    try:
        key = bytes.fromhex(text)
    except ValueError:
        raise ValueError(f"{what} is not hex: {text!r}") from None
    if len(key) != 32:
        raise ValueError(f"{what} must be 32 bytes (64 hex digits), got {len(key)}")
    return key


def parse_serial_spec(spec: str, signing_key: bytes | None = None) -> tuple[str, bytes | None]:
    """``serial:PATH[?key=HEX]`` (the box configuration's form) -> (path, signing key)."""
    if not spec.startswith("serial:") or len(spec) == len("serial:"):
        raise ValueError(f"serial line must be serial:PATH[?key=HEX], got {spec!r}")
    path, _, query = spec[len("serial:"):].partition("?")
    for item in filter(None, query.split("&")):
        name, _, value = item.partition("=")
        if name != "key":
            raise ValueError(f"serial line {spec!r}: unknown option {name!r} (only key=HEX)")
        signing_key = parse_signing_key(value, "serial line key")
    return path, signing_key
