"""One way to open a python-can bus on the box: the interface allow-list, a socketcand probe,
and one-line errors. The vehicle alerts and the robot link both open their bus here."""
from __future__ import annotations

import socket
import sys
import threading
from typing import TYPE_CHECKING, Any, Callable

from edge_runtime.errors import LinkError

if TYPE_CHECKING:
    import can

BUS_INTERFACES = ("virtual", "socketcand", "socketcan", "slcan", "pcan", "kvaser", "vector", "ixxat", "gs_usb",
                  "canalystii", "seeedstudio", "serial")
"""python-can interfaces a box may use: a vehicle bus adapter, the socketcand hub, or the
in-process virtual bus. Interfaces that are not a CAN bus (network broadcasts) are refused."""

SOCKETCAND_PROBE_S = 0.2
"""How long to wait for a socketcand server's ``< hi >`` before giving up on it."""


class CanLinkError(LinkError):
    """A CAN bus that cannot be opened or used; the message is one line naming it."""


def check_interface(interface: str) -> None:
    """The allow-list, in one place: CanLinkError unless ``interface`` is in BUS_INTERFACES."""
    if interface not in BUS_INTERFACES:
        raise CanLinkError(f"CAN interface {interface!r} is not allowed; use one of {', '.join(BUS_INTERFACES)}")


def probe_socketcand(host: str | None, port: int | None, timeout_s: float = SOCKETCAND_PROBE_S) -> None:
    """Connect to a socketcand server and wait for its greeting.

    python-can retries a refused connection for 10 s and waits for the greeting without a
    timeout, so a missing or hung hub costs one quick CanLinkError instead and the caller's
    backoff decides when to try again."""
    if port is None:
        raise CanLinkError("the socketcand interface needs a port (and a host)")
    try:
        with socket.create_connection((host or "127.0.0.1", port), timeout=timeout_s) as probe:
            greeting = probe.recv(16)
    except OSError as exc:
        raise CanLinkError(f"no socketcand server at {host}:{port}: {exc.strerror or exc}") from exc
    if not greeting.startswith(b"< hi >"):
        raise CanLinkError(f"no socketcand greeting from {host}:{port}")


def open_bus(interface: str, channel: str | None = None, bitrate: int | None = None,
             host: str | None = None, port: int | None = None, **kw) -> can.BusABC:
    """``can.Bus`` for an allow-listed interface, with a one-line CanLinkError instead of a traceback.

    ``host``/``port`` are the socketcand server's (probed first, see :func:`probe_socketcand`);
    ``bitrate`` is passed to interfaces that set one (not socketcand or virtual)."""
    import can  # here, not at import: a replay that sends nothing never needs python-can (DeferredBus)

    check_interface(interface)
    args = dict(kw)
    if interface == "socketcand":
        probe_socketcand(host, port)
        args.update(host=host, port=port, tcp_tune=True)
    if bitrate is not None and interface not in ("socketcand", "virtual"):
        args["bitrate"] = bitrate
    try:
        if interface == "socketcand":
            return _socketcand_bus(channel, args)
        return can.Bus(interface=interface, channel=channel, **args)
    except Exception as exc:  # noqa: BLE001 - whatever the interface raises becomes one line
        where = f"{interface}:{channel}" + (f" at {host}:{port}" if host is not None else "")
        raise CanLinkError(f"cannot open CAN bus {where}: {type(exc).__name__}: {exc}".replace("\n", " ")) from exc


_CONNECT_LOCK = threading.Lock()


def _socketcand_bus(channel: str | None, args: dict) -> can.BusABC:
    """python-can's socketcand bus with one bounded connection attempt.

    Its ``connect_to_server`` retries a refused connect for 10 s in a loop without a pause,
    logging every try, and its handshake waits for replies without a timeout: a hub that dies
    between :func:`probe_socketcand` and here would stall the caller (a heartbeat thread) for 10 s
    and flood the log. For the length of this call the module's connect is one attempt bounded by
    SOCKETCAND_PROBE_S, which also bounds the handshake; the socket is blocking again afterwards,
    as python-can expects. The lock keeps two threads from swapping the function at once."""
    import can
    import can.interfaces.socketcand.socketcand as _socketcand

    opened: list[socket.socket] = []

    def connect_once(sock: socket.socket, host: str, port: int) -> None:
        opened.append(sock)
        sock.settimeout(SOCKETCAND_PROBE_S)
        sock.connect((host, port))

    with _CONNECT_LOCK:
        retrying_connect, _socketcand.connect_to_server = _socketcand.connect_to_server, connect_once
        try:
            bus = can.Bus(interface="socketcand", channel=channel, **args)
        except BaseException:
            for sock in opened:
                sock.close()  # python-can leaves a failed socket open
            raise
        finally:
            _socketcand.connect_to_server = retrying_connect
    for sock in opened:
        sock.settimeout(None)
    return bus


VIRTUAL_MODULE = "can.interfaces.virtual"


class DeferredBus:
    """python-can's in-process virtual bus on ``channel``, opened (by ``open_bus``) when the first frame is sent.

    Why: a replay's publisher sends nothing on that bus while nobody else is on the channel (it counts such frames,
    :func:`reaches_anyone`), and python-can's import is a fifteenth of a day's replay. Until it opens, nobody in this
    process can be on the channel unless python-can is loaded and has the channel; the moment someone is, frames are
    sent and the bus opens, so a listener gets what it got from a bus opened at the start."""

    def __init__(self, open_bus: Callable[[], Any], channel: str):
        self._open = open_bus
        self.channel = channel
        self.bus: Any = None
        """The bus, once a frame was sent."""

    def send(self, msg: can.Message, timeout: float | None = None) -> None:
        if self.bus is None:
            self.bus = self._open()
        self.bus.send(msg, timeout)

    def shutdown(self) -> None:
        if self.bus is not None:
            self.bus.shutdown()


def reaches_anyone(bus: Any) -> bool:
    """Whether a frame sent on ``bus`` reaches anyone: any bus but python-can's in-process virtual bus, which drops
    what nobody else on its channel can hear (one that receives its own frames hears them); a :class:`DeferredBus`
    not yet open: whether anyone is on its virtual channel."""
    virtual = sys.modules.get(VIRTUAL_MODULE)  # not loaded: no virtual bus exists in this process
    if isinstance(bus, DeferredBus):
        if bus.bus is None:
            return virtual is not None and _anyone_on(virtual.channels, bus.channel)
        bus = bus.bus
    if virtual is None or not isinstance(bus, virtual.VirtualBus) or bus.receive_own_messages:
        return True
    return any(q is not bus.queue for q in bus.channel)


def _anyone_on(channels: dict, channel: Any) -> bool:
    """Whether any virtual bus is on the configured ``channel``. python-can keys its virtual channels by the
    channel after its config casting (``can.util.cast_from_string``: "0" is 0, "true" is True), so a configured
    string is matched as python-can would open it, and by its text too. A channel python-can would take from its
    own config (None) or a key it cannot compare counts as someone there: a frame sent to nobody costs little,
    a frame lost costs an alert."""
    if not isinstance(channel, str):
        return True
    from can.util import cast_from_string  # loaded: the virtual interface is

    opened_as = cast_from_string(channel)
    try:
        return any(queues and (key == opened_as or str(key) == channel) for key, queues in list(channels.items()))
    except Exception:  # noqa: BLE001 - a channel key whose comparison raises: open the bus
        return True
