"""A simulated CAN bus: a socketcand-protocol hub on 127.0.0.1 (docs/design.md section 6).

Every process reaches it with python-can's stock interface::

    can.Bus(interface="socketcand", host="127.0.0.1", port=PORT, channel="vcan0")

Each frame a client sends (``< send ID LEN B0 B1 ... >``) is relayed to every
*other* client in rawmode on the same channel as ``< frame ID SECS.USECS DATA >``
(no echo to the sender, like a SocketCAN socket). Faults: drop probability,
added delay, corrupt probability (one byte XOR-ed), and ``disconnect_all()``.

    python -m firmware_sim can-hub --port 0 [--drop P] [--delay-ms MS] [--corrupt P]
"""
from __future__ import annotations

import argparse
import random
import signal
import socket
import sys
import threading
import time

HANDSHAKE_SETTLE_S = 0.05
"""python-can reads the last ``< ok >`` of the handshake with a single recv(); frames
are held back this long after it so they do not arrive glued to it."""


class _Client:
    def __init__(self, sock: socket.socket, addr):
        self.sock = sock
        self.addr = addr
        self.channel: str | None = None
        self.active_after: float | None = None  # monotonic time from which frames are relayed to it
        self.wlock = threading.Lock()

    def write(self, text: str) -> None:
        with self.wlock:
            self.sock.sendall(text.encode("ascii"))

    def close(self) -> None:
        try:
            self.sock.shutdown(socket.SHUT_RDWR)
        except OSError:
            pass
        self.sock.close()


class CanHub:
    def __init__(self, port: int = 0, host: str = "127.0.0.1", drop: float = 0.0, delay_s: float = 0.0,
                 corrupt: float = 0.0, seed: int | None = None):
        for name, p in (("drop", drop), ("corrupt", corrupt)):
            if not 0.0 <= p <= 1.0:
                raise ValueError(f"{name} must lie in [0, 1], got {p}")
        if delay_s < 0:
            raise ValueError(f"delay must be >= 0, got {delay_s}")
        self.host, self.port = host, port
        self.drop, self.delay_s, self.corrupt = drop, delay_s, corrupt
        self._rng = random.Random(seed)
        self._rng_lock = threading.Lock()
        self._clients: list[_Client] = []
        self._lock = threading.Lock()
        self._sock: socket.socket | None = None
        self._threads: list[threading.Thread] = []
        self._running = threading.Event()
        self.stats = {"connections": 0, "frames_in": 0, "frames_out": 0, "dropped": 0, "corrupted": 0, "bad_commands": 0}

    # -- lifecycle ----------------------------------------------------------
    def start(self) -> "CanHub":
        s = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        s.bind((self.host, self.port))
        s.listen(16)
        s.settimeout(0.2)
        self._sock = s
        self.port = s.getsockname()[1]
        self._running.set()
        t = threading.Thread(target=self._accept_loop, name="can-hub-accept", daemon=True)
        t.start()
        self._threads.append(t)
        return self

    def stop(self) -> None:
        self._running.clear()
        self.disconnect_all()
        for t in self._threads:
            t.join(timeout=2.0)
        self._threads.clear()
        if self._sock is not None:
            self._sock.close()
            self._sock = None

    def __enter__(self) -> "CanHub":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    def disconnect_all(self) -> None:
        """Drop every client connection (they may reconnect)."""
        with self._lock:
            clients, self._clients = self._clients, []
        for c in clients:
            c.close()

    @property
    def n_clients(self) -> int:
        with self._lock:
            return len(self._clients)

    # -- server -------------------------------------------------------------
    def _accept_loop(self) -> None:
        while self._running.is_set():
            try:
                sock, addr = self._sock.accept()
            except socket.timeout:
                continue
            except OSError:
                break
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            client = _Client(sock, addr)
            with self._lock:
                self._clients.append(client)
                self.stats["connections"] += 1
            t = threading.Thread(target=self._serve, args=(client,), name=f"can-hub-{addr[1]}", daemon=True)
            t.start()
            self._threads = [x for x in self._threads if x.is_alive()] + [t]

    def _serve(self, client: _Client) -> None:
        buf = ""
        try:
            client.write("< hi >")
            while self._running.is_set():
                data = client.sock.recv(4096)
                if not data:
                    break
                buf += data.decode("ascii", errors="replace")
                while True:
                    start = buf.find("<")
                    end = buf.find(">", start + 1) if start >= 0 else -1
                    if start < 0:
                        buf = ""
                        break
                    if end < 0:
                        buf = buf[start:] if len(buf) - start < 1024 else ""
                        break
                    self._command(client, buf[start + 1:end].split())
                    buf = buf[end + 1:]
        except OSError:
            pass
        finally:
            with self._lock:
                if client in self._clients:
                    self._clients.remove(client)
            client.close()

    def _command(self, client: _Client, words: list[str]) -> None:
        if not words:
            return
        cmd = words[0]
        if cmd == "open" and len(words) == 2:
            client.channel = words[1]
            client.write("< ok >")
        elif cmd == "rawmode" and client.channel is not None:
            client.write("< ok >")
            client.active_after = time.monotonic() + HANDSHAKE_SETTLE_S
        elif cmd == "send" and client.active_after is not None:
            self._on_send(client, words[1:])
        else:
            self.stats["bad_commands"] += 1
            try:
                client.write("< error unknown command >")
            except OSError:
                pass

    def _on_send(self, sender: _Client, args: list[str]) -> None:
        try:
            id_str, length = args[0], int(args[1], 16)
            can_id = int(id_str, 16)
            payload = bytearray(int(b, 16) for b in args[2:2 + length])
            if len(payload) != length or any(b > 255 for b in payload):
                raise ValueError
        except (IndexError, ValueError):
            self.stats["bad_commands"] += 1
            return
        self.stats["frames_in"] += 1
        with self._rng_lock:
            dropped = self.drop > 0 and self._rng.random() < self.drop
            corrupt = not dropped and payload and self.corrupt > 0 and self._rng.random() < self.corrupt
            if corrupt:
                payload[self._rng.randrange(len(payload))] ^= self._rng.randrange(1, 256)
        if dropped:
            self.stats["dropped"] += 1
            return
        if corrupt:
            self.stats["corrupted"] += 1
        if self.delay_s > 0:
            time.sleep(self.delay_s)  # per sender: keeps its frame order, like a slow bus
        ts = time.time()
        id_out = f"{can_id & 0x7FF:03X}" if len(id_str) <= 3 else f"{can_id & 0x1FFFFFFF:08X}"
        line = f"< frame {id_out} {int(ts)}.{int((ts % 1) * 1e6):06d} {payload.hex().upper()} >"
        now = time.monotonic()
        with self._lock:
            targets = [c for c in self._clients if c is not sender and c.channel == sender.channel
                       and c.active_after is not None and now >= c.active_after]
        for c in targets:
            try:
                c.write(line)
                self.stats["frames_out"] += 1
            except OSError:
                pass  # its reader thread cleans it up


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--host", default="127.0.0.1", help="listen address (loopback only on this machine)")
    p.add_argument("--port", type=int, default=29536, help="TCP port; 0 picks a free one (printed)")
    p.add_argument("--drop", type=float, default=0.0, help="probability of dropping a frame")
    p.add_argument("--delay-ms", type=float, default=0.0, help="added latency per frame (ms)")
    p.add_argument("--corrupt", type=float, default=0.0, help="probability of flipping one byte of a frame")
    p.add_argument("--seed", type=int, default=None, help="seed of the fault injection")
    p.add_argument("--duration", type=float, default=None, help="stop after this many seconds (default: until SIGINT/SIGTERM)")


def cmd(a: argparse.Namespace) -> int:
    if not 0 <= a.port <= 65535:
        raise ValueError(f"can-hub: --port must be 0..65535, got {a.port}")
    try:
        hub = CanHub(port=a.port, host=a.host, drop=a.drop, delay_s=a.delay_ms / 1000.0, corrupt=a.corrupt, seed=a.seed)
        hub.start()
    except OSError as exc:
        raise ValueError(f"can-hub: cannot listen on {a.host}:{a.port}: {exc.strerror or exc}") from None
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    print(f"can-hub listening on {hub.host}:{hub.port} (socketcand; channel any, e.g. vcan0)", flush=True)
    stop.wait(a.duration)
    hub.stop()
    print("can-hub stopped: " + ", ".join(f"{k}={v}" for k, v in hub.stats.items()), flush=True)
    return 0


def main(argv: list[str] | None = None) -> int:
    from edge_runtime.cli import OneLineParser, run

    p = OneLineParser(prog="python -m firmware_sim can-hub",
                      description="simulated CAN bus: a socketcand-protocol hub on 127.0.0.1")
    add_arguments(p)
    a = p.parse_args(argv)
    return run(lambda: cmd(a), bad_input=(ValueError,))


if __name__ == "__main__":
    sys.exit(main())
