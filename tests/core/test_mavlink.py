"""The MAVLink 2 endpoint both MAVLink links share (edge_runtime/core/mavlink.py): a stray start
byte never holds back the genuine packet behind it."""
import io

import pytest

from edge_runtime.core.mavlink import make_mavlink

KEY = bytes(range(32))


def _heartbeat() -> bytes:
    out = io.BytesIO()
    make_mavlink(out, 1, 191, KEY, link_id=3).heartbeat_send(6, 8, 0, 0, 4)
    return out.getvalue()


@pytest.mark.parametrize("stray", [
    b"\xfe",                  # a MAVLink 1 start byte: in a damaged frame's signature or timestamp
    b"\xfe\xfd\x01",          # ... followed by what looks like a MAVLink 2 header
    b"\xfd\xfd\x00",          # a MAVLink 2 start byte whose flags look right ...
    b"\xfd\x10\x00\x00\x00\x01\x01\xff\xff\xff",  # ... and a whole header, with an id no dialect has
    b"\xfd\x10\x04",          # unknown incompat flags
])
def test_a_stray_start_byte_does_not_hold_back_the_next_packet(stray):
    """The packet right behind the stray bytes is parsed when its last byte arrives, not after
    the stray header's claimed length (up to 280 bytes, seconds of a quiet link) has."""
    rx = make_mavlink(None, 1, 1, KEY, link_id=0)
    got = [m.get_type() for m in rx.parse_buffer(stray + _heartbeat()) or ()]
    assert "HEARTBEAT" in got, got


def test_a_genuine_packet_after_another_is_still_parsed():
    rx = make_mavlink(None, 1, 1, KEY, link_id=0)
    got = [m.get_type() for m in rx.parse_buffer(_heartbeat() + _heartbeat()) or ()]
    assert got == ["HEARTBEAT", "HEARTBEAT"]
