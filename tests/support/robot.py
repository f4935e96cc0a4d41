"""Robot-link stand-ins and helpers shared by the robot-side tests."""
from __future__ import annotations

import threading
import time
from dataclasses import replace

import numpy as np

from edge_runtime.core.skeleton import BASE_HEIGHT_M, L_ANKLE, R_ANKLE
from edge_runtime.robot.calibration import Calibration, CalibrationParams
from edge_runtime.robot.link.base import LinkInterface, open_link
from edge_runtime.robot.link.protocol import blank_state, open_can_bus
from firmware_sim.devices.camera import Camera
from firmware_sim.people import human
from firmware_sim.robot.controller import (
    CanControllerPort,
    SawyerController,
    SimulatedRobot,
    run_realtime,
)

TARGET = (0.45, 0.25, 0.55)
"""A reachable hand position (m, robot frame)."""
EFF = np.array([0.0, 0.14, 0.8])
"""The end effector where the hazard and retraction tests put it (m, robot frame)."""
HEAD_Y = 0.75
"""A 1.75 m worker's head height (m, robot frame; the floor is at -0.914)."""
FPS = 30.0


def head_at(dist_m, direction=(0.0, 1.0)):
    """A head ``dist_m`` from EFF on the ground, along ``direction`` (x, z)."""
    d = np.asarray(direction, float) / np.linalg.norm(direction)
    return np.array([EFF[0] + dist_m * d[0], HEAD_Y, EFF[2] + dist_m * d[1]])


def true_calibration(cam: Camera, params: CalibrationParams = CalibrationParams()) -> Calibration:
    """The exact camera -> robot map of a simulated camera."""
    z = np.zeros((3, 3))
    return Calibration(cam.R.T, cam.position_m, "rigid", 1.6, z, z, params)


def anchored_worker(xz, heading=0.3):
    """A standing worker's robot-frame joints, ankles put exactly at the ground anchoring's ankle height."""
    j = human.joints(human.Body.from_height(1.75), human.Posture(), pelvis_xz_m=xz, heading_rad=heading)
    floor = -BASE_HEIGHT_M + CalibrationParams().ankle_height_m
    return j - [0.0, min(j[L_ANKLE, 1], j[R_ANKLE, 1]) - floor, 0.0]


class FakeLink(LinkInterface):
    """Records every command; ``fail`` makes commands raise; ``unreachable_retract`` has the
    "controller" answer every retraction unreachable; ``answer`` is its answer to every other
    command ("ok"; "refused"; None: it never answers). Its arm moves toward the last target
    at ``speed_mps`` when ``advance`` is called, and its tool turns to a target's yaw at once."""

    def __init__(self, start=(0.0, 0.14, 0.8), speed_mps=0.6):
        self._state = replace(blank_state(), ee_position_m=np.array(start, float))
        self.target = None
        self.stopped = True
        self.speed = speed_mps
        self.calls = []
        self.fail = False
        self.unreachable_retract = False
        self.runtime_state = "starting"
        self.answer: str | None = "ok"
        self._answers: dict[int, str] = {}

    def _log(self, name, *args) -> int:
        if self.fail:
            raise ConnectionError("link down")
        self.calls.append((name, *args))
        seq = len(self.calls)  # the command's sequence number
        if self.answer is not None and name != "heartbeat":
            self._answers[seq] = self.answer
        return seq

    def move_to(self, position_m, pitch_rad, yaw_rad):
        seq = self._log("move_to", tuple(position_m), pitch_rad, yaw_rad)
        self.target = np.array(position_m)
        self._state = replace(self._state, yaw_rad=yaw_rad)
        return seq

    def retract(self, position_m, pitch_rad, yaw_rad):
        seq = self._log("retract", tuple(position_m), pitch_rad, yaw_rad)
        self.retract_from = self._state.ee_position_m.copy()
        self.retracts_from = [*getattr(self, "retracts_from", []), self.retract_from]
        self.stopped = False
        if self.unreachable_retract:
            self._answers[seq], self.target = "unreachable", None
        else:
            self.target = np.array(position_m)
            self._state = replace(self._state, yaw_rad=yaw_rad)
        return seq

    def stop(self):
        seq = self._log("stop")
        self.stopped, self.target = True, None
        return seq

    def resume(self):
        seq = self._log("resume")
        self.stopped = False
        return seq

    def set_alarm(self, light, tone_hz, tone_db):
        return self._log("set_alarm", light, tone_hz, tone_db)

    def set_speed(self, limit_mps):
        """The speed override: recorded (``speed_limit_mps``); this arm's own motion ignores it."""
        self.speed_limit_mps = limit_mps
        return self._log("set_speed", limit_mps)

    def heartbeat(self):
        self._log("heartbeat")
        return True

    def set_runtime_state(self, state):
        self.runtime_state = state

    def poll(self):
        return self._state

    def result(self, seq):
        return self._answers.get(seq)

    @property
    def state(self):
        return self._state

    @property
    def link_ok(self):
        return True

    @property
    def heartbeats_itself(self):
        return False

    def advance(self, dt):
        if self.target is not None and not self.stopped:
            d = self.target - self._state.ee_position_m
            n = np.linalg.norm(d)
            step = min(n, self.speed * dt)
            if n > 0:
                self._state = replace(self._state, ee_position_m=self._state.ee_position_m + d / n * step)

    def names(self):
        return [c[0] for c in self.calls]

    # what the robot command uses of a RobotLink beyond the LinkInterface
    def close(self):
        self.closed = True

    def summary(self):
        return {"kind": "fake", "calls": len(self.calls)}


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


def start_simulated(sim: SimulatedRobot) -> None:
    """Let the simulated controller boot, then resume it (it boots stopped)."""
    sim.step(0.05)
    seq = sim.link.resume()
    sim.step(0.05)
    assert sim.link.result(seq) == "ok" and sim.link.state.mode == "run"


def exercise_live_controller(link) -> None:
    """Against a controller process in real time: move, light and tone, watchdog, stop."""
    seq = link.resume()
    assert pump(link, 3.0, lambda: link.result(seq) == "ok")
    move = link.move_to(TARGET, 0.0, 0.0)
    assert pump(link, 8.0, lambda: link.state.at_target and link.state.last_seq == move)
    assert np.linalg.norm(link.state.ee_position_m - TARGET) < 1e-3
    alarm = link.set_alarm("yellow", 4000.0, 80.0)
    alarm_state = lambda: (link.state.light, link.state.tone_hz, link.state.tone_db)  # noqa: E731
    assert pump(link, 2.0, lambda: alarm_state() == ("yellow", 4000.0, 80.0))
    assert link.result(alarm) == "ok"

    link.move_to((-0.2, 0.4, 0.6), 0.0, 0.0)
    assert pump(link, 2.0, lambda: link.state.moving)
    time.sleep(0.4)  # the runtime goes quiet: no heartbeat, no command
    assert pump(link, 1.0, lambda: link.state.watchdog and link.state.mode == "stopped")
    assert pump(link, 2.0, lambda: not link.state.moving and link.state.ee_speed_mps == 0.0)
    pump(link, 0.3)  # heartbeats again: still latched
    assert link.state.watchdog
    seq = link.resume()
    assert pump(link, 2.0, lambda: link.result(seq) == "ok" and not link.state.watchdog)

    link.move_to(TARGET, 0.3, -0.4)
    assert pump(link, 2.0, lambda: link.state.ee_speed_mps > 0.05)
    stop = link.stop()
    assert pump(link, 2.0, lambda: link.result(stop) == "ok" and link.state.mode == "stopped")
    assert pump(link, 2.0, lambda: not link.state.moving and link.state.ee_speed_mps == 0.0)
    assert np.linalg.norm(link.state.ee_position_m - TARGET) > 0.01  # halted on the way
