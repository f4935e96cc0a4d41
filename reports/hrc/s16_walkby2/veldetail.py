"""Per-frame detail of velstudy.py's estimators for one trace and person between two times.
usage: veldetail.py OUT.json WID T0 T1"""
import sys

from velstudy import study

X, rows = study(sys.argv[1])
for r in rows:
    if r["w"] == sys.argv[2] and float(sys.argv[3]) <= r["t"] <= float(sys.argv[4]):
        print(f"t {r['t']:.2f} {r['state'][:6]} d {r['d']:.2f} dnow {r['d_now']:.2f} a_head {r['a_head']:.2f} "
              f"se_h {r.get('se_head', 0):.2f} a_med {r.get('a_med', 0):.2f} se_m {r.get('se_med', 0):.2f} "
              f"d_med {r.get('d_med', 0):.2f} | a_true {r.get('a_true', float('nan')):.2f} d_true {r.get('d_true', float('nan')):.2f} "
              f"| ship {int(r['ship'])} med {int(r['med'])} medlcb {int(r['medlcb'])} headlcb {int(r['headlcb'])} "
              f"true {int(bool(r.get('true')))} reach {int(r['reach'])}")
