"""In-process timing of RobotLoop._retract_backfires against session 17's form (copied below), on a memo hit (the arm
still) and a miss (the arm moving). Run from the tree: python ab_backfire.py"""
import math
import sys
import time

sys.path.insert(0, ".")
sys.path.insert(0, "tests")
import numpy as np
from support.robot import FakeLink, anchored_worker

from edge_runtime.core.memo import Recent
from edge_runtime.robot import hazard as hz
from edge_runtime.robot.hazard import ZoneParams
from edge_runtime.robot.loop import MotionKind, RobotLoop


def old_bf(self):
    r, q0, q = self._retract, self._retract_q0, self._last_q
    z = self.zones
    if r is None or r.kind is not MotionKind.RETRACT or q0 is None or q is None or z.separation != "whole_body":
        return False
    reach = z.body_retract_distance_m + z.retract_lead_s * z.lost_person_speed_mps
    now_caps, start_caps = hz.arm_capsules(q), hz.arm_capsules(q0)
    for spheres in self.monitor.people_spheres():
        now = old_sep(self, spheres, now_caps)
        if now < reach and now < old_sep(self, spheres, start_caps) - self.params.retract_backfire_m:
            return True
    return False
MEMO = Recent(32)
def old_sep(self, spheres, caps):
    key = (id(spheres), id(caps))
    hit = MEMO.get(key)
    if hit is None or hit[0] is not spheres or hit[1] is not caps:
        hit = MEMO.put(key, (spheres, caps, hz.separation_m(*spheres, caps)))
    return hit[2]

loop = RobotLoop(FakeLink(), zones=ZoneParams())
q = np.array([0.3, -0.5, 0.2, 1.2, 0.1, 0.4, 0.0])
people = {1: anchored_worker((0.9, 1.2), heading=math.pi), 2: anchored_worker((-1.5, 1.8), heading=1.2)}
loop.monitor.observe(0.0, people, np.array([0.4, 0.14, 0.6]), q)
loop._retract = loop._radial_retract()
loop._retract_q0 = q + 0.05
loop._last_q = q.copy()
for f in (old_bf, RobotLoop._retract_backfires):
    assert f(loop) == old_bf(loop)
# memo-hit path (the arm still): the same q every call
res = {"old": [], "new": []}
for _ in range(30):
    for name, f in (("old", old_bf), ("new", RobotLoop._retract_backfires)):
        t0 = time.thread_time()
        for _ in range(2000):
            f(loop)
        res[name].append((time.thread_time() - t0) / 2000 * 1e6)
print("hit:", {k: (round(min(v), 2), round(float(np.median(v)), 2)) for k, v in res.items()})
# miss path: a new q every call (the arm moving), start remembered
qs = [q + 1e-4 * k for k in range(400)]
res = {"old": [], "new": []}
for _ in range(15):
    for name, f in (("old", old_bf), ("new", RobotLoop._retract_backfires)):
        t0 = time.thread_time()
        for qq in qs:
            loop._last_q = qq
            f(loop)
        res[name].append((time.thread_time() - t0) / len(qs) * 1e6)
print("miss:", {k: (round(min(v), 2), round(float(np.median(v)), 2)) for k, v in res.items()})
