"""What the walk-by tracers (wtrace.py; s16_walkby2/jtrace.py) share: one hard:200 scenario of a development seed
through hrc's own per-scenario path (hrc._run_one, CAN, lifter, 30 Hz, labelled calibration, max 2.0 m/s, shipped
box), its truth (scene_joints), and the run that prints the scenario's summary and writes the trace."""
import argparse
import json
import time
from dataclasses import dataclass

import numpy as np

from firmware_sim.scenarios import hrc
from firmware_sim.scenarios.hrc_world import WorldParams, scene_joints

SUMMARY_KEYS = ("name", "collision", "collision_steps", "first_collision_s", "arm_moved_in_contact", "min_separation_m",
                "stops", "retracts", "halts", "halt_reasons", "came_within_protective", "productive_time_share")


@dataclass
class Setup:
    args: argparse.Namespace
    box: object
    scenario: object
    world: WorldParams
    dt: float
    n_pre: int
    """pose frames' t_s less n_pre * dt is the scenario's time"""
    truth: np.ndarray
    """(W, T, 17, 3) every worker's true joints at the camera's rate"""

    def body(self, wid, t_s: float):
        """Worker ``wid``'s true (17, 3) body at scenario time ``t_s``, or None (not a worker index, not in the scene)."""
        k = int(round(t_s / self.dt))
        J = self.truth
        if not isinstance(wid, (int, np.integer)) or not (0 <= wid < J.shape[0] and 0 <= k < J.shape[1]):
            return None
        return J[wid, k] if np.isfinite(J[wid, k]).all() else None


def setup(flag: str, flag_help: str) -> Setup:
    """SEED NAME OUT.json [flag NAME] from the command line (development seeds only)."""
    ap = argparse.ArgumentParser()
    ap.add_argument("seed", type=int)
    ap.add_argument("name")
    ap.add_argument("out")
    ap.add_argument(flag, default="", help=flag_help)
    a = ap.parse_args()
    assert a.seed in (1, 3, 5, 7, 9, 11, 13, 15, 17, 19), "development seeds only"
    sc = next(s for s in hrc.scenarios_for("hard:200", a.seed, 2.0) if s.name == a.name)
    world = WorldParams(camera_hz=30.0, latency_s=None, labelled_calibration=True)
    return Setup(a, hrc.load_box(None), sc, world, world.dt_s, int(round(world.pre_roll_s / world.dt_s)),
                 scene_joints(sc, round(1.0 / world.dt_s)))


def run(su: Setup, out_extra: dict, frames: list) -> None:
    """Run the scenario, print its summary (one JSON line and the wall time) and write the trace."""
    t0 = time.time()
    r = hrc._run_one((su.scenario, "can", True, hrc.resolve_perception("lifter"), su.world, su.box))
    s = r.summary
    print(json.dumps({k: s[k] for k in SUMMARY_KEYS}), f"wall {time.time() - t0:.1f}s", flush=True)
    with open(su.args.out, "w") as f:
        json.dump({"summary": s, **out_extra, "frames": frames}, f, default=float)
