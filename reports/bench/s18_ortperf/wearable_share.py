"""The wearable loop's CPU share at 100 Hz in real time, measured by bench's own function (bench.loops._realtime on
bench.loops._Wearable, the shipped int8 model), with the other core busy (bench.machine.LoadGenerator), on a
development drive (seed 1 or 5).

    PYTHONPATH=. python reports/bench/s18_ortperf/wearable_share.py --seed 1 --seconds 15 --runs 2 --out X.json
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from pathlib import Path

from edge_runtime.wearable import limit_blas_threads

limit_blas_threads()  # as bench.worker does for its wearable task, before numpy is imported

from bench.loops import WearableConfig, _realtime, _Wearable, prepare_drive  # noqa: E402
from bench.machine import LoadGenerator, pin_cpus  # noqa: E402


def main(argv=None) -> int:
    import numpy as np

    p = argparse.ArgumentParser()
    p.add_argument("--seed", type=int, default=1, choices=(1, 5))
    p.add_argument("--minutes", type=float, default=3.0)
    p.add_argument("--seconds", type=float, default=15.0)
    p.add_argument("--runs", type=int, default=2)
    p.add_argument("--out", required=True)
    a = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as td:
        npy, start = prepare_drive(a.minutes, a.seed, Path(td) / "drive.npy")
        acc = np.load(npy).astype(np.float32)
    busy = LoadGenerator([1])
    pin_cpus([0])
    rows = []
    with busy:
        for _ in range(a.runs):
            w = _Wearable(WearableConfig(drive_npy="", start_index=start, realtime_s=a.seconds))
            try:
                t0 = time.strftime("%H:%M:%S", time.gmtime())
                r = _realtime(w, acc, start, a.seconds)
                rows.append({"utc_start": t0, **{k: r[k] for k in ("cpu_share_pct", "p50_us", "p99_us", "captures",
                                                                  "deadline_misses", "seconds")}})
                print(rows[-1], file=sys.stderr)
            finally:
                w.pub.close()
    Path(a.out).write_text(json.dumps({"seed": a.seed, "rows": rows}, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
