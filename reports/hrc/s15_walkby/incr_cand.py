"""reports/hrc/s14_sts/incremental.py (one scenario at a time, one JSONL line each, same path as `hrc`) with a
candidate from candidates.py applied first.  usage: incr_cand.py CANDIDATE SEED OUT.jsonl [incremental options]
(development seeds only)"""
import runpy
import sys
from pathlib import Path

here = Path(__file__).resolve().parent
sys.path.insert(0, str(here))
import candidates  # noqa: E402

cand = sys.argv[1]
assert int(sys.argv[2]) in (1, 3, 5, 7, 9, 11, 13, 15, 17, 19), "development seeds only"
candidates.apply(cand)
sys.argv = [str(here.parent / "s14_sts" / "incremental.py")] + sys.argv[2:]
runpy.run_path(sys.argv[0], run_name="__main__")
