"""The robot link's bus options, declared once for both ends' command lines (the runtime's
``robot`` and the simulator's ``sawyer``). Only argparse here: every command's options are
built when ``python -m edge_runtime`` starts, so this must not import the protocol's
python-can, cantools and pymavlink."""
from __future__ import annotations

import argparse
from dataclasses import dataclass

from edge_runtime import config
from edge_runtime.canbus.bus import BUS_INTERFACES

BUS_OPTIONS = {"interface": "python-can interface", "channel": "python-can channel",
               "host": "socketcand hub address", "port": "socketcand hub TCP port"}
"""The bus options of both ends' command lines (``--can-<key>``), and what they set."""


@config.section("robot_link")
@dataclass(frozen=True)
class RobotLinkParams:
    """The link to the arm's controller (``edge_runtime.robot.link``)."""

    kind: str = config.setting("can", config.one_of("can", "mavlink"))
    """"can" (robot_link.dbc frames, E2E-protected) or "mavlink" (MAVLink 2, signed)."""
    interface: str = config.setting("socketcand", config.one_of(*BUS_INTERFACES))
    """CAN only: python-can interface (socketcand for the simulated hub, socketcan/slcan on a box)."""
    channel: str = "can0"
    """CAN only: python-can channel."""
    bitrate: int = config.setting(500_000, ("a positive integer", lambda v: v > 0))
    """CAN only: bit rate (bit/s)."""
    host: str = "127.0.0.1"
    """CAN socketcand only: the hub's address."""
    port: int = config.setting(29536, config.TCP_PORT)
    """CAN socketcand only: the hub's TCP port."""
    serial: str = config.setting("", ("empty or serial:PATH[?key=HEX]", lambda v: v == "" or v.startswith("serial:")))
    """MAVLink only: ``serial:PATH[?key=HEX]``, the serial line and the 32-byte signing key."""
    baud: int = config.setting(921_600, ("a positive integer", lambda v: v > 0))
    """MAVLink only: serial baud rate."""


def tcp_port(text: str) -> int:
    """argparse type: a TCP port number, 1..65535."""
    try:
        port = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a TCP port: {text!r}") from None
    if not 1 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"TCP port must be 1..65535, got {port}")
    return port


def add_bus_arguments(parser, *, config_section: str | None = None, defaults: dict | None = None,
                      channel_flag: str = "--can-channel") -> None:
    """``--can-interface``, ``--can-host``, ``--can-port`` and the channel (``channel_flag``: the
    two command lines spell it differently) on ``parser``. With ``config_section`` each flag
    overrides that section's key, which the configuration checks; otherwise ``defaults`` apply
    and the port is checked here."""
    for key, what in BUS_OPTIONS.items():
        flag = channel_flag if key == "channel" else f"--can-{key}"
        if config_section is not None:
            parser.add_argument(flag, type=int if key == "port" else str, help=f"{what} [{config_section}] {key}")
            continue
        default = (defaults or {}).get(key)
        parser.add_argument(flag, type=tcp_port if key == "port" else str, default=default,
                            help=what + (f" (default {default})" if default is not None else ""))
