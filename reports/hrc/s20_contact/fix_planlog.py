"""Logger (no behaviour change): every escape plan's people (now and look-ahead copies), their separations from
the arm now, and the turn it found (None: nothing)."""
from edge_runtime.robot import loop as loop_mod
from edge_runtime.robot.hazard import people_separations_m


def apply(EV, t_of, **_):
    orig = loop_mod.plan_escape_turn
    RL = loop_mod.RobotLoop
    orig_escape = RL._escape

    def escape(self, decision):
        EV.append({"t": t_of(self.clock()), "ev": "escape_called", "d": round(decision.distance_m, 3),
                   "retract": None if self._retract is None else self._retract.kind.value})
        return orig_escape(self, decision)

    def plan(caps, people, *a, **k):
        turn = orig(caps, people, *a, **k)
        EV.append({"t": None, "ev": "plan", "n": len(people), "turn": turn,
                   "here": [round(float(x), 3) for x in people_separations_m(people, caps)]})
        return turn

    loop_mod.plan_escape_turn = plan
    RL._escape = escape
