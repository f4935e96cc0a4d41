"""Counterfactual: a backfiring retraction is still replaced once by the radial one, but that one is never stopped."""
from edge_runtime.robot import loop as loop_mod

_orig = loop_mod.RobotLoop._retract_backfires


def apply(EV, **kw):
    def patched(self):
        if not self._escaping and self._retract_fallback:
            return False
        return _orig(self)
    loop_mod.RobotLoop._retract_backfires = patched
