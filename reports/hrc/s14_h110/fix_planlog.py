"""Not a fix: logs every escape plan (runtime's people vs the true bodies) to see what the turn was planned on."""
import math

import numpy as np

from edge_runtime.robot import hazard
from edge_runtime.robot import loop as loop_mod
from edge_runtime.robot.hazard import body_spheres, point_clearance_m


def apply(EV, J, t_of):
    orig_plan = loop_mod.plan_escape_turn
    orig_escape = loop_mod.RobotLoop._escape
    cur = {}

    def escape(self, decision):
        cur["t"] = t_of(self.clock())
        cur["loop"] = self
        return orig_escape(self, decision)

    def plan(caps, people, j0, step, gain, dip, maxdeg, reach=math.inf):
        turn = orig_plan(caps, people, j0, step, gain, dip, maxdeg, reach)
        t = cur["t"]
        k = int(round(t * 100))
        true_people = [body_spheres(J[w, k]) for w in range(J.shape[0]) if np.isfinite(J[w, k, 0, 0])]
        turn_true = orig_plan(caps, true_people, j0, step, gain, dip, maxdeg, reach)
        here_rt = [round(float((point_clearance_m(c, caps) - r).min()), 3) for c, r in people]
        here_true = [round(float((point_clearance_m(c, caps) - r).min()), 3) for c, r in true_people]
        # the chosen turn's sweep against the TRUE bodies: closest pass per person
        sweep_true = None
        if turn is not None:
            turns = np.linspace(0, turn, 13)[1:]
            sweep_true = [round(min(float((point_clearance_m(c @ hazard._base_rotations([-a])[0].T, caps) - r).min())
                                    for a in turns), 3) for c, r in true_people]
        EV.append({"t": t, "ev": "plan", "turn_deg": None if turn is None else round(math.degrees(turn), 1),
                   "turn_true_deg": None if turn_true is None else round(math.degrees(turn_true), 1),
                   "here_runtime": here_rt, "here_true": here_true, "sweep_true_closest": sweep_true,
                   "j0": None if j0 is None else round(j0, 3)})
        return turn

    loop_mod.plan_escape_turn = plan
    loop_mod.RobotLoop._escape = escape
