"""Candidate changes to the whole-body rule's "keeps coming" clause (issue 13, walk-by halts), as monkeypatches
of HazardMonitor._speed_and_separation (no product edit; s15_walkby/candidates.py's method). Only the coming
clause's velocity changes: its approach and the separation it predicts ``predict_s`` ahead with it; the reach
clause (d <= reach_retract_m, d predicted with the head tracker's velocity), the ray / lost bounds and everything
else stay as shipped. Velocities are least-squares fits over the head tracker's own window (its resets included).
  headlcbK  the head's approach less K standard errors of its own fit (residual-based): a lower confidence bound
  medlcbK   the median over JOINTS of their fitted ground velocities; its approach less K times the joints' median
            standard error
  medK0     the median velocity as it is (no bound)
A fit with fewer than the tracker's min_samples gives no approach (the shipped tracker's zero velocity).
apply_all("a,b,ray:c") applies several, "ray:" ones from raycand.py."""
import inspect
import re
import textwrap

import numpy as np

from edge_runtime.robot import hazard
from edge_runtime.robot.hazard import ground, separation_per_shift_m

SHIPPED = "coming = approach > z.approach_speed_mps and d <= z.body_retract_distance_m + approach * z.retract_lead_s"
JOINTS = (0, 1, 4, 3, 6, 10, 11, 14)
"""pelvis, both hips, both ankles, head, both shoulders (H36M)"""


def _fit(ts, xs):
    """Least-squares slope of xs (n, ..., 2) on ts and each slope component's standard error (residual-based)."""
    t = ts - ts.mean()
    tt = float(t @ t)
    xm = xs.mean(axis=0)
    v = np.tensordot(t, xs - xm, axes=1) / tt
    res = xs - xm - t.reshape((-1,) + (1,) * (xs.ndim - 1)) * v
    s2 = (res ** 2).sum(axis=0) / max(len(ts) - 2, 1)
    return v, np.sqrt(s2 / tt)


def _coming(self, kind, k, wid, t_s, person_m, est, eff_g, caps, centres, radii):
    z = self.zones
    trk = self._trackers[wid]
    hist = self.__dict__.setdefault("_c2_hist", {}).setdefault(wid, [])
    hist.append((t_s, ground(person_m[list(JOINTS)])))
    hist[:] = [h for h in hist if h[0] >= trk._t[0] - 1e-9]  # the tracker's window, since its last reset
    if len(trk._t) < self.tracker.min_samples or len(hist) < self.tracker.min_samples:
        return False
    toward = eff_g - ground(est.position_m)
    u = toward / max(float(np.linalg.norm(toward)), 1e-9)
    ts = np.array([h[0] for h in hist])
    if kind == "head":
        v, se = _fit(np.fromiter(trk._t, float), ground(np.stack(trk._x)))
        v_g = ground(est.velocity_mps)  # the tracker's (clipped) velocity; its fit's standard error
    else:
        vj, sej = _fit(ts, np.stack([h[1] for h in hist]))  # (J, 2)
        v_g = np.median(vj, axis=0)
        sp = float(np.linalg.norm(v_g))
        if sp > self.tracker.max_speed_mps:
            v_g = v_g * (self.tracker.max_speed_mps / sp)
        se = np.median(np.sqrt((sej ** 2) @ (u ** 2)))
        se = np.array([se, 0.0])  # already along u
        u_se = np.array([1.0, 0.0])
    approach = float(v_g @ u)
    se_a = float(np.sqrt((se ** 2) @ (u ** 2))) if kind == "head" else float(se @ u_se)
    lcb = approach - k * se_a
    v3 = np.array([v_g[0], 0.0, v_g[1]])
    d = float(separation_per_shift_m(centres, radii, v3, (0.0, z.predict_s), caps).min())
    return lcb > z.approach_speed_mps and d <= z.body_retract_distance_m + lcb * z.retract_lead_s


def apply(name):
    m = re.fullmatch(r"(head|med)(lcb)?(\d+(?:\.\d+)?)", name)
    if not m:
        raise SystemExit(f"no candidate {name}")
    kind, k = m.group(1), float(m.group(3))
    src = textwrap.dedent(inspect.getsource(hazard.HazardMonitor._speed_and_separation))
    assert src.count(SHIPPED) == 1
    src = src.replace(SHIPPED, f"coming = _c2_coming(self, {kind!r}, {k}, wid, t_s, person_m, est, eff_g, caps, "
                               "centres, radii)")
    ns = dict(vars(hazard))
    ns["_c2_coming"] = _coming
    exec(compile(src, f"<candidate {name}>", "exec"), ns)
    hazard.HazardMonitor._speed_and_separation = ns["_speed_and_separation"]


def apply_all(spec: str) -> None:
    """Apply each of the ","-separated candidates: a name of this module or "ray:" + a raycand.py variant."""
    import raycand
    for cand in spec.split(","):
        if cand.startswith("ray:"):
            raycand.apply(cand[4:])
        else:
            apply(cand)
