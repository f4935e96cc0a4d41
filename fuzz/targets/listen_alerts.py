"""A CAN frame -> docs/examples/listen_alerts.py, the integrator's reference listener (its AlertListener).

The listener is a stand-alone script (stock tools only), so it is loaded from its file.
Seeds and mutations as for can_e2e: real AlertEncoder frames with mutated data, length,
identifier and flags. A frame it counts as an alert or heartbeat must be a standard data
frame of the DBC's length; anything else counted is a silent acceptance.
"""
from __future__ import annotations

import functools
import importlib.util

import can
import cantools
from hypothesis import strategies as st

from edge_runtime.wearable.alerts import DBC_PATH
from fuzz.harness import REPO, SilentAcceptance
from fuzz.targets.can_e2e import frames

NAME = "listen_alerts"
DOCUMENTED: tuple[type[BaseException], ...] = ()
SCRIPT = REPO / "docs" / "examples" / "listen_alerts.py"


@functools.lru_cache(maxsize=None)
def listener_module():
    spec = importlib.util.spec_from_file_location("listen_alerts", SCRIPT)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@functools.lru_cache(maxsize=None)
def dbc():
    return cantools.database.load_file(DBC_PATH)


def strategy() -> st.SearchStrategy[list[can.Message]]:
    return frames()


def run(msgs: list[can.Message]) -> None:
    lines: list[str] = []
    listener = listener_module().AlertListener(dbc(), emit=lines.append)
    for k, msg in enumerate(msgs):
        before = listener.counts["alerts"] + listener.counts["updates"] + listener.counts["heartbeats"]
        listener.tick(k * 0.01)
        listener.frame(msg, k * 0.01)
        if listener.counts["alerts"] + listener.counts["updates"] + listener.counts["heartbeats"] > before:
            message = dbc().get_message_by_frame_id(msg.arbitration_id)
            if msg.is_error_frame or msg.is_remote_frame or msg.is_extended_id or len(msg.data) != message.length:
                raise SilentAcceptance(f"the listener took a malformed frame for a {message.name}")
    listener.summary()
