"""Paired timing of two int8 lifters at the batch sizes the product runs (one call per frame for everyone seen:
1, 2 or 3 people), through edge_runtime.core.onnx.fast_run as edge_runtime.robot.lifter calls it, on realistic
windows (the export's validation split), one thread pinned to CPU 0 with the other core busy
(bench.machine.LoadGenerator, as bench's --busy-cpus 1). ort_ab.py (reports/bench/s18_ortperf) times batch 1 with
bench's feed; this adds batches 2 and 3.

    PYTHONPATH=. python reports/lifter/s19_fold/batch_timing.py --a edge_runtime/assets/lifter.int8.onnx \
        --b /tmp/fold/folded/lifter.int8.onnx --split /tmp/fold/work/val.npz --repeats 9 \
        --out reports/lifter/s19_fold/results/batch_timing.json

Each repeat times A and B interleaved (bench.timing.interleaved_calls, 5 rounds), the order swapped every other
repeat; reported per batch size: each model's median p50 over repeats and the median of the per-repeat ratio B/A.
"""
from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from bench.machine import LoadGenerator, pin_cpus
from bench.timing import interleaved_calls
from edge_runtime.core.onnx import fast_run, open_session
from models.lifter_train import eval_frames
from models.pose_data import PoseSet

OUTPUTS = ["pose_3d", "root_3d"]


def main(argv=None) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--a", required=True)
    p.add_argument("--b", required=True)
    p.add_argument("--split", required=True)
    p.add_argument("--batches", default="1,2,3")
    p.add_argument("--repeats", type=int, default=9)
    p.add_argument("--n", type=int, default=2000)
    p.add_argument("--out", required=True)
    a = p.parse_args(argv)
    ps = PoseSet.load(a.split)
    windows = ps.windows(eval_frames(ps, 3000)).astype(np.float32)
    calls = {}
    for b in map(int, a.batches.split(",")):
        feed = {"keypoints_2d": np.ascontiguousarray(windows[1000:1000 + b])}  # people of one scene and time
        for key, path in (("a", a.a), ("b", a.b)):
            sess = open_session(path, 1)
            run = fast_run(sess, OUTPUTS, feed, None)
            calls[(b, key)] = lambda run=run, feed=feed: run(OUTPUTS, feed, None)
    busy = LoadGenerator([1])  # made before pinning, as bench does
    pin_cpus([0])
    p50 = {k: [] for k in calls}
    t0 = time.strftime("%H:%M:%S", time.gmtime())
    with busy:
        time.sleep(0.5)
        for r in range(a.repeats):
            for b in sorted({k[0] for k in calls}):
                order = ("a", "b") if r % 2 == 0 else ("b", "a")
                times = interleaved_calls({k: calls[(b, k)] for k in order}, a.n, rounds=5, warmup=200)
                for k in order:
                    p50[(b, k)].append(float(np.median(times[k])) / 1e3)
    t1 = time.strftime("%H:%M:%S", time.gmtime())
    rows = {}
    for b in sorted({k[0] for k in calls}):
        ra, rb = np.array(p50[(b, "a")]), np.array(p50[(b, "b")])
        rows[str(b)] = {"a_p50_us_median": round(float(np.median(ra)), 2), "b_p50_us_median": round(float(np.median(rb)), 2),
                        "ratio_b_to_a_median": round(float(np.median(rb / ra)), 4),
                        "ratio_min_max": [round(float((rb / ra).min()), 4), round(float((rb / ra).max()), 4)]}
        print(f"batch {b}: A {rows[str(b)]['a_p50_us_median']:.1f} us, B {rows[str(b)]['b_p50_us_median']:.1f} us, "
              f"B/A {rows[str(b)]['ratio_b_to_a_median']:.3f} {rows[str(b)]['ratio_min_max']}")
    out = {"utc": f"{time.strftime('%Y-%m-%d', time.gmtime())} {t0}-{t1}", "argv": sys.argv[1:], "rows": rows,
           "loadavg": os.getloadavg()}
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(out, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
