"""The MAVLink 2 endpoint both MAVLink links share (the wrist IMU's and the arm's): pymavlink's
parser with a stricter signature check and resynchronisation after stray bytes. Separate from
``serial_line`` so that reading a configuration or a serial spec never needs pymavlink (a
wearable box without a serial IMU does not install it)."""
from __future__ import annotations

import time

from pymavlink.dialects.v20 import common as mavlink2

from edge_runtime.core.serial_line import MAVLINK_EPOCH_UNIX_S


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

        pymavlink takes any 0xFD (MAVLink 2) or 0xFE (MAVLink 1) as the start of a packet
        and waits for the length its header claims (up to 280 bytes, several heartbeats'
        worth on a quiet line), then drops all of it when the CRC fails. Here a start byte
        that cannot begin a packet of this link (:meth:`_false_start`) is skipped at once,
        and the bytes behind the start byte of a rejected frame are scanned again. A frame
        with a message id this dialect does not know is rejected too: pymavlink hands it over
        unchecked (it has no CRC extra to check it with, and skips the signature check), so
        stray bytes that look like one would otherwise swallow the genuine packets behind
        them, even on a signed link.
        """
        self.buf.extend(c)
        self.total_bytes_received += len(c)
        while self._false_start():
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

    def _false_start(self) -> bool:
        """Whether the byte at the parse position is a start byte no packet of this link begins with.

        Both ends of every link here speak MAVLink 2 only (signing needs it), so a 0xFE is a
        stray byte, not a MAVLink 1 packet: a signature's or a timestamp's 0xFE, rescanned
        behind a damaged frame, made the arm's parser wait for up to 263 bytes and its
        watchdog trip. A 0xFD is a false start when its header's incompat flags are unknown
        or its message id is not in the dialect (such a frame would be rejected anyway, see
        :meth:`parse_char`): decided from the 10-byte header, before the length it claims has
        arrived. Its length is not checked against the message's: a peer on a newer dialect
        may send extension fields this one does not know, which pymavlink drops."""
        n, i = self.buf_len(), self.buf_index
        if n < 1 or self.buf[i] not in (mavlink2.PROTOCOL_MARKER_V1, mavlink2.PROTOCOL_MARKER_V2):
            return False
        if self.buf[i] == mavlink2.PROTOCOL_MARKER_V1:
            return True
        if n >= 3 and self.buf[i + 2] & ~mavlink2.MAVLINK_IFLAG_SIGNED:
            return True
        if n < mavlink2.HEADER_LEN_V2:
            return False
        msg_id = self.buf[i + 7] | self.buf[i + 8] << 8 | self.buf[i + 9] << 16
        return msg_id not in mavlink2.mavlink_map

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
