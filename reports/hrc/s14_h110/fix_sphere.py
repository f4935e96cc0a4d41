"""Candidate fix (monkeypatch, no product edit): plan_escape_turn's sweep rule per body part instead of per person.
Shipped: a candidate turn is given up where its sweep passes nearer a PERSON (his nearest sphere) than
min(his separation now, reach_m) - dip_m. A worker already touching the arm with one hand has a separation near
or below zero, so his floor is there, and a sweep that carries another link into another part of him (his elbow)
passes: it never goes below his hand's separation. Here each of his body spheres keeps its own floor:
min(that sphere's clearance now, reach_m) - dip_m. Scoring (end separation, closest pass) is unchanged."""
import math

import numpy as np

from edge_runtime.robot import hazard
from edge_runtime.robot import loop as loop_mod
from edge_runtime.robot.hazard import SAWYER_J0_RANGE_RAD, _base_rotations, point_clearance_m


def plan_escape_turn(capsules, people, j0_rad, step_deg, min_gain_m, dip_m, max_turn_deg, reach_m=math.inf):
    if not people:
        return None
    centres = np.concatenate([c for c, _ in people])
    radii = np.concatenate([r for _, r in people])
    starts = np.cumsum([0] + [len(r) for _, r in people[:-1]])
    step = math.radians(step_deg)

    def per_person(clear):
        return np.minimum.reduceat(clear, starts, axis=-1)

    here_s = point_clearance_m(centres, capsules) - radii          # (S,) per sphere
    here = per_person(here_s)
    floor_s = np.minimum(here_s, reach_m) - dip_m                  # the change: each sphere its own floor
    best = None
    for sign in (1.0, -1.0):
        room = math.radians(max_turn_deg)
        if j0_rad is not None:
            room = min(room, SAWYER_J0_RANGE_RAD - sign * j0_rad)
        n = int(math.floor(room / step + 1e-9))
        if n < 1:
            continue
        turns = sign * step * np.arange(1, n + 1)
        moved = np.einsum("kij,nj->kni", _base_rotations(-turns), centres)
        ds = point_clearance_m(moved.reshape(-1, 3), capsules).reshape(n, -1) - radii[None]   # (n, S)
        d = per_person(ds)
        passed_s = np.minimum.accumulate(ds, axis=0)
        passed = per_person(passed_s)
        end, closest = d.min(axis=1), passed.min(axis=1)
        for k in range(n):
            if (passed_s[k] < floor_s).any():
                break
            if end[k] >= here.min() + min_gain_m and (best is None or (end[k], closest[k]) > best[:2]):
                best = (float(end[k]), float(closest[k]), float(turns[k]))
    return None if best is None else best[2]


def apply(EV, J, t_of):
    # the planlog wrapper (if loaded first) calls whatever loop_mod.plan_escape_turn was; install at both names
    hazard.plan_escape_turn = plan_escape_turn
    loop_mod.plan_escape_turn = plan_escape_turn
