"""The step model as the box calls it (StepModel.step: since s10-step2 a batch-1 IOBinding made once; session 10's
call was the session's own run, `_sess.run`, without the Python feed check) beside `_sess.run` and session.run of the
same graph and session.run of the one-shot graph, interleaved; pinned to CPU 0, a busy loop on CPU 1."""
import os, sys, json
import numpy as np
from bench.machine import LoadGenerator, pin_cpus
from bench.timing import interleaved_calls, summarize
from edge_runtime.core.manifest import ASSETS_DIR
from edge_runtime.wearable.classifier import Engine
def main():
    e = Engine.from_manifest(ASSETS_DIR, "int8")
    x = np.random.default_rng(1).normal(0, 3, (1, 33, 3)).astype(np.float32) + np.float32([0, 0, 9.80665])
    h, c = e.step_model.zero_state(1)
    sess = e.step_model.session
    ro = e.step_model._run_options
    x6 = np.random.default_rng(1).normal(0, 3, (1, 6, 33, 3)).astype(np.float32)
    calls = {"step int8, StepModel.step (what the loop calls)": lambda: e.step_model.step(x, h, c),
             "step int8, _sess.run (session 10's call)": lambda: sess._sess.run(["probs", "h_out", "c_out"],
                                                                             {"imu": x, "h": h, "c": c}, ro),
             "step int8, session.run": lambda: sess.run(["probs", "h_out", "c_out"], {"imu": x, "h": h, "c": c}),
             "one-shot int8, session.run (S = 6)": lambda: e.session.run(["probs"], {"imu": x6})}
    with LoadGenerator([1]):
        pin_cpus([0])
        t = interleaved_calls(calls, 6000, rounds=6, warmup=300)
    res = {k: summarize(v) for k, v in t.items()}
    print("load average", os.getloadavg())
    for k, v in res.items(): print(f"{k:55s} p50 {v['p50_us']:6.1f}  p99 {v['p99_us']:7.1f}")
    json.dump({"load_average": os.getloadavg(), "bound": e.step_model.bound, "rows": res}, open(sys.argv[1], "w"), indent=1)


if __name__ == "__main__":
    main()
