"""Session 22 (issue 12): rough per-decision cost of the streaming decider (NOT ``python -m bench``; the lead benches
on a quiet machine). One thread, the shipped stream models, the runtime's own classes:

    PYTHONPATH=. OMP_NUM_THREADS=1 nice -n 10 python reports/wearable/stream_s22/cost.py OUT.json

* model: ``StreamModel.classify_window`` at batch 1 (the copy into the input buffer and the onnxruntime run), p50 /
  p90 over 3000 calls, fp32 and int8, interleaved;
* samples: ``StreamLoop.feed`` of a live source's blocks (5 samples every 50 ms) with a classifier that costs
  nothing, per sample: the running sums, the ring and the hop bookkeeping without the model.
"""
from __future__ import annotations

import json
import os
import sys
import time

import numpy as np

from edge_runtime.core.manifest import ASSETS_DIR
from edge_runtime.wearable.sources import ImuBlock
from edge_runtime.wearable.stream_decider import StreamLoop, StreamModel, StreamParams


class Free:
    classes = ("Phone", "Texting", "TouchScreen", "Drink", "Marker", "Other")
    answer = np.float32([0.01, 0.01, 0.01, 0.01, 0.01, 0.95])

    def classify_window(self, window):
        return self.answer


def main(out: str) -> int:
    rng = np.random.default_rng(0)
    windows = (rng.normal(0, 2, (64, 100, 3)) + [0, 0, 9.81]).astype(np.float32)
    models = {p: StreamModel.from_manifest(ASSETS_DIR, f"stream-{p}") for p in ("fp32", "int8")}
    times = {p: [] for p in models}
    for m in models.values():
        for w in windows[:8]:
            m.classify_window(w)  # warm-up
    for i in range(3000):
        for p, m in models.items():
            t = time.perf_counter_ns()
            m.classify_window(windows[i % 64])
            times[p].append(time.perf_counter_ns() - t)
    res = {"load_average": os.getloadavg(), "utc": time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime())}
    for p, t in times.items():
        t = np.asarray(t) / 1e3
        res[f"model_{p}_us"] = {"p50": round(float(np.median(t)), 1), "p90": round(float(np.percentile(t, 90)), 1)}
    acc = (rng.normal(0, 2, (60_000, 3)) + [0, 0, 9.81]).astype(np.float32)  # 10 min
    loop = StreamLoop(Free(), StreamParams())
    t = time.perf_counter_ns()
    for i in range(0, len(acc), 5):
        loop.feed(ImuBlock(i / 100, acc[i:i + 5]))
    per_sample_us = (time.perf_counter_ns() - t) / 1e3 / len(acc)
    hop_s = StreamParams().hop_s
    res["feed_per_sample_us_without_model"] = round(per_sample_us, 2)
    for p in models:
        per_hop_us = res[f"model_{p}_us"]["p50"]
        res[f"share_of_one_core_{p}"] = round((per_sample_us * 100 + per_hop_us / hop_s) / 1e6, 5)
    res["note"] = ("share of one core = (feed per sample x 100 Hz + model p50 / hop) / 1 s; rough, on a shared "
                   "machine, not python -m bench")
    print(json.dumps(res, indent=1))
    with open(out, "w") as f:
        json.dump(res, f, indent=1)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1]))
