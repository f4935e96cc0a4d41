"""Candidate fix (monkeypatch, no product edit): no escape turn is planned while anyone has been within GUARD_M
(default [zones] body_sensing_uncertainty_m, 0.3 m; the monitor's Decision.distance_m, now or predict_s ahead)
of the arm at any decision in the last HOLD_S (default [robot_loop] escape_replan_s, 0.5 s): one lifted frame
putting him further off (0.15-0.4 m lift error on a reaching worker here) does not license a sweep past him."""
import math
import os

from edge_runtime.robot import loop as loop_mod


def apply(EV, J, t_of):
    cur = loop_mod.RobotLoop._escape

    def escape(self, decision):
        guard = float(os.environ.get("GUARD_M", self.zones.body_sensing_uncertainty_m))
        hold = float(os.environ.get("HOLD_S", self.params.escape_replan_s))
        now = self.clock()
        if decision.distance_m < guard:
            self._close_s = now
        if now - getattr(self, "_close_s", -math.inf) < hold and self._retract is not None:
            return None
        return cur(self, decision)

    loop_mod.RobotLoop._escape = escape
