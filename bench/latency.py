"""Per-inference latency of the ConvLSTM: torch eager, onnxruntime fp32, onnxruntime int8, side by side.

Method
------
* batch 1, one (1, 6, 33, 3) float32 window of plausible wrist data, the same
  array for every runtime;
* every runner is warmed up, then all runners are timed in *interleaved
  rounds* (runner A k calls, runner B k calls, ..., repeated) so that they
  share the machine's noise (frequency changes, other processes) instead of
  one runtime getting a quiet minute and another a busy one;
* each call is timed alone with ``time.perf_counter_ns``; the garbage collector
  is paused while timing; p50, p99 and mean in microseconds;
* onnxruntime runs the shipped models from ``edge_runtime/assets`` (sha256
  checked through the manifest) with the runtime's own session settings
  (``edge_runtime.engine.session_options``: N intra-op threads, no spinning,
  all graph optimisations). Two onnxruntime rows per precision:
  ``onnxruntime`` = ``session.run`` with a pre-built feed (what the runtime
  library costs) and ``edge_runtime`` = ``Engine.classify`` (plus the product's
  input checks);
* torch eager runs ``models.nets`` ConvLSTM in eval mode under
  ``torch.inference_mode`` with ``torch.set_num_threads(N)``; its weights are a
  seeded random initialisation (latency does not depend on weight values; the
  shipped assets are torch-free). Without torch installed these rows are skipped.

When the assets are missing and torch is present, fp32 and int8 models are
exported on the fly from a random initialisation (``export``).
"""
from __future__ import annotations

import gc
import os
import platform
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np

from edge_runtime.engine import ASSETS_DIR, Engine

MODEL = "convlstm"


def torch_available() -> bool:
    try:
        import torch  # noqa: F401
    except ImportError:
        return False
    return True


def machine_info() -> dict:
    import onnxruntime

    cpu, flags = platform.processor() or platform.machine(), []
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name") and cpu in ("", platform.machine(), platform.processor()):
                    cpu = line.split(":", 1)[1].strip()
                if line.startswith("flags") and not flags:
                    flags = line.split(":", 1)[1].split()
    except OSError:
        pass
    try:
        affinity = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        affinity = None
    info = {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "cores_available": affinity,
        "isa": [f for f in ("avx2", "avx512f", "avx512_vnni", "avx_vnni", "amx_int8") if f in flags],
        "platform": platform.platform(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "onnxruntime": onnxruntime.__version__,
        "torch": None,
    }
    if torch_available():
        import torch

        info["torch"] = torch.__version__
    return info


def sample_window(seed: int = 0) -> np.ndarray:
    rng = np.random.default_rng(seed)
    x = rng.normal(0.0, 3.0, size=(1, 6, 33, 3)) + np.array([0.0, 0.0, 9.80665])
    return np.ascontiguousarray(x, dtype=np.float32)


def time_interleaved(runners: dict[str, Callable[[], object]], n: int, warmup: int, rounds: int = 10
                     ) -> dict[str, np.ndarray]:
    """Per-call wall times in ns, runners interleaved in ``rounds`` blocks."""
    for f in runners.values():
        for _ in range(warmup):
            f()
    rounds = max(1, min(rounds, n))
    per = -(-n // rounds)
    out = {k: np.empty(per * rounds, np.int64) for k in runners}
    clock = time.perf_counter_ns
    was = gc.isenabled()
    gc.disable()
    try:
        for r in range(rounds):
            for k, f in runners.items():
                buf = out[k]
                for i in range(r * per, (r + 1) * per):
                    t0 = clock()
                    f()
                    buf[i] = clock() - t0
    finally:
        if was:
            gc.enable()
    return {k: v[:n] for k, v in out.items()}


@dataclass
class Row:
    model: str
    precision: str
    runtime: str
    threads: int
    times_ns: np.ndarray = field(repr=False)
    extra: dict = field(default_factory=dict)

    def as_dict(self) -> dict:
        t = self.times_ns / 1e3
        return {"model": self.model, "precision": self.precision, "runtime": self.runtime,
                "threads": self.threads, "p50_us": round(float(np.median(t)), 2),
                "p99_us": round(float(np.percentile(t, 99)), 2), "mean_us": round(float(t.mean()), 2),
                "min_us": round(float(t.min()), 2), "n": int(len(t)), **self.extra}


def _on_the_fly_assets(workdir: Path) -> Path:
    """fp32 + int8 ConvLSTM from a random initialisation, with a manifest (needs torch)."""
    import torch

    from edge_runtime.labels import CLASSES
    from edge_runtime.manifest import SCHEMA_VERSION, sha256_file, write_manifest
    from export.onnx_export import example_input, save_onnx, to_onnx
    from export.quantize import build_variant
    from models.nets import build

    torch.manual_seed(0)
    model = build(MODEL, len(CLASSES)).eval()
    fp = save_onnx(to_onnx(model, CLASSES, commit=""), workdir / "convlstm.fp32.onnx")
    q = build_variant(fp, workdir / "convlstm.int8.onnx", "qdq_conv", example_input(256, seed=3))
    entries = []
    for p, prec in ((fp, "fp32"), (q, "int8")):
        entries.append({"name": f"{MODEL}-{prec}", "file": p.name, "sha256": sha256_file(p), "precision": prec,
                        "arch": MODEL, "parameters": {}, "classes": list(CLASSES),
                        "inputs": [{"name": "imu", "shape": ["N", 6, 33, 3], "dtype": "float32"}],
                        "outputs": [{"name": "probs", "shape": ["N", len(CLASSES)], "dtype": "float32"}],
                        "metrics": {}, "provenance": {"command": "bench: random initialisation"}})
    write_manifest(workdir, {"version": SCHEMA_VERSION, "created_by": "python -m bench (on the fly)",
                             "models": entries})
    return workdir


def run(threads: list[int], n: int = 2000, warmup: int = 200, assets: str | Path | None = None,
        use_torch: bool = True, rounds: int = 10, log: Callable[[str], None] = lambda s: None) -> dict:
    assets = Path(assets) if assets else ASSETS_DIR
    source = str(assets)
    tmp = None
    if not (assets / "manifest.json").exists():
        if not torch_available():
            raise FileNotFoundError(f"{assets / 'manifest.json'}: no shipped models and no torch to export "
                                    "them on the fly (run `python -m export assets --seed 0`)")
        tmp = tempfile.TemporaryDirectory()
        log(f"no manifest in {assets}: exporting fp32 and int8 from a random initialisation")
        assets = _on_the_fly_assets(Path(tmp.name))
        source = "exported on the fly from a random initialisation"
    use_torch = use_torch and torch_available()
    x = sample_window()
    rows: list[Row] = []
    try:
        for t in threads:
            runners: dict[tuple, Callable] = {}
            extra: dict[tuple, dict] = {}
            for prec in ("fp32", "int8"):
                t0 = time.perf_counter()
                eng = Engine.from_manifest(assets, prec, threads=t)
                load_ms = (time.perf_counter() - t0) * 1e3
                size = (Path(assets) / eng.entry["file"]).stat().st_size
                sess, feed, outs = eng.session, {eng.input_name: x}, [eng.output_name]
                import onnxruntime as ort

                ro = ort.RunOptions()
                runners[(prec, "onnxruntime")] = lambda s=sess, f=feed, o=outs, r=ro: s.run(o, f, r)
                runners[(prec, "edge_runtime")] = lambda e=eng: e.classify(x)
                for rt in ("onnxruntime", "edge_runtime"):
                    extra[(prec, rt)] = {"file": eng.entry["file"], "size_bytes": size,
                                         "load_ms": round(load_ms, 1)}
            if use_torch:
                import torch

                from models.nets import build

                torch.set_num_threads(t)
                torch.manual_seed(0)
                tm = build(MODEL, len(eng.classes)).eval()
                xt = torch.from_numpy(x)

                def torch_run(m=tm, xt=xt):
                    with torch.inference_mode():
                        return m(xt)

                runners[("fp32", "torch-eager")] = torch_run
                extra[("fp32", "torch-eager")] = {"weights": "random init (latency is weight-independent)"}
            log(f"timing {len(runners)} runners x {n} calls with {t} thread(s) ...")
            times = time_interleaved(runners, n, warmup, rounds)
            for (prec, rt), ts in times.items():
                rows.append(Row(MODEL, prec, rt, t, ts, extra.get((prec, rt), {})))
    finally:
        if tmp is not None:
            tmp.cleanup()
    order = {"torch-eager": 0, "onnxruntime": 1, "edge_runtime": 2}
    rows.sort(key=lambda r: (r.threads, order.get(r.runtime, 9), r.precision))
    results = [r.as_dict() for r in rows]
    return {"machine": machine_info(),
            "method": {"batch": 1, "warmup": warmup, "n": n, "rounds": rounds, "interleaved": True,
                       "timer": "time.perf_counter_ns per call, gc paused", "assets": source,
                       "command": "python -m bench " + " ".join(sys.argv[1:])},
            "results": results, "checks": checks(results)}


def checks(results: list[dict]) -> dict:
    """The issue's must-hold at one thread: int8 faster than fp32 and than torch eager (p50)."""
    out = {}
    for t in sorted({r["threads"] for r in results}):
        get = lambda prec, rt: next((r for r in results if r["threads"] == t and r["precision"] == prec  # noqa: E731
                                     and r["runtime"] == rt), None)
        i8, f32, te = get("int8", "onnxruntime"), get("fp32", "onnxruntime"), get("fp32", "torch-eager")
        if not i8 or not f32:
            continue
        c = {"int8_p50_us": i8["p50_us"], "int8_vs_fp32": round(f32["p50_us"] / i8["p50_us"], 2),
             "int8_faster_than_fp32": i8["p50_us"] < f32["p50_us"], "int8_p50_le_50us": i8["p50_us"] <= 50.0}
        if te:
            c["int8_vs_torch_eager"] = round(te["p50_us"] / i8["p50_us"], 2)
            c["int8_faster_than_torch_eager"] = i8["p50_us"] < te["p50_us"]
        out[f"threads={t}"] = c
    return out


def format_table(report: dict) -> str:
    m = report["machine"]
    lines = [f"{m['cpu']} ({m['cores']} cores), python {m['python']}, onnxruntime {m['onnxruntime']}, "
             f"torch {m['torch'] or 'absent'}",
             f"{'model':<9} {'precision':<9} {'runtime':<13} {'threads':>7} {'p50 us':>9} {'p99 us':>9} "
             f"{'mean us':>9} {'n':>7}"]
    for r in report["results"]:
        lines.append(f"{r['model']:<9} {r['precision']:<9} {r['runtime']:<13} {r['threads']:>7} "
                     f"{r['p50_us']:>9.1f} {r['p99_us']:>9.1f} {r['mean_us']:>9.1f} {r['n']:>7}")
    for t, c in report["checks"].items():
        s = f"{t}: int8 p50 {c['int8_p50_us']:.1f} us; {c['int8_vs_fp32']:.2f}x faster than onnxruntime fp32"
        if "int8_vs_torch_eager" in c:
            s += f", {c['int8_vs_torch_eager']:.2f}x faster than torch eager"
        lines.append(s)
    return "\n".join(lines)
