"""Candidate fix (monkeypatch, no product edit): no escape turn is planned while the nearest person's whole-body
separation (Decision.distance_m: now or predict_s ahead, the monitor's own figure) is below GUARD_M
(default [zones] body_sensing_uncertainty_m, 0.3 m): within the lifted joints' error of the arm no turn can be
shown to clear him, and the arm stays stopped (ISO/TS 15066: standstill when a person reaches it)."""
import os

from edge_runtime.robot import loop as loop_mod


def apply(EV, J, t_of):
    cur = loop_mod.RobotLoop._escape  # whatever is installed now (the trace's logging wrapper)

    def escape(self, decision):
        guard = float(os.environ.get("GUARD_M", self.zones.body_sensing_uncertainty_m))
        if decision.distance_m < guard and self._retract is not None:
            return None
        return cur(self, decision)

    loop_mod.RobotLoop._escape = escape
