"""MAVLink 2 bytes of the wrist IMU's serial line -> the IMU packet decoder -> the wearable loop.

Seeds: what the simulated IMU firmware writes (HIGHRES_IMU and SCALED_IMU, signed with the
decoder's key, and an unsigned stream the decoder must refuse). Every mutated stream is
followed by genuine signed packets stamped later: they must still be delivered (a forged
packet must not starve the link, a stray byte must not swallow good packets).
"""
from __future__ import annotations

import time

from hypothesis import strategies as st

from edge_runtime.wearable.mavlink_source import ImuPacketDecoder
from edge_runtime.wearable.sources import ImuBlock
from fuzz.harness import GoodInputLost
from fuzz.mutate import GENERIC_TOKENS, mutated
from fuzz.probe import through_loop
from fuzz.seeds import SIGNING_KEY, SIGNING_T0, mavlink_streams, signed_tail

NAME = "mavlink_imu"
DOCUMENTED: tuple[type[BaseException], ...] = ()
TAIL_PACKETS = 20


def strategy() -> st.SearchStrategy[bytes]:
    return mutated(list(mavlink_streams()), GENERIC_TOKENS, max_ops=4)


def run(data: bytes) -> None:
    decoder = ImuPacketDecoder(signing_key=SIGNING_KEY)
    decoder.mav.signing.timestamp = SIGNING_T0  # as if the seeds arrived when they were made
    events: list = []
    decoder.feed(data, time.monotonic(), events)
    decoder.flush(events)
    before = decoder.stats.samples
    decoder.feed(signed_tail(TAIL_PACKETS), time.monotonic(), events)
    decoder.flush(events)
    delivered = decoder.stats.samples - before + decoder.stats.out_of_order
    if delivered < TAIL_PACKETS - 1:  # the first may be taken by a truncated packet ahead of it
        raise GoodInputLost(f"only {delivered} of {TAIL_PACKETS} genuine packets after the input got through")
    through_loop(e for e in events if isinstance(e, ImuBlock))
