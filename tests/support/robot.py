"""Robot-link stand-ins and helpers shared by the robot-side tests."""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass

import numpy as np

from edge_runtime.robot.link.base import open_link
from edge_runtime.robot.link.protocol import open_can_bus
from firmware_sim.robot.controller import (
    CanControllerPort,
    SawyerController,
    run_realtime,
)


@dataclass
class FakeState:
    ee_position_m: np.ndarray
    unreachable: bool = False


class FakeLink:
    """Records every call; ``fail`` makes calls raise; ``unreachable_retract`` refuses retracts."""

    def __init__(self, start=(0.0, 0.14, 0.8), speed_mps=0.6):
        self.state = FakeState(np.array(start, float))
        self.target = None
        self.stopped = True
        self.speed = speed_mps
        self.calls = []
        self.fail = False
        self.unreachable_retract = False

    def _log(self, name, *args):
        if self.fail:
            raise ConnectionError("link down")
        self.calls.append((name, *args))

    def move_to(self, position_m, pitch_rad, yaw_rad):
        self._log("move_to", tuple(position_m), pitch_rad, yaw_rad)
        self.target, self.state.unreachable = np.array(position_m), False

    def retract(self, position_m, pitch_rad, yaw_rad):
        self._log("retract", tuple(position_m), pitch_rad, yaw_rad)
        self.retract_from = self.state.ee_position_m.copy()
        self.stopped = False
        if self.unreachable_retract:
            self.state.unreachable, self.target = True, None
        else:
            self.target = np.array(position_m)

    def stop(self):
        self._log("stop")
        self.stopped, self.target = True, None

    def resume(self):
        self._log("resume")
        self.stopped = False

    def set_alarm(self, light, tone_hz, tone_db):
        self._log("set_alarm", light, tone_hz, tone_db)

    def heartbeat(self):
        self._log("heartbeat")

    def poll(self):
        return self.state

    def advance(self, dt):
        if self.target is not None and not self.stopped:
            d = self.target - self.state.ee_position_m
            n = np.linalg.norm(d)
            step = min(n, self.speed * dt)
            if n > 0:
                self.state.ee_position_m = self.state.ee_position_m + d / n * step

    def names(self):
        return [c[0] for c in self.calls]


def pump(link, seconds: float, until=None) -> bool:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        link.poll()
        if until is not None and until():
            return True
        time.sleep(0.005)
    return until is None


class InProcessController:
    """The controller on a socketcand bus in a real-time thread (in-process, for inspection)."""

    def __init__(self, hub):
        factory = lambda: open_can_bus("socketcand", "vcan0", "127.0.0.1", hub.port)  # noqa: E731
        self.controller = SawyerController(CanControllerPort(bus=factory(), bus_factory=factory))
        self.stop = threading.Event()
        self.thread = threading.Thread(target=run_realtime, args=(self.controller, 30.0, self.stop), daemon=True)

    def __enter__(self):
        self.thread.start()
        return self.controller

    def __exit__(self, *exc):
        self.stop.set()
        self.thread.join(5)
        self.controller.port.close()


def can_link(hub):
    link = open_link("can", interface="socketcand", host="127.0.0.1", port=hub.port, channel="vcan0")
    assert pump(link, 5.0, lambda: link.link_ok)
    return link
