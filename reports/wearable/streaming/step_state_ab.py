"""s11-replay: a capture's step as the loop calls it, two ways, interleaved in one process: s10-step2's call
(``StepModel._step_one``: the state copied in and out every step) against ``StepModel.step_stream`` (the state kept
in the bound buffers). Blocks of 400 captures of 6 steps from the zero state each way, 20 blocks, after 300 warm-up
captures; CPU 0, a busy loop on CPU 1. Run: PYTHONPATH=. python reports/wearable/streaming/step_state_ab.py OUT.json"""
import json
import os
import subprocess
import sys
import time

import numpy as np

from edge_runtime.core.manifest import ASSETS_DIR
from edge_runtime.wearable.classifier import Engine, StepStream


def capture_timer(model, x, times):
    """Two calls that each time one capture's 6 steps, into ``times["copied"]`` and ``times["kept"]``."""

    def copied():
        h, c = model.zero_state(1)
        for _ in range(6):
            t = time.perf_counter()
            _, h, c = model._step_one(x, h, c)
            times["copied"].append(time.perf_counter() - t)

    def kept():
        stream = StepStream(*model.zero_state(1))
        for _ in range(6):
            t = time.perf_counter()
            model.step_stream(x, stream)
            times["kept"].append(time.perf_counter() - t)

    return copied, kept


def main(out_path):
    busy = subprocess.Popen([sys.executable, "-c", "import os; os.sched_setaffinity(0, {1})\nwhile True: pass"])
    try:
        os.sched_setaffinity(0, {0})
        out = {"load_before": os.getloadavg()}
        for precision in ("int8", "fp32"):
            model = Engine.from_manifest(ASSETS_DIR, precision).step_model
            x = (np.random.default_rng(0).normal(0, 3, (1, 33, 3)) + [0, 0, 9.80665]).astype(np.float32)
            times = {"copied": [], "kept": []}
            copied, kept = capture_timer(model, x, times)
            for _ in range(300):
                copied()
                kept()
            times["copied"].clear()
            times["kept"].clear()
            for _ in range(20):
                for _ in range(400):
                    copied()
                for _ in range(400):
                    kept()
            out[precision] = {k: {"p50_us": round(float(np.percentile(v, 50)) * 1e6, 2),
                                  "p99_us": round(float(np.percentile(v, 99)) * 1e6, 2), "n": len(v)}
                              for k, v in times.items()}
            print(precision, out[precision], flush=True)
        out["load_after"] = os.getloadavg()
        with open(out_path, "w") as f:
            json.dump(out, f, indent=1)
    finally:
        busy.kill()


if __name__ == "__main__":
    main(sys.argv[1])
