"""Candidate tighter ray bounds for people in view but not lifted (issue 13), as variants of
hazard.ray_separation_m built from its own source (no product edit):
  extX      ray_body_extent_m = X (shipped 1.3): every joint within X (ground) of the foot / hips / head anchor
  bands     each seen joint that is not an anchor is also near its ray only where the ray is within that joint's
            own height band (JOINT_BANDS_M, widened by e like the anchors'): a standing or bending 1.45-2.0 m
            person's knees, trunk, shoulders and neck; elbows and wrists keep the whole 0-2.6 m
  eX        RAY_KEYPOINT_ERROR_M = X (shipped 0.25): how far a keypoint's ray may pass from its joint (not a physical
            premise: the detector's error; measured only to show what a useful bound would need)
  hold      (offline: every unlifted person with rays; in a run: the never-lifted ones, HazardMonitor._unlifted) a
            bound carried over time: the larger of this frame's bound and the
            last one less (lost_person_speed_mps + iso_robot_speed_mps) x the time since (the person and the arm
            cannot close faster), while he stays unlifted in view; a true bound if each frame's is
  any of these joined by "+"
apply(name) installs one in hazard (for closed-loop runs); variant(name) returns the function (offline).
Offline (main): per jtrace.py trace, frames with a ray bound and a truth: bound > truth (a violation: not a bound),
the worst violation, and frames with the bound <= reach_retract_m while the truth is > 1.3 m ("low", and the
episodes they make per person, runs more than 1 s apart: about a halt each); shipped and each
variant.  usage: raycand.py VARIANT,... OUT.json ..."""
import inspect
import json
import sys
import textwrap

import numpy as np

from edge_runtime.robot import hazard

JOINT_BANDS_M = {2: (0.2, 0.9), 5: (0.2, 0.9),                 # knees: standing 0.28 x height, raised running
                 7: (0.6, 1.5), 8: (0.8, 1.8), 9: (0.9, 2.0),  # spine, thorax, neck/nose: bending down to the head's 1.2
                 11: (0.8, 1.8), 14: (0.8, 1.8)}               # shoulders
"""Height above the floor (m) of joints a 1.45-2.0 m tall person shows, standing, walking or bending toward the work
(the shipped head band's 1.2 m low end): the simulator's bodies span knees 0.39-0.58, spine 0.94-1.28, thorax
1.06-1.59, neck 1.12-1.78, shoulders 1.04-1.60 (truthstats.py on the session's traces)."""
OLD = """        if j in ranges:
            lo, hi = max(lo, ranges[j][0]), min(hi, ranges[j][1])
"""
NEW = """        if j in ranges:
            lo, hi = max(lo, ranges[j][0]), min(hi, ranges[j][1])
        elif _BANDS and int(j) in _BANDS:
            r = ray_range(int(j), _BANDS[int(j)])
            if r is not None and max(lo, r[0]) <= min(hi, r[1]):  # a band the ray misses narrows nothing
                lo, hi = max(lo, r[0]), min(hi, r[1])
"""
_SHIPPED = hazard.ray_separation_m


def variant(name):
    bands = "bands" in name
    ext = next((float(p[3:]) for p in name.split("+") if p.startswith("ext")), None)
    src = textwrap.dedent(inspect.getsource(_SHIPPED))
    assert src.count(OLD) == 1
    src = src.replace(OLD, NEW)
    ns = dict(vars(hazard))
    ns["_BANDS"] = JOINT_BANDS_M if bands else {}
    e = next((float(p[1:]) for p in name.split("+") if p.startswith("e") and not p.startswith("ext")), None)
    if e is not None:
        ns["RAY_KEYPOINT_ERROR_M"] = e
    exec(compile(src, f"<ray candidate {name}>", "exec"), ns)
    fn = ns["ray_separation_m"]
    if ext is None:
        return fn

    def with_extent(rays, capsules, zones):
        import dataclasses
        return fn(rays, capsules, dataclasses.replace(zones, ray_body_extent_m=ext))
    return with_extent


def explained():
    """hazard.ray_separation_m returning its locals as a third value (which region and term binds)."""
    src = textwrap.dedent(inspect.getsource(_SHIPPED)).replace("    return d, stands", "    return d, stands, locals()")
    ns = dict(vars(hazard))
    exec(compile(src, "<ray_separation_m explained>", "exec"), ns)
    return ns["ray_separation_m"]


def _held_unlifted(orig):
    """HazardMonitor._unlifted with each never-lifted person's ray bound carried over time ("hold"): the larger of
    this frame's bound and his last one less the closing speed times the time since, while he stays in view and
    unlifted (forgotten after lost_hold_s). Lifted-before people (_lost) are not changed."""
    def _unlifted(self, t_s, unseen, bounds, lifted_now):
        z = self.zones
        closing = z.lost_person_speed_mps + z.iso_robot_speed_mps
        held = self.__dict__.setdefault("_rc_held", {})
        for wid in [w for w in held if w not in unseen or w in self._seen or t_s - held[w][0] > z.lost_hold_s]:
            del held[wid]
        for wid, b in list(bounds.items()):
            if b is None or wid in self._seen:
                continue
            if wid in held:
                b = (max(b[0], held[wid][1] - closing * (t_s - held[wid][0])), b[1])
                bounds[wid] = b
            held[wid] = (t_s, b[0])
        return orig(self, t_s, unseen, bounds, lifted_now)
    return _unlifted


def apply(name):
    base = name.replace("+hold", "").replace("hold", "")
    if base:
        hazard.ray_separation_m = variant(base)
    if "hold" in name:
        hazard.HazardMonitor._unlifted = _held_unlifted(hazard.HazardMonitor._unlifted)


if __name__ == "__main__":
    names = ["shipped"] + sys.argv[1].split(",")
    base = {n: n.replace("+hold", "").replace("hold", "") for n in names}
    fns = {n: _SHIPPED if base[n] in ("shipped", "") else variant(base[n]) for n in names}
    Z = hazard.ZoneParams()
    closing = Z.lost_person_speed_mps + Z.iso_robot_speed_mps
    tot = {n: [0, 0, 0.0, 0, 0] for n in names}  # frames, violations, worst, low, low episodes
    for path in sys.argv[2:]:
        X = json.load(open(path))
        row = {n: [0, 0, 0.0, 0, 0] for n in names}
        held = {n: {} for n in names}  # wid -> (t, bound)
        last_low = {n: {} for n in names}  # wid -> t of the last low frame (episodes: > 1 s apart)
        for f in X["frames"]:
            for n in names:
                for w in [w for w in held[n] if w not in f["unlifted"] or f["t"] - held[n][w][0] > Z.lost_hold_s]:
                    del held[n][w]
            caps = tuple(np.array(c) for c in f["caps"])
            for w, u in f["unlifted"].items():
                if "dirs" not in u or "true_d_now" not in u:
                    continue
                rays = hazard.PersonRays(np.array(u["origin"]), np.array(u["dirs"], float), u["floor_y"])
                tr = u["true_d_now"]
                for n, fn in fns.items():
                    b = fn(rays, caps, Z)
                    if b is None:
                        continue
                    if "hold" in n:
                        if w in held[n]:
                            t0, b0 = held[n][w]
                            b = (max(b[0], b0 - closing * (f["t"] - t0)),)
                        held[n][w] = (f["t"], b[0])
                    r = row[n]
                    r[0] += 1
                    if b[0] > tr + 1e-6:
                        r[1] += 1
                        r[2] = max(r[2], b[0] - tr)
                    if b[0] <= Z.reach_retract_m and tr > 1.3:
                        r[3] += 1
                        if f["t"] - last_low[n].get(w, -9.0) > 1.0:
                            r[4] += 1
                        last_low[n][w] = f["t"]
        for n in names:
            tot[n] = [tot[n][0] + row[n][0], tot[n][1] + row[n][1], max(tot[n][2], row[n][2]), tot[n][3] + row[n][3],
                      tot[n][4] + row[n][4]]
        print(path.split("/")[-1], " | ".join(f"{n}: {r[0]} fr, viol {r[1]} (worst {r[2]:.3f}), low {r[3]} in {r[4]}"
                                              for n, r in row.items()))
    print("TOTAL", " | ".join(f"{n}: {r[0]} fr, viol {r[1]} (worst {r[2]:.3f}), low {r[3]} in {r[4]}"
                              for n, r in tot.items()))
