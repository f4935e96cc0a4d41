"""Where the arm's productive time goes: ``python -m firmware_sim hrc`` with the monitor's state,
reason and measurement recorded at every judged control step, then each non-NORMAL step put in one
bucket (see ``classify``).

Usage (same arguments as ``hrc``; its own --json is written as usual):

    PYTHONPATH=. python reports/hrc/s17_prodshare/record_states.py SEGMENTS.json.gz -- \
        --scenario hard:60 --seed 19 --link can --max-speed 2.0 --perception lifter \
        --protection speed_scaled --json OUT.json --jobs 1 --quiet

Nothing in the product is changed: three functions are wrapped for the run (``RobotLoop.tick``, after
which the judge reads the state; ``HazardMonitor._update_level``, which sees the monitor's measured
entry level, the separation its exit is judged on and the exit radii; ``hrc_world._true_separation``,
the judge's true whole-body separation, computed every 5th step and at level changes, carried forward
in between). ``--jobs 1`` only (the wrappers live in this process).
"""
from __future__ import annotations

import gzip
import json
import sys
from collections import defaultdict

from edge_runtime.robot import hazard, loop
from edge_runtime.robot.hazard import State
from firmware_sim.scenarios import hrc, hrc_world

_rec: dict = {}


def _reset():
    _rec.update(steps=[], true_at={}, entry=None, d_exit=None, exit_r=None)


_orig_update_level = hazard.HazardMonitor._update_level
_orig_tick = loop.RobotLoop.tick
_orig_true_sep = hrc_world._true_separation
_orig_run = hrc.run_scenario


def _update_level(self, t_s, entry, d, est, exit_r):
    _rec["entry"], _rec["d_exit"] = int(entry), float(d)
    _rec["exit_r"] = {int(k): float(v) for k, v in exit_r.items()}
    return _orig_update_level(self, t_s, entry, d, est, exit_r)


def _tick(self):
    _orig_tick(self)
    m = self.monitor
    _rec["steps"].append((int(m.state), m.reason, int(m.level), _rec["entry"], _rec["d_exit"],
                          _rec["exit_r"], bool(self._escaping), m.last.speed_scale))


def _true_separation(*a, **kw):
    d = _orig_true_sep(*a, **kw)
    if _rec["steps"]:  # called after the step's tick: it belongs to the last recorded step
        _rec["true_at"][len(_rec["steps"]) - 1] = d
    return d


def classify(state: int, reason: str, level: int, entry, d_exit, exit_r, escaping: bool, true_d: float,
             protective_m: float, reach_m: float) -> str:
    """The bucket of one non-NORMAL step.

    * ``fault_*``: FAULT (stale/invalid pose, or a person seen but never lifted: ``person_unseen``).
    * ``close``: the true separation is within the protective distance at the slowest speed the
      protection works at (LEVEL1) or within reach (LEVEL2): a stop the truth also calls for.
    * ``wait``: the monitor's own measurement already allows a lower level (its entry level is below
      the level it holds): ``hyst`` while its separation is still within the level's exit radius
      (entry + ``hysteresis_m``), ``dwell`` once beyond it (the ``dwell_s`` before resuming).
    * ``false``: the monitor measures someone within the distance, the truth does not (the margins
      Z_d, a lost person's reachable set, a ray bound, a lift error), by the monitor's reason.
    LEVEL2 is split into retraction and escape by whether the loop's motion is an escape turn.
    """
    if state == State.FAULT:
        return "fault_unseen" if reason.startswith("person_unseen") else "fault_" + reason.split(":")[0]
    why = reason.split(":", 1)[0].split(" (", 1)[0]
    if state == State.LEVEL2:
        kind = "escape" if escaping else "retract"
        if true_d <= reach_m:
            return f"L2_{kind}_close"
        if entry is not None and entry < level:
            return f"L2_{kind}_{_wait(d_exit, exit_r, level)}"
        return f"L2_{kind}_false"
    if true_d <= protective_m:
        return "L1_close"
    if entry is not None and entry < level:
        return f"L1_{_wait(d_exit, exit_r, level)}"
    return f"L1_false_{why}"


def _wait(d_exit, exit_r, level: int) -> str:
    return "dwell" if exit_r is not None and d_exit > exit_r.get(level, float("inf")) else "hyst"


def _run_scenario(sc, link, runtime, perception, world, box):
    _reset()
    res = _orig_run(sc, link, runtime, perception, world, box)
    steps = _rec["steps"]
    n_pre = int(round(world.pre_roll_s / world.dt_s))
    z = box.zones
    v_stop = z.min_speed_fraction * z.iso_robot_speed_mps if z.speed_scaling else z.iso_robot_speed_mps
    protective_m = z.body_protective_distance_m(v_stop)
    buckets: dict = defaultdict(int)
    reasons: dict = defaultdict(int)
    true_d = float("inf")
    productive = 0
    scale_sum = 0.0
    segments: list = []  # run-length: [first judged step, steps, state, reason, bucket]
    for i, (state, reason, level, entry, d_exit, exit_r, escaping, scale) in enumerate(steps):
        true_d = _rec["true_at"].get(i, true_d)
        if i < n_pre:
            continue
        if state == State.NORMAL:
            productive += 1
            scale_sum += scale
            bucket = "normal"
        else:
            bucket = classify(state, reason, level, entry, d_exit, exit_r, escaping, true_d, protective_m, z.reach_retract_m)
            buckets[bucket] += 1
            reasons[f"{State(state).name}:{reason.split(':', 1)[0].split(' (', 1)[0]}"] += 1
        if segments and segments[-1][2:] == [State(state).name, reason, bucket]:
            segments[-1][1] += 1
        else:
            segments.append([i - n_pre, 1, State(state).name, reason, bucket])
    dt = world.dt_s
    s = res.summary
    s["s17"] = {"judged_steps": len(steps) - n_pre, "productive_s": round(productive * dt, 3),
                "mean_speed_scale_normal": round(scale_sum / productive, 4) if productive else None,
                "buckets_s": {k: round(v * dt, 3) for k, v in sorted(buckets.items())},
                "reasons_s": {k: round(v * dt, 3) for k, v in sorted(reasons.items())},
                "protective_m": round(protective_m, 3)}
    _RESULTS.append({"name": s.get("name"), **s["s17"], "summary_productive_s": s.get("productive_s"),
                     "collision": s.get("collision"), "min_separation_m": s.get("min_separation_m"),
                     "scenario_s": s.get("scenario_s"), "segments": segments})
    return res


_RESULTS: list = []


def main(argv: list[str]) -> int:
    out, rest = argv[0], argv[argv.index("--") + 1:]
    hazard.HazardMonitor._update_level = _update_level
    loop.RobotLoop.tick = _tick
    hrc_world._true_separation = _true_separation
    hrc.run_scenario = _run_scenario
    from firmware_sim.__main__ import main as fs_main

    rc = fs_main(["hrc", *rest])
    with gzip.open(out, "wt") as f:
        json.dump(_RESULTS, f, indent=0)
    return rc


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
