"""GOLA-HRC: the gradient-based online learning algorithm of dissertation section 4.2.2.

The robot holds the work-piece; after every task cycle the worker's CAP
(:mod:`edge_runtime.posture.cap`) at the current end-effector height P and pitch O is
known, and GOLA moves the end effector once, toward a lower CAP, until the
CAP stops changing. Two degrees of freedom: the height P (metres above the
floor, i.e. robot-frame y + 0.914 m) and the pitch O (degrees: the tilt of
the work-piece about the robot x axis, positive = its face turned toward the
worker on the +z side; 0 = as set up, face up).

The equations as printed (Eq. 1-9) and as implemented::

    grad_p = (CAP_p - CAP) / dh            grad_o = (CAP_o - CAP) / da              (1, 2)
    dh = -min(lp * |grad_p|, sp) * sign(grad_p)                                     (3)
    da = -min(lo * |grad_o|, so) * sign(grad_o)                                     (4)
    P <- P + dh,  O <- O + da,  lp <- d_alpha * lp,  lo <- d_alpha * lo             (5-8)
    stop when |CAP_p - CAP| < eps and |CAP_o - CAP| < eps                            (9)

* **Descent.** The printed Eq. 3-4 read ``dh = min(lp * grad_p, sp) * grad_p/|grad_p|``,
  which steps *up* the gradient (toward a worse CAP) and, for a negative gradient,
  caps nothing. The algorithm minimises CAP, so the step here is against the
  gradient and its length is ``min(l * |grad|, s)``.
* **One robot move per task cycle.** CAP_p and CAP_o need a task cycle each, so
  the coordinates take turns (coordinate descent): cycle 1 measures CAP at
  (P0, O0); cycle 2 moves the height by the search step dh0 and measures CAP_p;
  cycle 3 moves the pitch by da0 and measures CAP_o; from then on each cycle
  moves one coordinate by its descent step (3)-(4), computed from the CAP change
  that coordinate's previous move caused. The step just taken is the next
  search step (``dh`` and ``da`` are both "search step length" and step in the
  text). An iteration is one task cycle, one robot move and one CAP. Eq. 9 is
  checked once each coordinate has made ``min_descent_steps`` descent steps after
  its probe (default 1, so at least five task cycles).
* **Units.** Gradients are per metre and per *radian*: with Table 4.1's lo0 =
  1.1, a gradient per degree would give steps of hundredths of a degree.
* **Small steps.** A coordinate whose descent step falls below ``min_step_m`` /
  ``min_step_deg`` holds still (its gradient is then unknown; dividing noise by a
  tiny step would send the next step to the cap); its next CAP change is measured
  at no move, i.e. it is the repetition noise.
* **Reachability.** Every proposal is clamped to the configured safe range
  (height and pitch bounds) and to a sphere of ``reach_m`` around the arm's
  shoulder (Sawyer joint j1, 0.317 m above the base top); a clamp is logged with a
  notice, and the gradient uses the move actually made. A move the robot refuses
  (``unreachable``) is reported with :meth:`GolaSession.refused`: the pose stays
  where it was and that coordinate's next step is halved and reversed.
* **A worker who leaves.** An observation without a valid CAP (``None``, NaN, or an
  invalid :class:`~edge_runtime.posture.cap.CapResult`) pauses the session: nothing is
  learnt, the learning rates do not decay, the robot holds the pose, and the same
  pose is proposed again until a valid CAP arrives.

The session is a small state machine (:meth:`GolaSession.propose` -> move the
robot, run a task cycle -> :meth:`GolaSession.observe`), so it runs the same
in-process and over a robot link. Every iteration (and every pause) is one JSON
line in the session log.
"""
from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import IO, Any

import numpy as np

from edge_runtime import config
from edge_runtime.core.skeleton import BASE_HEIGHT_M
from edge_runtime.errors import ConfigError
from edge_runtime.posture.cap import CapParams, CapResult, cap_score, cycle_cap

SAWYER_SHOULDER_Y_M = 0.317
"""Height of the Sawyer's shoulder joint (j1) above the base top: 0.08 m (j0) + 0.237 m (j1)."""
SAWYER_REACH_M = 1.26
"""Published Sawyer reach from the shoulder (m)."""


class GolaParamError(ConfigError):
    """Impossible GOLA parameters; the message names the key."""


@config.section("gola")
@dataclass(frozen=True)
class GolaParams:
    """GOLA-HRC parameters: Table 4.1's defaults plus the box's safety limits (the [gola] section)."""

    dh0_m: float = 0.15
    """delta_h0: the first height search step (m), Eq. 1."""
    da0_deg: float = 20.0
    """delta_a0: the first pitch search step (deg), Eq. 2."""
    p0_m: float = 1.055
    """P0: the starting height above the floor (m), Eq. 5: the 50th-percentile elbow height."""
    o0_deg: float = 0.0
    """O0: the starting pitch (deg), Eq. 6."""
    lp0: float = 1.1
    """lp0: the height learning rate (m per CAP/m), Eq. 3 and 7."""
    lo0: float = 1.1
    """lo0: the pitch learning rate (rad per CAP/rad), Eq. 4 and 8."""
    sp_m: float = 0.2
    """s_p: the largest height step (m), Eq. 3."""
    so_deg: float = 30.0
    """s_o: the largest pitch step (deg), Eq. 4."""
    d_alpha: float = 0.9
    """d_alpha: learning-rate discount per iteration, Eq. 7-8 (0 < d_alpha <= 1)."""
    epsilon: float = 0.3
    """eps: convergence threshold on the CAP change of each coordinate's last move, Eq. 9."""
    min_descent_steps: int = 1
    """Descent steps (Eq. 3-4) each coordinate must have made before Eq. 9 may stop the session:
    the first height and pitch moves are search probes, not steps, and with repetition noise
    two small probe differences would otherwise end a session after three task cycles."""
    max_iterations: int = 40
    """Task cycles before the session stops unconverged (the Learnt pose is then the last one)."""
    min_step_m: float = 0.005
    """A height step shorter than this is not made (m)."""
    min_step_deg: float = 0.5
    """A pitch step smaller than this is not made (deg)."""
    height_min_m: float = 0.70
    """Lowest work-piece height above the floor the cell allows (m)."""
    height_max_m: float = 1.60
    """Highest work-piece height above the floor the cell allows (m)."""
    pitch_min_deg: float = -30.0
    """Smallest pitch the cell allows (deg; negative = face turned away from the worker)."""
    pitch_max_deg: float = 60.0
    """Largest pitch the cell allows (deg)."""
    workpiece_x_m: float = 0.0
    """Robot-frame x of the work-piece, fixed during a session (m)."""
    workpiece_z_m: float = 0.70
    """Robot-frame z of the work-piece (toward the worker), fixed during a session (m)."""
    reach_m: float = 1.10
    """Largest distance from the arm's shoulder (j1) to the work-piece (m): the Sawyer's 1.26 m
    less the gripper and work-piece."""

    def __post_init__(self):
        def need(key: str, ok: bool, what: str):
            if not ok:
                raise GolaParamError(f"[gola] {key}: must be {what}, got {getattr(self, key)!r}")

        for f in fields(self):
            v = getattr(self, f.name)
            number = isinstance(v, (int, float)) and not isinstance(v, bool)
            need(f.name, number and math.isfinite(v), "a finite number")
        for key in ("dh0_m", "da0_deg", "lp0", "lo0", "sp_m", "so_deg", "epsilon", "min_step_m", "min_step_deg",
                    "reach_m"):
            need(key, getattr(self, key) > 0, "positive")
        need("d_alpha", 0 < self.d_alpha <= 1, "in (0, 1]")
        need("min_descent_steps", isinstance(self.min_descent_steps, int) and self.min_descent_steps >= 0,
             "a non-negative integer")
        need("max_iterations", isinstance(self.max_iterations, int) and self.max_iterations >= 3,
             "an integer of at least 3")
        need("height_min_m", 0 < self.height_min_m < self.height_max_m, "positive and below height_max_m")
        need("pitch_min_deg", -90 <= self.pitch_min_deg < self.pitch_max_deg <= 90,
             "below pitch_max_deg, both within -90..90")
        need("pitch_max_deg", -90 <= self.pitch_max_deg <= 90, "within -90..90")
        need("p0_m", self.height_min_m <= self.p0_m <= self.height_max_m, "within height_min_m..height_max_m")
        need("o0_deg", self.pitch_min_deg <= self.o0_deg <= self.pitch_max_deg, "within pitch_min_deg..pitch_max_deg")
        need("dh0_m", self.dh0_m < self.height_max_m - self.height_min_m, "smaller than the height range")
        lo, hi = self.height_range_reachable()
        need("reach_m", lo <= self.p0_m <= hi, f"long enough to reach p0_m (reachable heights {lo:.3f}..{hi:.3f} m)")

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "[gola]") -> "GolaParams":
        """Parameters from a mapping (a TOML table); unknown keys and bad values name the key."""
        known = {f.name for f in fields(cls)}
        for k in data:
            if k not in known:
                raise GolaParamError(f"{source} {k}: unknown key (known: {', '.join(sorted(known))})")
        return cls(**data)

    @property
    def workpiece_xz_m(self) -> tuple[float, float]:
        """(x, z) of the work-piece in the robot frame (m)."""
        return self.workpiece_x_m, self.workpiece_z_m

    def height_range_reachable(self) -> tuple[float, float]:
        """Heights above the floor (m) the arm reaches at the work-piece's horizontal position."""
        horiz = math.hypot(self.workpiece_x_m, self.workpiece_z_m)
        if horiz >= self.reach_m:
            return (math.inf, -math.inf)
        dy = math.sqrt(self.reach_m ** 2 - horiz ** 2)
        centre = SAWYER_SHOULDER_Y_M + BASE_HEIGHT_M
        return centre - dy, centre + dy

    def clamp(self, height_m: float, pitch_deg: float) -> tuple[float, float, str]:
        """The pose inside the safe range and the arm's reach, and a notice ("" when unchanged)."""
        lo, hi = self.height_range_reachable()
        h_lo, h_hi = max(self.height_min_m, lo), min(self.height_max_m, hi)
        h = min(max(height_m, h_lo), h_hi)
        p = min(max(pitch_deg, self.pitch_min_deg), self.pitch_max_deg)
        notes = []
        if h != height_m:
            by_reach = (h == hi < self.height_max_m) or (h == lo > self.height_min_m)
            why = "the arm's reach" if by_reach else "the safe range"
            notes.append(f"height {height_m:.3f} m clamped to {h:.3f} m ({why} {h_lo:.3f}..{h_hi:.3f} m)")
        if p != pitch_deg:
            notes.append(f"pitch {pitch_deg:.1f} deg clamped to {p:.1f} deg (safe range "
                         f"{self.pitch_min_deg:g}..{self.pitch_max_deg:g} deg)")
        return h, p, "; ".join(notes)


@dataclass(frozen=True)
class Proposal:
    """Where the end effector should be for the next task cycle."""

    iteration: int
    """1-based task cycle this pose is for."""
    height_m: float
    """Work-piece height above the floor (m), after clamping."""
    pitch_deg: float
    """Work-piece pitch (deg), after clamping."""
    moved: str
    """Which coordinate this move changed: "start", "height", "pitch", or "hold" (paused / refused)."""
    notice: str = ""
    """Why the requested pose was changed (clamped), or "" when it was not."""

    @property
    def robot_y_m(self) -> float:
        """The height as a robot-frame y coordinate (m)."""
        return self.height_m - BASE_HEIGHT_M


@dataclass
class _Coordinate:
    """Search state of one degree of freedom (height in m, pitch in rad internally)."""

    step: float                     # the step of the next move (signed)
    rate: float                     # learning rate l
    max_step: float                 # s
    min_step: float
    last_delta_cap: float | None = None
    grad: float | None = None
    moves: int = 0                  # moves made (the first is the search probe)


@dataclass
class GolaSession:
    """One worker's GOLA-HRC session: ``propose()`` -> robot moves, task cycle -> ``observe(cap)``.

    ``state`` is "running", "paused" (no valid pose: the worker left), "converged" or
    "max_iterations". ``log`` (a path or an open text file) receives one JSON line per
    iteration and per pause."""

    params: GolaParams = field(default_factory=GolaParams)
    cap_params: CapParams = field(default_factory=CapParams)
    log: str | Path | IO[str] | None = None
    worker: str = ""
    """A label for the log (participant id)."""

    def __post_init__(self):
        p = self.params
        self.height_m, self.pitch_deg = p.p0_m, p.o0_deg
        self.iteration = 0                  # valid task cycles observed
        self.state = "running"
        self.pauses = 0                     # observations without a valid CAP
        self.refusals = 0                   # moves the robot refused
        self.clamps = 0                     # proposals clamped to the safe range / reach
        self.history: list[dict] = []
        self._coords = {
            "height": _Coordinate(p.dh0_m, p.lp0, p.sp_m, p.min_step_m),
            "pitch": _Coordinate(math.radians(p.da0_deg), p.lo0, math.radians(p.so_deg),
                                 math.radians(p.min_step_deg)),
        }
        self._turn = "start"
        self._pending: Proposal | None = None
        self._prev_pose = (self.height_m, self.pitch_deg)
        self._last_cap: float | None = None
        self._log_file: IO[str] | None = None
        self._own_log = False
        if isinstance(self.log, (str, Path)):
            self._log_file = open(self.log, "a", encoding="utf-8")
            self._own_log = True
        elif self.log is not None:
            self._log_file = self.log

    # -- the state machine ------------------------------------------------------------------
    @property
    def done(self) -> bool:
        return self.state in ("converged", "max_iterations")

    @property
    def rates(self) -> tuple[float, float]:
        """The current learning rates (lp, lo)."""
        return self._coords["height"].rate, self._coords["pitch"].rate

    @property
    def learnt(self) -> tuple[float, float]:
        """(height above the floor in m, pitch in deg): the current pose, the Learnt one once done."""
        return self.height_m, self.pitch_deg

    def propose(self) -> Proposal:
        """The pose for the next task cycle (the same one again while paused or after a refusal)."""
        if self.done:
            raise RuntimeError(f"the session is {self.state}; nothing more to propose")
        if self._pending is not None:
            return self._pending
        turn = self._turn
        if turn == "start":
            prop = Proposal(self.iteration + 1, self.height_m, self.pitch_deg, "start")
        else:
            c = self._coords[turn]
            h, o = self.height_m, self.pitch_deg
            if abs(c.step) >= c.min_step:
                if turn == "height":
                    h += c.step
                else:
                    o += math.degrees(c.step)
            h2, o2, notice = self.params.clamp(h, o)
            if notice:
                self.clamps += 1
            prop = Proposal(self.iteration + 1, h2, o2, turn, notice)
        self._prev_pose = (self.height_m, self.pitch_deg)
        self.height_m, self.pitch_deg = prop.height_m, prop.pitch_deg
        self._pending = prop
        return prop

    def refused(self, reason: str = "unreachable") -> Proposal:
        """The robot refused the last proposal: go back to the previous pose, reverse and halve that
        coordinate's step, and log it. Returns the pose to hold (the previous one)."""
        prop = self._pending
        if prop is None:
            raise RuntimeError("refused() without a pending proposal")
        self.refusals += 1
        self.height_m, self.pitch_deg = self._prev_pose
        if prop.moved in self._coords:
            c = self._coords[prop.moved]
            c.step = -0.5 * c.step
            self._turn = "pitch" if prop.moved == "height" else "height"
        held = Proposal(prop.iteration, self.height_m, self.pitch_deg, "hold",
                        f"robot refused height {prop.height_m:.3f} m, pitch {prop.pitch_deg:.1f} deg: {reason}")
        self._pending = held
        self._write({"event": "refused", "iteration": prop.iteration, "reason": reason,
                     "requested": {"height_m": prop.height_m, "pitch_deg": prop.pitch_deg}})
        return held

    def observe(self, cap: float | CapResult | None) -> str:
        """The CAP of the task cycle done at the last proposal; returns the new state."""
        prop = self._pending
        if prop is None:
            raise RuntimeError("observe() without a proposal: call propose() and move the robot first")
        value, reason = _cap_value(cap)
        if value is None:
            self.pauses += 1
            self.state = "paused"
            self._write({"event": "paused", "iteration": prop.iteration, "reason": reason,
                         "height_m": self.height_m, "pitch_deg": self.pitch_deg, "pauses": self.pauses})
            return self.state
        self._pending = None
        self.iteration += 1
        self.state = "running"
        grad_info = self._learn(prop, value)
        rec = {"event": "iteration", "iteration": self.iteration, "worker": self.worker, "moved": prop.moved,
               "height_m": round(prop.height_m, 5), "pitch_deg": round(prop.pitch_deg, 4), "cap": round(value, 5),
               **grad_info, "lp": self._coords["height"].rate, "lo": self._coords["pitch"].rate,
               "state": self.state}
        if prop.notice:
            rec["notice"] = prop.notice
        if isinstance(cap, CapResult):
            rec["parts"] = {k: round(v, 4) for k, v in cap.parts.items()}
        self.history.append(rec)
        self._write(rec)
        return self.state

    def observe_joints(self, joints: np.ndarray) -> str:
        """Observe one (17, 3) pose or a (T, 17, 3) task cycle: CAP with this session's weights."""
        j = np.asarray(joints, dtype=float)
        res = cap_score(j, self.cap_params) if j.ndim == 2 else cycle_cap(j, self.cap_params)
        return self.observe(res)

    def close(self) -> None:
        if self._own_log and self._log_file is not None:
            self._log_file.close()
            self._log_file = None

    def summary(self) -> dict:
        """JSON-ready outcome of the session."""
        return {"worker": self.worker, "state": self.state, "iterations": self.iteration,
                "learnt": {"height_m": self.height_m, "pitch_deg": self.pitch_deg},
                "pauses": self.pauses, "refusals": self.refusals, "clamps": self.clamps,
                "params": asdict(self.params)}

    # -- internals --------------------------------------------------------------------------
    def _learn(self, prop: Proposal, cap: float) -> dict:
        """Eq. 1-9 for the coordinate the last move changed; decide the next turn and the state."""
        info: dict = {}
        if prop.moved in self._coords:
            c = self._coords[prop.moved]
            old = self._prev_pose
            moved_by = (prop.height_m - old[0]) if prop.moved == "height" else math.radians(prop.pitch_deg - old[1])
            c.last_delta_cap = cap - self._last_cap
            c.moves += 1
            if abs(moved_by) >= 0.5 * c.min_step:
                c.grad = c.last_delta_cap / moved_by                                   # Eq. 1-2
                c.step = -min(c.rate * abs(c.grad), c.max_step) * float(np.sign(c.grad))  # Eq. 3-4 (descent)
            else:
                c.grad = None
                c.step = 0.0
            info = {"delta_cap": round(c.last_delta_cap, 5), "gradient": None if c.grad is None else round(c.grad, 5),
                    "next_step": round(c.step if prop.moved == "height" else math.degrees(c.step), 5)}
        self._last_cap = cap
        for c in self._coords.values():                                            # Eq. 7-8
            c.rate *= self.params.d_alpha
        self._turn = {"start": "height", "height": "pitch", "pitch": "height", "hold": self._turn}[prop.moved]
        eps = self.params.epsilon
        ready = all(c.moves > self.params.min_descent_steps for c in self._coords.values())
        deltas = [c.last_delta_cap for c in self._coords.values()]
        if ready and all(d is not None and abs(d) < eps for d in deltas):           # Eq. 9
            self.state = "converged"
        elif self.iteration >= self.params.max_iterations:
            self.state = "max_iterations"
        return info

    def _write(self, rec: dict) -> None:
        if self._log_file is not None:
            self._log_file.write(json.dumps(rec) + "\n")
            self._log_file.flush()


def _cap_value(cap: float | CapResult | None) -> tuple[float | None, str]:
    """(the CAP, "") or (None, why it is not usable)."""
    if cap is None:
        return None, "no pose (the worker left or was not seen)"
    if isinstance(cap, CapResult):
        if not cap.valid:
            return None, cap.reason or "invalid CAP"
        cap = cap.cap
    v = float(cap)
    if not math.isfinite(v):
        return None, f"CAP is not finite ({v})"
    return v, ""


__all__ = ["GolaParams", "GolaParamError", "GolaSession", "Proposal", "SAWYER_REACH_M", "SAWYER_SHOULDER_Y_M"]
