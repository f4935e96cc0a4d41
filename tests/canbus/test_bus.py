"""canbus/bus.py: only allow-listed interfaces open, and a bus that cannot be opened is one line."""
import logging
import socket
import threading
import time

import can
import pytest

from edge_runtime.canbus import bus as bus_module
from edge_runtime.canbus.bus import CanLinkError, open_bus


def test_open_bus_one_line_error():
    with pytest.raises(CanLinkError) as e:
        open_bus("no_such_interface", "can0")
    assert "\n" not in str(e.value) and "no_such_interface" in str(e.value)
    with pytest.raises(CanLinkError, match="not allowed"):
        open_bus("udp", "x")  # only the allow-listed bus interfaces open


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_hub_gone_after_the_probe_is_one_quiet_attempt(monkeypatch, caplog):
    """python-can alone retries a refused connect for 10 s, logging every try (thousands of lines)."""
    monkeypatch.setattr(bus_module, "probe_socketcand", lambda host, port: None)  # the hub died after it
    caplog.set_level(logging.WARNING, logger="can")
    with pytest.raises(CanLinkError, match="cannot open CAN bus socketcand") as e:
        open_bus("socketcand", "vcan0", host="127.0.0.1", port=_free_port())
    assert "\n" not in str(e.value)
    assert len(caplog.records) <= 1


def test_hub_that_greets_and_then_hangs_is_a_timeout():
    """The handshake after ``< hi >`` is bounded; python-can alone waits for ``< ok >`` forever
    (here: until the fake hub gives up after 5 s, which would read as a protocol error instead)."""
    server = socket.create_server(("127.0.0.1", 0))
    port, done = server.getsockname()[1], threading.Event()

    def greet_then_hang():
        conns = []
        server.settimeout(0.05)
        give_up = time.monotonic() + 5.0
        while not done.is_set() and time.monotonic() < give_up:
            try:
                conn, _ = server.accept()
            except TimeoutError:
                continue
            except OSError:
                break
            conn.sendall(b"< hi >")
            conns.append(conn)
        for conn in conns:
            conn.close()

    thread = threading.Thread(target=greet_then_hang, daemon=True)
    thread.start()
    try:
        with pytest.raises(CanLinkError, match="timed out"):
            open_bus("socketcand", "vcan0", host="127.0.0.1", port=port)
    finally:
        done.set()
        server.close()
        thread.join(6)


def test_socketcand_bus_blocks_normally_once_open(hub):
    bus = open_bus("socketcand", "vcan0", host="127.0.0.1", port=hub.port)
    try:
        bus.send(can.Message(arbitration_id=0x123, data=b"\x01", is_extended_id=False))
        assert bus.recv(0.3) is None  # our own frame is not echoed; a recv with a timeout returns
    finally:
        bus.shutdown()
