"""reports/hrc/s14_sts/incremental.py (one hard:200 scenario at a time, one JSONL line each, hrc's own path) with
candidates applied first: CAND is "+"-free names joined by ",": a candidates2.py name (headlcb2, medlcb2, ...) or
"ray:" + a raycand.py variant (ray:bands+ext1.1).  usage: incr_cand2.py CAND SEED OUT.jsonl [incremental options]
(development seeds only)"""
import runpy
import sys
from pathlib import Path

here = Path(__file__).resolve().parent
sys.path.insert(0, str(here))
import candidates2  # noqa: E402

assert int(sys.argv[2]) in (1, 3, 5, 7, 9, 11, 13, 15, 17, 19), "development seeds only"
candidates2.apply_all(sys.argv[1])
sys.argv = [str(here.parent / "s14_sts" / "incremental.py")] + sys.argv[2:]
runpy.run_path(sys.argv[0], run_name="__main__")
