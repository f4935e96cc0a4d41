"""Session 21 (issue 12): parameters and a rough CPU cost of one streaming decision at batch 1.

    PYTHONPATH=. OMP_NUM_THREADS=1 nice -n 10 python reports/wearable/stream_s21/cost.py MODEL.pt WINDOW_S HOP_S OUT.json

Exports the model to ONNX (fp32, one fixed window of WINDOW_S at 25 Hz) under /work/s9-runs/stream21/, runs it
with onnxruntime (one intra-op thread, sequential) and torch (one thread) on random windows, and reports the median
and p90 per decision and the share of one core at one decision per HOP_S. Rough: measured on the shared 2-core box,
not by ``python -m bench`` (the lead benches on a quiet machine). The 25 Hz averaging (a running sum of 4 frames)
costs next to nothing and is not timed.
"""
from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parent))
from data import DEFAULT_DIR  # noqa: E402
from net import STEP_S, load, params  # noqa: E402

REPS = 3000


def timed(fn, x: list) -> np.ndarray:
    for v in x[:200]:
        fn(v)  # warm-up
    out = np.empty(len(x))
    for k, v in enumerate(x):
        t = time.perf_counter()
        fn(v)
        out[k] = time.perf_counter() - t
    return out * 1e6


def main(argv: list[str]) -> int:
    import onnxruntime as ort

    model_path, window_s, hop_s, out = argv[0], float(argv[1]), float(argv[2]), Path(argv[3])
    torch.set_num_threads(1)
    model, _ = load(model_path)
    steps = int(round(window_s / STEP_S))
    onnx_path = DEFAULT_DIR / f"{Path(model_path).stem}_w{window_s:g}.onnx"
    torch.onnx.export(model, torch.zeros(1, 3, steps), str(onnx_path), input_names=["x25"], output_names=["logits"],
                      opset_version=17, dynamo=False)
    so = ort.SessionOptions()
    so.intra_op_num_threads = 1
    so.inter_op_num_threads = 1
    so.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    sess = ort.InferenceSession(str(onnx_path), so, providers=["CPUExecutionProvider"])
    rng = np.random.default_rng(0)
    xs = [rng.normal(0, 3, (1, 3, steps)).astype(np.float32) for _ in range(REPS)]
    ort_us = timed(lambda v: sess.run(None, {"x25": v}), xs)
    with torch.no_grad():
        torch_us = timed(lambda v: model(torch.from_numpy(v)), xs)
    same = float(np.mean([np.argmax(sess.run(None, {"x25": v})[0]) == int(model(torch.from_numpy(v)).argmax())
                          for v in xs[:500]]))
    lengths = [steps, steps // 2, steps // 4]  # each conv's output positions (after each max-pool)
    convs = [m for m in model.modules() if isinstance(m, torch.nn.Conv1d)]
    macs = int(sum(c.weight.numel() * n for c, n in zip(convs, lengths)) + model.head.weight.numel())
    res = {"model": model_path, "params": params(model), "window_s": window_s, "input_steps_25hz": steps,
           "macs_per_decision": macs, "hop_s": hop_s,
           "onnxruntime_fp32_us": {"p50": round(float(np.median(ort_us)), 1),
                                   "p90": round(float(np.percentile(ort_us, 90)), 1)},
           "torch_us": {"p50": round(float(np.median(torch_us)), 1),
                        "p90": round(float(np.percentile(torch_us, 90)), 1)},
           "core_share_at_hop_pct": round(float(np.median(ort_us)) / (hop_s * 1e6) * 100, 4),
           "onnx_vs_torch_top_class_agreement": same, "onnx": str(onnx_path),
           "load_average": [round(v, 2) for v in os.getloadavg()],
           "utc": time.strftime("%Y-%m-%d %H:%M:%S", time.gmtime())}
    out.write_text(json.dumps(res, indent=1))
    print(json.dumps(res, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
