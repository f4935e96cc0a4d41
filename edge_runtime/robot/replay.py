"""``python -m edge_runtime robot --link none``: the robot-side decision chain with no arm.

An integrator audits a recorded shift with it: the same input, lifter, tracker, calibration,
hazard monitor and loop as on the box, but the commands go to :class:`NoArm`, which
carries nothing anywhere. ``--fast`` replays the recording on a simulated clock (the
frames' own timestamps, the loop ticked every ``TICK_S`` of recording time between them),
as fast as the machine can; without it the recording is replayed in real time.

:class:`NoArm` is honest about what it is: it answers every command at once (so the loop
sees an arm that does what it is told, and runs its normal task cycle), and moves its hand
toward the last target at ``speed_mps`` (so distances to the end effector change as the task
would move them), but no arm was connected, and the summary says so: ``link_verdict`` is
never "ok", and nothing in the log means that a real arm was safe.
"""
from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from edge_runtime.robot.link.base import LinkInterface
from edge_runtime.robot.link.protocol import RobotState, blank_state

NO_ARM_VERDICT = "none: no arm was connected; commands were logged, not sent, and nothing here shows an arm was safe"
TICK_S = 0.01
"""Control cycle of the replay, in recording time (s): the loop's tick() between frames."""


class NoArm(LinkInterface):
    """A stand-in for the arm (module docstring): answers "ok" to every command and moves its
    hand toward the last target at ``speed_mps`` on the loop's clock; stops when told."""

    connected = False
    """No arm behind it: the command's summary says so."""

    def __init__(self, clock, start_m=(0.45, 0.14, 0.55), speed_mps: float = 0.5):
        self.clock = clock
        self.speed_mps = speed_mps
        self.limit_mps = speed_mps
        """The speed override the loop set last (speed and separation monitoring)."""
        self._seq = 0
        self._target: np.ndarray | None = None
        self._t = clock()
        self._state = replace(blank_state(self._t), ee_position_m=np.array(start_m, float), mode="stopped")
        self.commands: dict[str, int] = {}
        """Commands the loop gave, by name (what it would have sent)."""
        self.runtime_state = "starting"

    def _command(self, name: str) -> int:
        self.commands[name] = self.commands.get(name, 0) + 1
        self._seq = self._seq % 65535 + 1
        return self._seq

    def move_to(self, position_m, pitch_rad: float, yaw_rad: float) -> int:
        if self._state.mode != "stopped":
            self._target = np.asarray(position_m, float)
        self._state = replace(self._state, yaw_rad=float(yaw_rad), pitch_rad=float(pitch_rad))
        return self._command("move")

    def retract(self, position_m, pitch_rad: float, yaw_rad: float) -> int:
        self._target = np.asarray(position_m, float)
        self._state = replace(self._state, mode="retract", yaw_rad=float(yaw_rad), pitch_rad=float(pitch_rad))
        return self._command("retract")

    def stop(self) -> int:
        self._target = None
        self._state = replace(self._state, mode="stopped")
        return self._command("stop")

    def resume(self) -> int:
        self._state = replace(self._state, mode="run")
        return self._command("resume")

    def set_alarm(self, light: str, tone_hz: float, tone_db: float) -> int:
        self._state = replace(self._state, light=light, tone_hz=float(tone_hz), tone_db=float(tone_db))
        return self._command("alarm")

    def set_speed(self, limit_mps: float) -> int:
        self.limit_mps = float(limit_mps)
        return self._command("speed")

    def heartbeat(self) -> bool:
        return True

    def set_runtime_state(self, state: str) -> None:
        self.runtime_state = state

    def poll(self) -> RobotState | None:
        now = self.clock()
        pos = self._state.ee_position_m
        if self._target is not None and now > self._t:
            step = self._target - pos
            dist = float(np.linalg.norm(step))
            reach = min(self.speed_mps, self.limit_mps) * (now - self._t)
            pos = self._target.copy() if dist <= reach else pos + step * (reach / dist)
        self._t = now
        self._state = replace(self._state, t_s=now, ee_position_m=pos)
        return self._state

    def result(self, seq: int) -> str | None:
        return "ok" if isinstance(seq, int) and seq > 0 else None  # every command is "carried out" at once

    @property
    def state(self) -> RobotState | None:
        return self._state

    @property
    def link_ok(self) -> bool:
        return True

    @property
    def heartbeats_itself(self) -> bool:
        return True

    def summary(self) -> dict:
        return {"arm": "none", **{f"would_send_{k}": v for k, v in sorted(self.commands.items())}}

    def close(self) -> None:
        pass


class ReplayClock:
    """The loop's clock in a ``--fast`` replay: recording time, moved on by the driver."""

    def __init__(self):
        self.now_s = 0.0

    def __call__(self) -> float:
        return self.now_s


def fast_frames(loop, clock: ReplayClock, frames, duration_s: float | None):
    """A recording as fast as it goes: for each (t_s, feed), tick the loop every ``TICK_S`` of
    recording time since the previous frame, set the clock to the frame's time and yield
    (t from the first frame s, feed). The loop never waits."""
    t0 = None
    for t_s, feed in frames:
        if t0 is None:
            t0 = t_s
            clock.now_s = t_s
        if duration_s and t_s - t0 > duration_s:
            return
        ticks = max(0, math.ceil((t_s - clock.now_s) / TICK_S) - 1)
        for _ in range(ticks):
            clock.now_s += TICK_S
            loop.tick()
        clock.now_s = t_s
        yield t_s - t0, feed
    clock.now_s += TICK_S
    loop.tick()
