"""Serial-line specs, MAVLink 2 signing keys and the signed MAVLink endpoint, shared by every
MAVLink link on the box (the wrist IMU source and the robot link), so both read
``serial:PATH?key=HEX`` the same way and refuse forged packets the same way."""
from __future__ import annotations

import os
import re
import time
from dataclasses import dataclass, field
from pathlib import Path

from pymavlink.dialects.v20 import common as mavlink2

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


class SignedMAVLink(mavlink2.MAVLink):
    """pymavlink's MAVLink with a stricter signature check.

    pymavlink records a stream's timestamp before it compares the signature, so one forged
    packet with a future timestamp would make every genuine packet look replayed. Here the
    signature is checked first; the timestamp only advances on a genuine packet. The reason
    of the last failure ("forged", "replayed", "stale") is kept for the counters.
    """

    last_signature_failure = ""

    def parse_char(self, c):
        """pymavlink's parser, resynchronising after a stray start byte.

        pymavlink takes any 0xFD as the start of a packet and waits for the length its
        header claims (up to 280 bytes, several heartbeats' worth on a quiet line), then
        drops all of it when the CRC fails. Here a start byte whose header has unknown
        incompat flags is skipped at once, and the bytes behind the start byte of a
        rejected frame are scanned again. A frame with a message id this dialect does not
        know is rejected too: pymavlink hands it over unchecked (it has no CRC extra to check
        it with, and skips the signature check), so stray bytes that look like one would
        otherwise swallow the genuine packets behind them, even on a signed link.
        """
        self.buf.extend(c)
        self.total_bytes_received += len(c)
        while (self.buf_len() >= 3 and self.buf[self.buf_index] == mavlink2.PROTOCOL_MARKER_V2
               and self.buf[self.buf_index + 2] & ~mavlink2.MAVLINK_IFLAG_SIGNED):
            self.buf_index += 1
        m = super().parse_char(b"")
        if m is not None and m.get_type().startswith("UNKNOWN_"):
            m = mavlink2.MAVLink_bad_data(bytes(m.data), "unknown message id: unchecked, rescanned")
        if m is not None and m.get_type() == "BAD_DATA":
            data = bytes(getattr(m, "data", b""))
            reason = str(getattr(m, "reason", "")).lower()
            if (len(data) > 1 and data[0] in (mavlink2.PROTOCOL_MARKER_V1, mavlink2.PROTOCOL_MARKER_V2)
                    and "signature" not in reason):
                self.buf = bytearray(data[1:]) + self.buf[self.buf_index:]
                self.buf_index = 0
        return m

    def check_signature(self, msgbuf, srcSystem, srcComponent) -> bool:  # noqa: N803 - pymavlink's names
        import hashlib

        h = hashlib.new("sha256")
        h.update(self.signing.secret_key)
        h.update(msgbuf[:-6])
        if h.digest()[:6] != bytes(msgbuf[-6:]):
            self.last_signature_failure = "forged"
            return False
        tlow, thigh = self.mav_sign_unpacker.unpack(msgbuf[-12:-6])
        timestamp = tlow + (thigh << 32)
        stream = (msgbuf[-13], srcSystem, srcComponent)
        last = self.signing.stream_timestamps.get(stream)
        if last is not None and timestamp <= last:
            self.last_signature_failure = "replayed"
            return False
        if last is None and timestamp + 6000 * 1000 < self.signing.timestamp:
            self.last_signature_failure = "stale"
            return False
        self.signing.stream_timestamps[stream] = timestamp
        self.signing.timestamp = max(self.signing.timestamp, timestamp)
        return True


def make_mavlink(writer, src_system: int, src_component: int, signing_key: bytes | None, link_id: int) -> SignedMAVLink:
    """A MAVLink 2 endpoint that signs what it sends and refuses unsigned packets when given a key."""
    mav = SignedMAVLink(writer, srcSystem=src_system, srcComponent=src_component)
    mav.robust_parsing = True
    if signing_key is not None:
        if len(signing_key) != 32:
            raise ValueError(f"MAVLink signing key must be 32 bytes, got {len(signing_key)}")
        mav.signing.secret_key = bytes(signing_key)
        mav.signing.link_id = link_id
        mav.signing.timestamp = int((time.time() - MAVLINK_EPOCH_UNIX_S) * 100_000)
        mav.signing.sign_outgoing = True  # allow_unsigned_callback stays None: unsigned packets are refused
    return mav


def signature_failure(mav: SignedMAVLink, bad) -> str | None:
    """For a BAD_DATA packet: "unsigned", "forged", "replayed" or "stale"; None if not a signature problem."""
    if "signature" not in str(getattr(bad, "reason", "")).lower():
        return None
    data = bytes(getattr(bad, "data", b""))
    signed = len(data) > 2 and data[0] == mavlink2.PROTOCOL_MARKER_V2 and data[2] & mavlink2.MAVLINK_IFLAG_SIGNED
    if not signed:
        return "unsigned"
    why, mav.last_signature_failure = mav.last_signature_failure or "forged", ""
    return why
