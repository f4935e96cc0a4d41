"""The one ONNX session factory of the box: every model (classifier, lifter, a camera's 2D pose
model) is opened here, the same way on every product.

Sessions are set up for a small edge box: ``threads`` intra-op threads (default 1), one
inter-op thread, sequential execution, no spin-waiting (idle threads sleep instead of
burning a core), all graph optimisations. Through :func:`session_from_manifest` the bytes
whose sha256 was checked against ``assets/manifest.json`` are the bytes onnxruntime loads.
"""
from __future__ import annotations

import os
from pathlib import Path
from typing import Sequence

import numpy as np
import onnxruntime as ort

from edge_runtime.core.manifest import ASSETS_DIR, ModelIntegrityError, load_verified


def session_options(threads: int = 1) -> ort.SessionOptions:
    """onnxruntime options for the box: ``threads`` intra-op, 1 inter-op, sequential, no spinning."""
    if not isinstance(threads, int) or isinstance(threads, bool) or threads < 1:
        raise ValueError(f"threads must be a positive integer, got {threads!r}")
    so = ort.SessionOptions()
    so.intra_op_num_threads = threads
    so.inter_op_num_threads = 1
    so.execution_mode = ort.ExecutionMode.ORT_SEQUENTIAL
    so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_ENABLE_ALL
    so.add_session_config_entry("session.intra_op.allow_spinning", "0")
    so.add_session_config_entry("session.inter_op.allow_spinning", "0")
    so.log_severity_level = 3  # errors only: warnings would go to stderr on every load
    return so


def open_session(model: bytes | str | os.PathLike, threads: int = 1, source: str = "", *,
                 optimized_model_path: str | os.PathLike | None = None) -> ort.InferenceSession:
    """An onnxruntime CPU session for a model file or its bytes, with :func:`session_options`.

    An unreadable file or a model onnxruntime refuses raises :class:`ModelIntegrityError`
    naming ``source`` (default: the path). ``optimized_model_path``: onnxruntime also saves
    there the graph it runs after its optimisations (the export's int8 report lists the
    operators the box really executes, e.g. QLinearConv, from it)."""
    source = source or (str(model) if not isinstance(model, bytes) else "<model bytes>")
    so = session_options(threads)
    if optimized_model_path is not None:
        so.optimized_model_filepath = str(optimized_model_path)
    if not isinstance(model, bytes):
        try:
            model = Path(model).read_bytes()
        except OSError as e:
            raise ModelIntegrityError(f"{source}: cannot read model file ({e.strerror or e})") from None
    try:
        return ort.InferenceSession(model, so, providers=["CPUExecutionProvider"])
    except Exception as e:  # onnxruntime raises its own exception types
        msg = str(e).strip().splitlines()[0] if str(e).strip() else type(e).__name__
        raise ModelIntegrityError(f"{source}: onnxruntime cannot load the model ({msg})") from None


def same_arrays(got: Sequence[np.ndarray], want: Sequence[np.ndarray]) -> bool:
    """Whether two lists of results are the same arrays, bit for bit (the check of the private paths here)."""
    return len(got) == len(want) and all(np.array_equal(a, b) for a, b in zip(got, want))


def fast_run(session: ort.InferenceSession, outputs: Sequence[str], feed: dict[str, np.ndarray],
             run_options: ort.RunOptions):
    """``session.run`` or, when this onnxruntime has it, the compiled session's own run under it (``_sess.run``,
    private): why: it skips the Python wrapper's check of the feed's names on every call, about 2 of a step's
    23 us at batch 1 on one thread, 2.6-6 % of the int8 lifter's bench call at any batch size
    (reports/bench/s18_ortperf/report.md). It is taken only if it accepts ``(outputs, feed, run_options)`` and
    gives exactly what ``session.run`` gives on ``feed``; any other onnxruntime (no ``_sess``, another signature,
    other results) gets the public call, the same results at the wrapper's cost."""
    inner = getattr(getattr(session, "_sess", None), "run", None)
    if callable(inner):
        try:
            if same_arrays(inner(list(outputs), feed, run_options), session.run(list(outputs), feed, run_options)):
                return inner
        except Exception:  # noqa: BLE001 - a private API that changed: the public call below is the contract
            pass
    return session.run


def session_from_manifest(assets_dir: str | os.PathLike = ASSETS_DIR, name_or_precision: str = "int8",
                          arch: str | tuple[str, ...] | None = None, threads: int = 1,
                          public_key_file: str | os.PathLike | None = None
                          ) -> tuple[ort.InferenceSession, dict, str]:
    """(session, manifest entry, model path) for the entry ``name_or_precision`` of ``arch``,
    loaded from the bytes whose sha256 was checked against the manifest (itself signature-checked
    with ``public_key_file``)."""
    entry, data, path = load_verified(assets_dir, name_or_precision, arch=arch, public_key_file=public_key_file)
    return open_session(data, threads, str(path)), entry, str(path)
