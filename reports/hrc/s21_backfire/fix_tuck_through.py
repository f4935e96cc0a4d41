"""Counterfactual: a retraction toward the tuck (not an escape turn) is never given up for a backfire."""
from edge_runtime.robot import loop as loop_mod

_orig = loop_mod.RobotLoop._retract_backfires


def apply(EV, **kw):
    def patched(self):
        if not self._escaping:
            return False
        return _orig(self)
    loop_mod.RobotLoop._retract_backfires = patched
