"""Per-inference latency of one shipped model on one runtime, measured inside a child process.

Every configuration (manifest entry x runtime x threads) runs in its own
process (``bench.worker``) so that its peak resident memory is its own:

* ``onnxruntime``: the manifest entry's file, sha256-checked
  (``edge_runtime.core.manifest.read_verified``), on the box's session settings
  (``edge_runtime.core.onnx.open_session``: N intra-op threads, 1 inter-op,
  no spinning, all graph optimisations); ``session.run`` with a pre-built feed.
  The child imports numpy and onnxruntime only (no torch), as a box would.
* ``openvino``: the same ONNX file on OpenVINO's CPU plugin when the ``openvino`` extra is
  installed (else the row is skipped with a note): ``INFERENCE_NUM_THREADS`` N, one stream,
  the latency hint, fp32 inference precision (OpenVINO would otherwise run fp32 layers in
  bf16 on a CPU that has it), ``InferRequest.infer`` with a pre-built feed. Its int8 rows
  run the QDQ graph through OpenVINO's own low-precision transformations.
* ``torch-eager``: the same network rebuilt in torch, in eval mode under
  ``torch.inference_mode`` with ``torch.set_num_threads(N)``. The ConvLSTM and
  its baselines come from ``models.nets`` with the training checkpoint's
  weights when it is found (``runs/assets-seed<S>/<arch>/model.pt``, S from the
  manifest's provenance), else a seeded random initialisation (latency does not
  depend on weight values). The lifter is ``models.lifter.LifterNet`` (strided,
  as exported) from the checkpoint the manifest's provenance names, else the
  manifest's architecture randomly initialised.
  A model torch cannot rebuild is skipped with a note.

Inputs come from the manifest entry (``inputs[].shape``, the batch dimension
set to 1): the ConvLSTM gets a plausible wrist window (gravity on z plus
3 m/s^2 noise; its step model one sub-window of it, and an LSTM state like the others), any other model standard-normal values scaled by 0.3 (e.g.
normalised 2D keypoints). Latency does not depend on the values.
"""
from __future__ import annotations

import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Callable

import numpy as np

from bench.timing import peak_rss_mb, rss_mb, time_calls
from edge_runtime.core.manifest import STEP_ARCH, example_shape

RUNTIMES = ("onnxruntime", "openvino", "torch-eager")
REPO_ROOT = Path(__file__).resolve().parent.parent
NETS_ARCHS = ("convlstm", "cnn", "lstm")
"""Architectures ``models.nets.build`` rebuilds."""


@dataclass(frozen=True)
class InferenceConfig:
    assets: str
    """Assets directory holding manifest.json."""
    entry: str
    """Manifest entry name, e.g. ``convlstm-int8``."""
    runtime: str = "onnxruntime"
    """One of :data:`RUNTIMES`."""
    threads: int = 1
    """Intra-op threads."""
    n: int = 2000
    """Timed single inferences (batch 1)."""
    warmup: int = 200
    """Untimed calls first."""
    seed: int = 0
    """Seed of the input values and of a random torch initialisation."""


class CannotRebuild(Exception):
    """torch cannot rebuild this model (no torch, no builder for its arch): the row is skipped."""


def example_inputs(entry: dict, seed: int = 0) -> dict[str, np.ndarray]:
    """One batch-1 array per manifest input (:func:`edge_runtime.core.manifest.example_shape`: the
    ConvLSTM's sub-window count at the full window, other symbolic dimensions 1)."""
    rng = np.random.default_rng(seed)
    feed = {}
    for spec in entry["inputs"]:
        shape = example_shape(spec, 1)
        dtype = np.dtype(spec.get("dtype", "float32"))
        if entry.get("arch") in NETS_ARCHS or (entry.get("arch") == STEP_ARCH and spec["name"] == "imu"):
            x = rng.normal(0.0, 3.0, size=shape) + np.array([0.0, 0.0, 9.80665])[: shape[-1]]
        else:
            x = rng.normal(0.0, 0.3, size=shape)
        feed[spec["name"]] = np.ascontiguousarray(x, dtype=dtype)
    return feed


def _ort_runner(cfg: InferenceConfig, entry: dict, feed: dict) -> tuple[Callable[[], object], dict]:
    import onnxruntime as ort

    from edge_runtime.core.manifest import read_verified
    from edge_runtime.core.onnx import fast_run, open_session

    data, source = read_verified(cfg.assets, entry), str(Path(cfg.assets) / entry["file"])
    if entry.get("arch") == STEP_ARCH:  # the box's own call of a step (its IOBinding), not a generic session.run
        from edge_runtime.wearable.classifier import N_SUBSEQ, StepModel, StepStream

        model = StepModel(data, cfg.threads, source, entry["classes"])
        x, h, c = (feed[k] for k in ("imu", "h", "c"))
        if len(x) != 1:
            return (lambda: model.step(x, h, c)), {"call": "StepModel.step (a batch)"}
        now = {"stream": None, "steps": 0}

        def capture_step():
            """As a capture is stepped: 6 steps from the zero state, each from the state the one before left."""
            if now["steps"] % N_SUBSEQ == 0:
                now["stream"] = StepStream(*model.zero_state(1))
            now["steps"] += 1
            return model.step_stream(x, now["stream"])

        return capture_step, {"call": f"StepModel.step_stream ({model.call_path}; captures of {N_SUBSEQ} steps from "
                                      "the zero state)"}
    sess = open_session(data, cfg.threads, source)
    outputs = [o.name for o in sess.get_outputs()]
    ro = ort.RunOptions()
    run = fast_run(sess, outputs, feed, ro)  # the call the box makes (the lifter's): session.run or its compiled run
    return (lambda: run(outputs, feed, ro)), {"call": "core.onnx.fast_run" + (" (compiled run)" if run != sess.run
                                                                              else " (session.run)")}


def _openvino_runner(cfg: InferenceConfig, entry: dict, feed: dict) -> tuple[Callable[[], object], dict]:
    try:
        import openvino as ov
    except ImportError:
        raise CannotRebuild("openvino not installed (pip install 'edge-safety[openvino]')") from None
    from edge_runtime.core.manifest import read_verified

    read_verified(cfg.assets, entry)  # the file OpenVINO reads is the one the manifest names
    core = ov.Core()
    compiled = core.compile_model(core.read_model(str(Path(cfg.assets) / entry["file"])), "CPU", {
        "INFERENCE_NUM_THREADS": cfg.threads, "NUM_STREAMS": 1, "PERFORMANCE_HINT": "LATENCY",
        "INFERENCE_PRECISION_HINT": "f32"})
    request = compiled.create_infer_request()
    return (lambda: request.infer(feed)), {"openvino": ov.__version__}


def find_checkpoint(entry: dict) -> Path | None:
    """The training checkpoint of a ``models.nets`` entry: the manifest's provenance
    ``checkpoint``, else ``runs/assets-seed<S>/<arch>/model.pt`` of this repository."""
    prov = entry.get("provenance") or {}
    candidates = []
    if prov.get("checkpoint"):
        candidates.append(Path(prov["checkpoint"]))
    if prov.get("seed") is not None:
        candidates.append(REPO_ROOT / "runs" / f"assets-seed{prov['seed']}" / entry["arch"] / "model.pt")
    return next((c if c.is_absolute() else REPO_ROOT / c for c in candidates
                 if (c if c.is_absolute() else REPO_ROOT / c).is_file()), None)


def _shown(p: Path) -> str:
    return str(p.relative_to(REPO_ROOT) if p.is_relative_to(REPO_ROOT) else p)


def _torch_nets_model(entry: dict, seed: int):
    import torch

    from models.nets import build

    ckpt = find_checkpoint(entry)
    if ckpt is not None:
        from models.train import load_checkpoint

        model, meta = load_checkpoint(ckpt)
        if meta.get("arch") == entry["arch"] and list(meta.get("classes", [])) == list(entry["classes"]):
            return model.eval(), f"checkpoint {_shown(ckpt)}", ckpt
    torch.manual_seed(seed)
    model = build(entry["arch"], len(entry["classes"])).eval()
    return model, "seeded random init (latency is weight-independent)", None


def _find_config(obj, keys=("channels", "filter_widths")) -> dict | None:
    """The first dict (depth-first) in a manifest entry holding ``keys``: the lifter's architecture."""
    if isinstance(obj, dict):
        if all(k in obj for k in keys):
            return obj
        obj = list(obj.values())
    if isinstance(obj, list):
        return next((c for c in map(_find_config, obj) if c is not None), None)
    return None


def _torch_lifter_model(entry: dict, seed: int):
    """``models.lifter.LifterNet`` (strided, as exported): the training checkpoint named in the
    manifest's provenance when it exists and has the manifest's architecture, else a seeded
    random initialisation of that architecture (any dict in the entry with ``channels`` and
    ``filter_widths``; LifterConfig's defaults when there is none)."""
    try:
        from models.lifter import LifterConfig, LifterNet
    except ImportError as e:
        raise CannotRebuild(f"models.lifter not importable ({e})") from None
    import dataclasses

    import torch

    found = _find_config(entry)
    ckpt = find_checkpoint(entry)
    if ckpt is not None:
        from models.lifter_train import load_checkpoint

        model, ck = load_checkpoint(ckpt, strided=True)
        if found is None or ck.get("config") == found:
            return model.eval(), f"checkpoint {_shown(ckpt)}", ckpt
    known = {f.name for f in dataclasses.fields(LifterConfig)}
    config = LifterConfig.from_dict({**LifterConfig().to_dict(), **{k: v for k, v in (found or {}).items()
                                                                     if k in known}})
    torch.manual_seed(seed)
    where = "the manifest's architecture" if found else "LifterConfig defaults (no architecture in the manifest)"
    return LifterNet(config, strided=True).eval(), f"seeded random init, {where} (latency is weight-independent)", None


TORCH_BUILDERS = {**{a: _torch_nets_model for a in NETS_ARCHS}, "lifter": _torch_lifter_model}
"""arch -> function(entry, seed) -> (torch module in eval mode, weights note, weights file or None)."""


def _torch_runner(cfg: InferenceConfig, entry: dict, feed: dict) -> tuple[Callable[[], object], dict]:
    try:
        import torch
    except ImportError:
        raise CannotRebuild("torch not installed") from None
    builder = TORCH_BUILDERS.get(entry["arch"])
    if builder is None:
        raise CannotRebuild(f"no torch builder for arch {entry['arch']!r}")
    torch.set_num_threads(cfg.threads)
    model, weights, weights_file = builder(entry, cfg.seed)
    args = [torch.from_numpy(a) for a in feed.values()]

    def run():
        with torch.inference_mode():
            return model(*args)

    return run, {"weights": weights, "file_bytes": weights_file.stat().st_size if weights_file else None}


RUNNERS = {"onnxruntime": _ort_runner, "openvino": _openvino_runner, "torch-eager": _torch_runner}
"""runtime -> function(config, entry, feed) -> (one timed call, extra row fields)."""


def measure(cfg: InferenceConfig) -> dict:
    """Run in a child process: load, warm up, time ``cfg.n`` calls. Returns the per-call
    times (ns), resident memory before loading the model and at the peak, load time,
    file size, or ``{"skipped": reason}``."""
    from edge_runtime.core.manifest import load_manifest, manifest_path, select_model

    if cfg.runtime not in RUNTIMES:
        raise ValueError(f"runtime {cfg.runtime!r} not one of {RUNTIMES}")
    mpath = manifest_path(cfg.assets)
    entry = select_model(load_manifest(mpath), cfg.entry, str(mpath))
    feed = example_inputs(entry, cfg.seed)
    # The runtime library is imported before the idle reading: its footprint belongs to the runtime.
    if cfg.runtime == "torch-eager":
        try:
            import torch  # noqa: F401
        except ImportError:
            return {"skipped": "torch not installed"}
    elif cfg.runtime == "openvino":
        try:
            import openvino  # noqa: F401
        except ImportError:
            return {"skipped": "openvino not installed (pip install 'edge-safety[openvino]')"}
    else:
        import onnxruntime  # noqa: F401
    idle = rss_mb()
    t0 = time.perf_counter()
    try:
        fn, info = RUNNERS[cfg.runtime](cfg, entry, feed)
    except CannotRebuild as e:
        return {"skipped": str(e)}
    load_ms = (time.perf_counter() - t0) * 1e3
    times = time_calls(fn, cfg.n, cfg.warmup)
    # file_bytes: the ONNX file for onnxruntime and openvino, the torch checkpoint (or None) for torch eager
    return {"config": asdict(cfg), "times_ns": times.tolist(), "rss_idle_mb": idle, "peak_rss_mb": peak_rss_mb(),
            "load_ms": round(load_ms, 1), "file_bytes": (mpath.parent / entry["file"]).stat().st_size,
            "torch_loaded": "torch" in sys.modules, **info}
