"""Counterfactual: no backfire check at all (retractions and escape turns run to their end)."""
from edge_runtime.robot import loop as loop_mod


def apply(EV, **kw):
    loop_mod.RobotLoop._retract_backfires = lambda self: False
