"""Where a halted arm's time goes: every pose frame the monitor spends at LEVEL2 (retract) or LEVEL1 (stop),
classified by what holds it there. Hooks HazardMonitor._update_level (no product edit) and runs hrc's suite.
usage: where.py SUITE SEED OUT.json [--protection speed_scaled|stop_only] [--config BOX.toml] [--only NAME]
A frame at level L is one of: 'entry' (this frame's evidence asks for L or more: within reach, coming, a lost
or unlifted person's bound), 'band' (asks for less, but the separation is within L's exit radius: hysteresis),
'dwell' (beyond the exit radius, waiting out dwell_s). Frames in FAULT are counted apart."""
import argparse
import collections
import json
from dataclasses import replace

from edge_runtime.robot import hazard
from edge_runtime.robot.hazard import State
from firmware_sim.scenarios import hrc

ap = argparse.ArgumentParser()
ap.add_argument("suite")
ap.add_argument("seed", type=int)
ap.add_argument("out")
ap.add_argument("--protection", default=None)
ap.add_argument("--config", default=None)
ap.add_argument("--only", default=None)
a = ap.parse_args()

COUNT = collections.Counter()
ENTRY_WHY = collections.Counter()
orig_update = hazard.HazardMonitor._update_level
orig_ss = hazard.HazardMonitor._speed_and_separation


def speed_and_separation(self, *args, **kw):
    r = orig_ss(self, *args, **kw)
    self._s25_coming = self._coming
    return r


def update_level(self, t_s, entry, d, est, exit_r):
    before = self.level
    orig_update(self, t_s, entry, d, est, exit_r)
    lvl = self.level
    if lvl == State.NORMAL:
        COUNT["NORMAL"] += 1
        return
    if entry >= lvl:
        why = "entry"
        if lvl == State.LEVEL2:
            z = self.zones
            ENTRY_WHY["coming" if getattr(self, "_s25_coming", False) and d > z.reach_retract_m else
                      "within_reach" if d <= z.reach_retract_m else "lost_or_bound"] += 1
    elif d <= exit_r[lvl]:
        why = "band"
    else:
        why = "dwell"
    COUNT[f"{lvl.name}:{why}"] += 1
    if before < lvl:
        COUNT[f"{lvl.name}:entered"] += 1


hazard.HazardMonitor._update_level = update_level
hazard.HazardMonitor._speed_and_separation = speed_and_separation
box = hrc.load_box(a.config)
if a.protection:
    box = replace(box, zones=replace(box.zones, **hrc.PROTECTIONS[a.protection]))
res = hrc.run(scenario=a.suite, link="can", seed=a.seed, perception="lifter", max_speed_mps=2.0, box=box,
              only=a.only, jobs=1)
frames = sum(v for k, v in COUNT.items() if not k.endswith(":entered"))
out = {"suite": a.suite, "seed": a.seed, "protection": res.get("protection"), "collisions": res["collisions"],
       "min_separation_m": res["min_separation_m"], "productive_time_share": res["productive_time_share"],
       "state_share": res.get("state_share"), "frames": frames,
       "frame_share": {k: round(v / frames, 4) for k, v in sorted(COUNT.items()) if not k.endswith(":entered")},
       "entered": {k: v for k, v in COUNT.items() if k.endswith(":entered")},
       "level2_entry_frames_by_cause": dict(ENTRY_WHY)}
json.dump(out, open(a.out, "w"), indent=1)
print(json.dumps(out, indent=1))
