"""Capture the arguments of the hazard functions during the bench scenario (simulated clock) -> pickle."""
import pickle
import sys
from pathlib import Path

sys.path.insert(0, str(Path.cwd()))
import bench.robot_cycle as rc
import edge_runtime.robot.hazard as hz
import edge_runtime.robot.loop as loopmod

CAP = {"plan_escape_turn": [], "separation_per_shift_m": [], "point_clearance_m": [], "body_spheres": [],
       "arm_points_m": []}
def wrap(mod, name, key, limit=4000):
    fn = getattr(mod, name)
    def w(*a, **k):
        r = fn(*a, **k)
        if len(CAP[key]) < limit:
            CAP[key].append((a, k, r))
        return r
    setattr(mod, name, w)
wrap(loopmod, "plan_escape_turn", "plan_escape_turn")
wrap(hz, "separation_per_shift_m", "separation_per_shift_m")
wrap(hz, "point_clearance_m", "point_clearance_m")
wrap(hz, "body_spheres", "body_spheres")
wrap(hz, "arm_points_m", "arm_points_m")
from edge_runtime.core.manifest import ASSETS_DIR, load_manifest

lifter = rc.lifter_entry(load_manifest(ASSETS_DIR)["models"])
cfg = rc.RobotConfig("/work/notes/perf/workers.npz", float(sys.argv[1]), "", lifter["precision"], rc._arm_posture(), simulated=True)
run = rc.run_cycle(cfg)
pickle.dump(CAP, open(sys.argv[2], "wb"))
print({k: len(v) for k, v in CAP.items()})
