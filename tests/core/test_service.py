"""edge_runtime/core/service.py: the test plays systemd's side of the notify protocol on a real
unix datagram socket. READY=1 arrives, a healthy loop's WATCHDOG=1 keep-alives arrive every
half interval of WATCHDOG_USEC, and a hung loop's stop. Time is a counter the test turns, so
nothing here depends on how loaded the machine is."""
import json
import os
import socket
import threading

import numpy as np
import pytest

from edge_runtime.core import service
from edge_runtime.wearable import command
from edge_runtime.wearable.alerts import WearableStatus
from edge_runtime.wearable.labels import CLASSES
from edge_runtime.wearable.loop import WearableLoop
from edge_runtime.wearable.sources import ImuBlock, ReplayStats

WATCHDOG_USEC = 2_000_000  # WatchdogSec=2: keep-alives due every 1 s


class Clock:
    """A monotonic clock that moves only when told to (s)."""

    def __init__(self):
        self.now_s = 0.0

    def __call__(self) -> float:
        return self.now_s


@pytest.fixture
def supervisor(tmp_path):
    """systemd's notify socket: a bound datagram socket, non-blocking, and the environment naming it."""
    sock = socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM)
    path = str(tmp_path / "notify")
    sock.bind(path)
    sock.setblocking(False)
    yield sock, {"NOTIFY_SOCKET": path, "WATCHDOG_USEC": str(WATCHDOG_USEC), "WATCHDOG_PID": str(os.getpid())}
    sock.close()


def received(sock) -> list[bytes]:
    """Every datagram waiting on the socket (none waits for more: the sends are synchronous)."""
    out = []
    while True:
        try:
            out.append(sock.recv(4096))
        except BlockingIOError:
            return out


def test_ready_first_then_keepalives_every_half_interval(supervisor):
    sock, env = supervisor
    clock = Clock()
    n = service.Notifier(env, clock)
    assert n.keepalive_interval_s == WATCHDOG_USEC / 2e6
    sent_at = []
    for step in range(101):  # a loop iterating every 50 ms for 5 s
        clock.now_s = step * 0.05
        n.alive()
        sent_at += [(clock.now_s, m) for m in received(sock)]
    assert sent_at[0] == (0.0, b"READY=1")
    assert [m for _, m in sent_at[1:]] == [b"WATCHDOG=1"] * 5
    assert np.allclose([t for t, _ in sent_at[1:]], [1.0, 2.0, 3.0, 4.0, 5.0])
    assert n.keepalives_sent == 5 and n.send_errors == 0
    n.close()


def test_abstract_socket_name(supervisor):
    _, env = supervisor
    name = f"edge-safety-test-{os.getpid()}"
    with socket.socket(socket.AF_UNIX, socket.SOCK_DGRAM) as sock:
        sock.bind(b"\0" + name.encode())
        n = service.Notifier({**env, "NOTIFY_SOCKET": "@" + name}, Clock())
        n.alive()
        assert sock.recv(64) == b"READY=1"
        n.close()


@pytest.mark.parametrize("env, interval_s", [
    ({}, None),                                                     # not under systemd: nothing to do
    ({"WATCHDOG_USEC": "2000000", "WATCHDOG_PID": "1"}, None),      # the watchdog is another process's
    ({"WATCHDOG_USEC": "soon"}, None),
    ({"WATCHDOG_USEC": "300000"}, 0.15),
])
def test_watchdog_interval_from_the_environment(env, interval_s):
    assert service.Notifier({"NOTIFY_SOCKET": "/run/nowhere", **env}).keepalive_interval_s == interval_s


def test_no_notify_socket_sends_nothing_and_a_dead_socket_is_counted_not_raised(tmp_path):
    quiet = service.Notifier({}, Clock())
    quiet.alive()
    assert not quiet.enabled and not quiet.ready_sent
    gone = service.Notifier({"NOTIFY_SOCKET": str(tmp_path / "no-such-socket")}, Clock())
    gone.alive()
    gone.alive()
    assert gone.send_errors == 2 and not gone.ready_sent  # READY is retried, the loop goes on


class NoClassifier:
    classes = CLASSES

    def classify_capture(self, x700):
        raise AssertionError("a recording at rest never triggers the detector")


class NoBus:
    """Stands in for the AlertPublisher: its status, and frames that are taken and dropped."""

    period = 0.1  # the heartbeat period (s) a replay's data clock steps by

    def __init__(self):
        self.status = WearableStatus()

    def advance_to(self, t_s):
        pass

    def send_heartbeat(self):
        return True

    def beat_if_due(self):
        pass

    def publish_alert(self, alert):
        return 0

    def check_running(self):
        pass  # no heartbeat thread to have died

    def send_alert(self, alert):
        return True


class HangingSource:
    """Blocks of a wrist at rest; after ``healthy`` of them the next one never comes (a hung
    driver), until the test lets it go. Each block moves the clock on by its own length."""

    def __init__(self, clock: Clock, healthy: int, block_s: float = 0.1):
        self.clock, self.healthy, self.block_s = clock, healthy, block_s
        self.hung, self.release = threading.Event(), threading.Event()

    def __iter__(self):
        rest = np.tile(np.float32([0.0, 0.0, 9.81]), (int(self.block_s * 100), 1))
        for i in range(self.healthy):
            self.clock.now_s = i * self.block_s
            yield ImuBlock(i * self.block_s, rest)
        self.hung.set()
        self.release.wait(timeout=60)


def test_the_wearable_drive_loop_keeps_alive_while_it_turns_and_goes_silent_when_it_hangs(supervisor):
    sock, env = supervisor
    clock = Clock()
    source = HangingSource(clock, healthy=35)  # 3.5 s of samples in 0.1 s blocks
    previous = service.reset(service.Notifier(env, clock))
    try:
        loop = WearableLoop(NoClassifier(), publisher=NoBus())
        drive = threading.Thread(target=command._drive, args=(command._Source(iter(source), ReplayStats()), loop, []),
                                 daemon=True)
        drive.start()
        assert source.hung.wait(timeout=20)
        healthy = received(sock)
        assert healthy == [b"READY=1"] + [b"WATCHDOG=1"] * 3  # at 1.0, 2.0, 3.0 s of a 3.4 s run
        clock.now_s += 10 * WATCHDOG_USEC / 1e6  # ten watchdog intervals pass with the loop stuck
        assert drive.is_alive() and received(sock) == []  # systemd hears nothing, and restarts it
    finally:
        source.release.set()
        service.reset(previous)
    drive.join(timeout=60)
    assert not drive.is_alive()


class SteppingClock(Clock):
    """Each reading is ``step_s`` later than the one before: one loop iteration per reading."""

    def __init__(self, step_s: float):
        super().__init__()
        self.step_s = step_s

    def __call__(self) -> float:
        self.now_s += self.step_s
        return self.now_s


def test_the_robot_drive_loop_sends_ready_then_keepalives_per_turn(supervisor, tmp_path, monkeypatch):
    from support.robot import FakeLink

    from edge_runtime.__main__ import main
    from edge_runtime.robot import command as robot_cli
    from firmware_sim.people import human

    sock, env = supervisor
    body = human.Body.from_height(1.8)
    frames = 12  # 0.4 s of a worker standing 3 m from the arm, at 30 Hz
    rows = [{"t": i / 30, "joints_robot_m": human.joints(body, human.Posture(), pelvis_xz_m=(0.0, 3.0)).tolist()}
            for i in range(frames)]
    (tmp_path / "joints.jsonl").write_text("".join(json.dumps(r) + "\n" for r in rows))
    monkeypatch.setattr(robot_cli, "_open_link", lambda cfg: FakeLink())
    previous = service.reset(service.Notifier(env, SteppingClock(WATCHDOG_USEC / 1e6 / 4)))  # 2 turns per keep-alive
    try:
        assert main(["robot", "--joints", str(tmp_path / "joints.jsonl"), "--quiet"]) == 0
    finally:
        service.reset(previous)
    assert received(sock) == [b"READY=1"] + [b"WATCHDOG=1"] * ((frames - 1) // 2)
