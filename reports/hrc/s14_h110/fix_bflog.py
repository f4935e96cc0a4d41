"""Not a fix: logs, at each backfire, who the arm's own motion brought nearer (the runtime's bodies, per person id:
separation now against the arm now and against the arm where the retraction began)."""
from edge_runtime.robot import loop as loop_mod
from edge_runtime.robot.hazard import arm_capsules, body_spheres, separation_m


def apply(EV, J, t_of):
    cur = loop_mod.RobotLoop._retract_backfires

    def backfires(self):
        r = cur(self)
        if r:
            now_caps, start_caps = arm_capsules(self._last_q), arm_capsules(self._retract_q0)
            EV.append({"t": t_of(self.clock()), "ev": "backfire_who", "per": {
                wid: (round(separation_m(*body_spheres(s.person_m), now_caps), 3),
                      round(separation_m(*body_spheres(s.person_m), start_caps), 3))
                for wid, s in self.monitor._seen.items()}})
        return r

    loop_mod.RobotLoop._retract_backfires = backfires
