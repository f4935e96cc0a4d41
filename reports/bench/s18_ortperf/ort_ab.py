"""Interleaved A/B timing of onnxruntime session options and int8 model files, timed as ``python -m bench``
times its "int8 lifter" and "int8 ConvLSTM step" rows (bench.inference._ort_runner: ``session.run`` with a
pre-built feed for the lifter; ``StepModel.step_stream`` captures of 6 steps for the step model), with the
other core busy as ``--busy-cpus`` makes it (bench.machine.LoadGenerator: a spinning process pinned there).

    PYTHONPATH=. python reports/bench/s18_ortperf/ort_ab.py lifter --variants base,fastrun,bound \
        [--model FILE] [--models name=FILE,...] [--repeats 7] [--n 2000] --out /tmp/ortperf/X.json

Each variant gets its own session; every repeat times all variants interleaved in 5 rounds
(bench.timing.interleaved_calls), so they share the machine's noise; the report is the median over repeats
of each repeat's p50, with the min-max of those p50s (the spread the other helpers' load makes). Before timing,
every variant's outputs are compared bit for bit with the first variant's on 64 random feeds.
"""
from __future__ import annotations

import argparse
import contextlib
import json
import os
import sys
import time
from pathlib import Path

import numpy as np
import onnxruntime as ort

import edge_runtime.core.onnx as core_onnx
from bench.inference import example_inputs
from bench.machine import LoadGenerator, pin_cpus
from bench.timing import interleaved_calls
from edge_runtime.core.manifest import ASSETS_DIR, load_manifest, manifest_path, read_verified, select_model

ENTRIES = {"lifter": "lifter-int8", "step": "convlstm-step-int8"}

# name -> (session config entries, SessionOptions attributes); "base" is today's edge_runtime.core.onnx
OPTIONS: dict[str, tuple[dict[str, str], dict[str, object]]] = {
    "base": ({}, {}),
    "extended": ({}, {"graph_optimization_level": ort.GraphOptimizationLevel.ORT_ENABLE_EXTENDED}),
    "basic": ({}, {"graph_optimization_level": ort.GraphOptimizationLevel.ORT_ENABLE_BASIC}),
    "nomempat": ({}, {"enable_mem_pattern": False}),
    "noarena": ({}, {"enable_cpu_mem_arena": False}),
    "daz": ({"session.set_denormal_as_zero": "1"}, {}),
    "spin": ({"session.intra_op.allow_spinning": "1"}, {}),
    "noprepack": ({"session.disable_prepacking": "1"}, {}),
    "u8u8": ({"session.x64quantprecision": "1"}, {}),
    "qdqcleanup": ({"session.enable_quant_qdq_cleanup": "1"}, {}),
    "noquantqdq": ({"session.disable_quant_qdq": "1"}, {}),
    "deterministic": ({}, {"use_deterministic_compute": True}),
    "noopt": ({}, {"graph_optimization_level": ort.GraphOptimizationLevel.ORT_DISABLE_ALL}),
    "nonhwc": ({"optimization.disable_specified_optimizers": "NhwcTransformer"}, {}),
}


@contextlib.contextmanager
def patched_options(name: str):
    """edge_runtime.core.onnx.session_options with variant ``name``'s changes (the product's factory, patched
    only while the variant's session is built)."""
    entries, attrs = OPTIONS[name]
    orig = core_onnx.session_options

    def so_fn(threads: int = 1) -> ort.SessionOptions:
        so = orig(threads)
        for k, v in entries.items():
            so.add_session_config_entry(k, v)
        for k, v in attrs.items():
            setattr(so, k, v)
        return so

    core_onnx.session_options = so_fn
    try:
        yield
    finally:
        core_onnx.session_options = orig


@contextlib.contextmanager
def model_bytes(data: bytes):
    """edge_runtime.core.manifest.read_verified handing over ``data`` (a candidate file's bytes) while bench's
    runner is built, so that the timed call is bench's own for any model file."""
    import edge_runtime.core.manifest as manifest

    orig = manifest.read_verified
    manifest.read_verified = lambda assets, entry: data
    try:
        yield
    finally:
        manifest.read_verified = orig


def bench_call(data: bytes, entry: dict, feed: dict, opt: str):
    """bench.inference._ort_runner's timed call (the lifter: ``session.run`` with the pre-built feed; the step
    model: ``StepModel.step_stream``, captures of 6 steps from the zero state) on ``data`` with option ``opt``."""
    from bench.inference import InferenceConfig, _ort_runner

    with patched_options(opt), model_bytes(data):
        fn, info = _ort_runner(InferenceConfig(str(ASSETS_DIR), entry["name"]), entry, feed)
    return fn, info.get("call", "session.run")


def lifter_caller(data: bytes, entry: dict, feed: dict, how: str, opt: str):
    """(call, outputs_of(feed), what) for the lifter: bench's ``session.run``, the private ``_sess.run`` or
    edge_runtime.core.onnx.bound_call."""
    if how == "run":
        fn, what = bench_call(data, entry, feed, opt)
        sess = core_onnx.open_session  # outputs on other feeds: a session like bench's
        with patched_options(opt):
            s = sess(data, 1, "lifter")
        names = [o.name for o in s.get_outputs()]
        return fn, (lambda f: s.run(names, f)), what
    with patched_options(opt):
        sess = core_onnx.open_session(data, 1, "lifter")
    outputs = [o.name for o in sess.get_outputs()]
    ro = ort.RunOptions()
    if how == "fastrun":
        inner = sess._sess.run
        return (lambda: inner(outputs, feed, ro)), (lambda f: inner(outputs, f, ro)), "_sess.run"
    if how == "bound":  # input and outputs bound once to batch-1 buffers
        call_x = core_onnx.bound_call(sess, feed, outputs, ro)
        (x,) = feed.values()
        return (lambda: call_x(x)), (lambda f: call_x(*f.values())), "core.onnx.bound_call"
    raise ValueError(how)


def step_caller(data: bytes, entry: dict, feed: dict, opt: str):
    """bench's step call; its outputs over two captures of bench's sub-window (every decision)."""
    fn, what = bench_call(data, entry, feed, opt)
    return fn, (lambda f: [fn() for _ in range(12)]), what


def parse_variant(v: str, models: dict[str, Path]) -> tuple[str, str, str]:
    """'opt' | 'opt+how' | 'file:opt+how' -> (model key, option name, call)."""
    mkey, _, rest = v.rpartition(":")
    opt, _, how = rest.partition("+")
    return mkey or "shipped", opt, how or "run"


def main(argv=None) -> int:
    p = argparse.ArgumentParser()
    p.add_argument("what", choices=sorted(ENTRIES))
    p.add_argument("--variants", required=True, help="comma list of [model:]option[+call]; call: run|fastrun|bound")
    p.add_argument("--models", default="", help="comma list of key=path of other model files")
    p.add_argument("--repeats", type=int, default=7)
    p.add_argument("--n", type=int, default=2000)
    p.add_argument("--warmup", type=int, default=200)
    p.add_argument("--cpu", type=int, default=0)
    p.add_argument("--busy-cpu", type=int, default=1, help="-1: no load generator")
    p.add_argument("--out", required=True)
    a = p.parse_args(argv)
    mpath = manifest_path(ASSETS_DIR)
    entry = select_model(load_manifest(mpath), ENTRIES[a.what], str(mpath))
    models = {"shipped": None, **{k: Path(v) for k, v in (s.split("=", 1) for s in a.models.split(",") if s)}}
    feed = example_inputs(entry, 0)
    rng = np.random.default_rng(1)
    if a.what == "lifter":
        checks = [{k: rng.normal(0, 0.3, v.shape).astype(np.float32) for k, v in feed.items()} for _ in range(64)]
    else:
        checks = [feed]  # the step's check runs bench's own call: two captures of its sub-window
    variants = a.variants.split(",")
    calls, info, ref = {}, {}, None
    for v in variants:
        mkey, opt, how = parse_variant(v, models)
        data = read_verified(ASSETS_DIR, entry) if models[mkey] is None else models[mkey].read_bytes()
        if a.what == "lifter":
            call, outputs_of, path = lifter_caller(data, entry, feed, how, opt)
        else:
            call, outputs_of, path = step_caller(data, entry, feed, opt)
        outs = [[np.asarray(o) for o in outputs_of(f)] for f in checks]
        if ref is None:
            ref = outs
        diffs = [float(np.abs(x - y).max()) for o, r in zip(outs, ref) for x, y in zip(o, r)]
        info[v] = {"identical_to_first": all(d == 0.0 for d in diffs), "max_abs_diff": max(diffs), "call": path}
        calls[v] = call
    print(json.dumps(info), file=sys.stderr)
    busy = LoadGenerator([a.busy_cpu]) if a.busy_cpu >= 0 else contextlib.nullcontext()  # checked before pinning
    pin_cpus([a.cpu])
    p50s: dict[str, list[float]] = {v: [] for v in variants}
    t0 = time.strftime("%H:%M:%S", time.gmtime())
    with busy:
        time.sleep(0.5)
        for r in range(a.repeats):
            order = variants if r % 2 == 0 else variants[::-1]  # alternate who goes first in a round
            times = interleaved_calls({v: calls[v] for v in order}, a.n, rounds=5, warmup=a.warmup)
            for v in variants:
                p50s[v].append(float(np.median(times[v])) / 1e3)
            print(f"repeat {r + 1}: " + ", ".join(f"{v} {p50s[v][-1]:.1f}" for v in variants), file=sys.stderr)
    t1 = time.strftime("%H:%M:%S", time.gmtime())
    rows = {v: {"p50_us_median": round(float(np.median(p50s[v])), 2), "p50_us_min": round(min(p50s[v]), 2),
                "p50_us_max": round(max(p50s[v]), 2), "p50s_us": [round(x, 2) for x in p50s[v]], **info[v]}
            for v in variants}
    base = rows[variants[0]]["p50_us_median"]
    for v in variants:  # paired: the ratio in each repeat, then its median (the load moves both alike)
        rows[v]["ratio_to_first_median"] = round(float(np.median(np.array(p50s[v]) / np.array(p50s[variants[0]]))), 4)
    out = {"what": a.what, "utc": f"{time.strftime('%Y-%m-%d', time.gmtime())} {t0}-{t1}",
           "argv": sys.argv[1:], "load_generator_cpu": a.busy_cpu, "cpu": a.cpu, "rows": rows,
           "loadavg": os.getloadavg()}
    Path(a.out).parent.mkdir(parents=True, exist_ok=True)
    Path(a.out).write_text(json.dumps(out, indent=1))
    for v in variants:
        r = rows[v]
        print(f"{v:28s} p50 {r['p50_us_median']:7.2f} us [{r['p50_us_min']:.1f}-{r['p50_us_max']:.1f}] "
              f"x{r['ratio_to_first_median']:.3f}  identical={r['identical_to_first']} maxdiff={r['max_abs_diff']:.2e}"
              f"  {r['call']}")
    print(f"(base median {base:.2f} us; {out['utc']} UTC)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
