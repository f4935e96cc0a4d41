"""What the bench's robot scenario leaves for the garbage collector: prof_cycle.py's run with gc.DEBUG_SAVEALL,
then the types of every object a collection found unreachable (reference cycles), and which closures made them.

    cd TREE && PYTHONPATH=. /work/main/.venv/bin/python reports/bench/s17_perf7/garbage.py --seconds 60 --out X.json

On main 3284fbf: 25,380 objects, 1,800 of them ``_assign.<locals>.best`` closures (one per frame) with their
cells, tuples, lists and dicts; on branch perf7 only start-up leftovers (literal_eval's, argparse's).
"""
from __future__ import annotations

import collections
import gc
import sys
from pathlib import Path

sys.path.insert(0, str(Path.cwd()))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "s15_perf"))

import prof_cycle as pc  # noqa: E402

if __name__ == "__main__":
    gc.set_debug(gc.DEBUG_SAVEALL)
    pc.main()
    gc.collect()
    kinds = collections.Counter(type(o).__name__ for o in gc.garbage)
    print(f"unreachable objects: {len(gc.garbage)}", kinds.most_common(20))
    closures = collections.Counter(f.__qualname__ for f in gc.garbage if type(f).__name__ == "function")
    print("functions among them:", closures.most_common(10))
