"""Candidate changes to the whole-body retraction rule's coming clause (monkeypatches; no product edit).
persistK: a person "keeps coming" only once the shipped clause has held for K consecutive lifted frames of his
(frames within 0.1 s of each other; a frame where he is lifted and the clause is false resets the count); the
reach clause (d <= reach_retract_m), the unlifted / lost / ray bounds and everything else are unchanged.
nowsep: the coming clause's distance test on the separation now instead of min(now, predict_s ahead)."""
import inspect
import textwrap

import numpy as np

from edge_runtime.robot import hazard

SHIPPED = "coming = approach > z.approach_speed_mps and d <= z.body_retract_distance_m + approach * z.retract_lead_s"


def _persist(self, wid, t_s, raw, k):
    n = getattr(self, "_cand_n", None)
    if n is None:
        n = self._cand_n = {}
    cnt, last = n.get(wid, (0, -1e9))
    if raw:
        cnt = cnt + 1 if t_s - last <= 0.1 + 1e-9 else 1
        n[wid] = (cnt, t_s)
        return cnt >= k
    n[wid] = (0, t_s)
    return False


def apply(name):
    src = textwrap.dedent(inspect.getsource(hazard.HazardMonitor._speed_and_separation))
    assert src.count(SHIPPED) == 1
    if name.startswith("persist"):
        k = int(name[len("persist"):])
        new = f"coming = _cand_persist(self, wid, t_s, {SHIPPED.split(' = ', 1)[1]}, {k})"
    elif name == "nowsep":
        old = "d = float(separation_per_shift_m(centres, radii, v3, (0.0, z.predict_s), caps).min())"
        assert src.count(old) == 1
        indent = src.split(old)[0].rsplit("\n", 1)[1]
        src = src.replace(old, "_per = separation_per_shift_m(centres, radii, v3, (0.0, z.predict_s), caps)\n"
                          + indent + "d, _d_now = float(_per.min()), float(_per[0])")
        new = SHIPPED.replace("and d <=", "and _d_now <=")
    else:
        raise SystemExit(f"no candidate {name}")
    src = src.replace(SHIPPED, new)
    ns = dict(vars(hazard))
    ns["_cand_persist"] = _persist
    ns["np"] = np
    exec(compile(src, f"<candidate {name}>", "exec"), ns)
    hazard.HazardMonitor._speed_and_separation = ns["_speed_and_separation"]
