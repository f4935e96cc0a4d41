"""A CAN frame on the vehicle bus -> the E2E check -> the wearable's decode (AlertEncoder.decode).

Seeds: real DISTRACTION_ALERT and WEARABLE_STATUS frames of the AlertEncoder. Mutations
reach the data bytes, the length, the identifier and the extended/remote/error flags.
A frame the checker passes as valid must be one the DBC describes: a standard data frame
of the message's length; anything else passing is a silent acceptance.
"""
from __future__ import annotations

import can
from hypothesis import strategies as st

from edge_runtime.canbus.e2e import E2EChecker
from edge_runtime.errors import InputError
from edge_runtime.wearable.alerts import AlertEncoder
from fuzz.harness import SilentAcceptance
from fuzz.mutate import mutated
from fuzz.seeds import alert_frames

NAME = "can_e2e"
DOCUMENTED = (InputError,)
_ENCODER = AlertEncoder()


def frames() -> st.SearchStrategy[list[can.Message]]:
    """A short sequence of mutated frames (a checker keeps state from frame to frame)."""
    seeds = alert_frames()
    ids = sorted({i for i, _ in seeds})
    arb = st.one_of(st.sampled_from(ids), st.sampled_from(ids).map(lambda i: i | 0x1000_0000),
                    st.integers(0, 0x1FFF_FFFF))
    frame = st.builds(
        lambda i, data, ext, rtr, err: can.Message(arbitration_id=i, data=data, is_extended_id=ext,
                                                   is_remote_frame=rtr, is_error_frame=err, check=False),
        arb, mutated([d for _, d in seeds], max_ops=3).map(lambda b: b[:64]),
        st.booleans(), st.booleans(), st.booleans())
    return st.lists(frame, min_size=1, max_size=6)


def strategy() -> st.SearchStrategy[list[can.Message]]:
    return frames()


def run(msgs: list[can.Message]) -> None:
    checker = E2EChecker(db=_ENCODER.db)
    for msg in msgs:
        if not checker.check(msg).valid:
            continue
        message = _ENCODER.db.get_message_by_frame_id(msg.arbitration_id)
        if msg.is_extended_id != message.is_extended_frame or msg.is_remote_frame or msg.is_error_frame:
            raise SilentAcceptance(f"a {'remote' if msg.is_remote_frame else 'error' if msg.is_error_frame else 'extended'} "
                                   f"frame 0x{msg.arbitration_id:x} passed the E2E check")
        if len(msg.data) != message.length:
            raise SilentAcceptance(f"a {len(msg.data)}-byte {message.name} (DBC: {message.length}) passed the E2E check")
        _ENCODER.decode(msg)
