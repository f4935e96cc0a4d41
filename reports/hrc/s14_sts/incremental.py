"""Run hard:200 scenarios of one seed one at a time, in a chosen order, appending each scenario's summary
to a JSONL file as it finishes (so a run cut short by the stop time still counts what it ran).
Same per-scenario path as `python -m firmware_sim hrc` (hrc._run_one with the CLI's defaults:
CAN, lifter perception, 30 Hz, labelled calibration, max speed 2.0).
usage: incremental.py SEED OUT.jsonl [--config BOX.toml] [--first a,b,c] [--only-first]"""
import argparse
import json
import time

from firmware_sim.scenarios import hrc
from firmware_sim.scenarios.hrc_world import WorldParams

ap = argparse.ArgumentParser()
ap.add_argument("seed", type=int)
ap.add_argument("out")
ap.add_argument("--config", default=None)
ap.add_argument("--first", default="")
ap.add_argument("--only-first", action="store_true")
ap.add_argument("--skip-first", action="store_true", help="run every scenario except --first")
ap.add_argument("--link", default="can")
a = ap.parse_args()
box = hrc.load_box(a.config)
scs = hrc.scenarios_for("hard:200", a.seed, 2.0)
first = [n for n in a.first.split(",") if n]
order = [] if a.skip_first else [s for n in first for s in scs if s.name == n]
if not a.only_first:
    order += [s for s in scs if s.name not in first]
world = WorldParams(camera_hz=30.0, latency_s=None, labelled_calibration=True)
percept = hrc.resolve_perception("lifter")
for sc in order:
    t0 = time.time()
    r = hrc._run_one((sc, a.link, True, percept, world, box))
    d = dict(r.summary, wall_s=round(time.time() - t0, 1), config=a.config, seed=a.seed,
             safety_sha256=hrc.safety_sha256(box), arm_moving=hrc.arm_was_moving(r.summary) if r.summary.get("collision") else None)
    with open(a.out, "a") as f:
        f.write(json.dumps(d, default=float) + "\n")
