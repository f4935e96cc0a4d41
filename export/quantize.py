"""int8 quantisation with onnxruntime.quantization, chosen by measurement.

Calibration: a :class:`WindowReader` (``CalibrationDataReader``) over
preprocessed capture windows (N, 6, 33, 3) m/s^2 -- simulated ground-truth
windows of the training subjects, never the test windows. MinMax ranges.

Candidates (:data:`VARIANTS`), each built from the same fp32 graph after
``quant_pre_process`` (shape inference + ORT basic graph clean-up):

* ``dynamic``            quantize_dynamic on every supported op: Conv -> ConvInteger,
                         LSTM -> DynamicQuantizeLSTM, Gemm/MatMul -> MatMulInteger;
* ``qdq_conv``           static QDQ, per-channel int8 weights, uint8 activations, on the
                         conv stack (Conv, ReLU, MaxPool and the reshuffles up to the LSTM);
                         LSTM and the dense head stay fp32;
* ``qdq_conv_pt``        the same with per-tensor weights;
* ``qdq_conv_s8``        the same with int8 activations (S8S8);
* ``qdq_conv2``          static QDQ on the second conv only (first conv sees raw m/s^2);
* ``qdq_conv+dyn_lstm``  qdq_conv, then the LSTM dynamic (DynamicQuantizeLSTM);
* ``qdq_all``            static QDQ on the conv stack and the dense head (QGemm);
* ``qdq_all+dyn_lstm``   qdq_all, then DynamicQuantizeLSTM.

Every candidate has 7-bit weights (``reduce_range``): x86 CPUs without VNNI saturate u8 x s8
dot products with 8-bit weights, so a build faithful here could drift on a box; each candidate's
:func:`integer_kernel_drift` (integer kernels against the same QDQ graph in float) is recorded.

Choice (:func:`choose`): every candidate is timed on onnxruntime with one
intra-op thread at batch 1, interleaved in rounds so that they share the
machine's noise; candidates whose predictions drift from fp32 (argmax
agreement < ``MIN_AGREEMENT`` on held-back windows, or macro-F1 moved by more
than ``MAX_F1_DELTA`` when labels are given) are refused; the fastest of the
rest wins; candidates within 3 % of the fastest count as tied and the first
of them in :data:`VARIANTS` order wins (so timing noise does not flip the
choice between equally fast variants). The report
records every candidate's latency and drift, and which operators ended up
int8: graph op types, the op types onnxruntime actually runs after its
optimisations (QLinearConv, QGemm, DynamicQuantizeLSTM, ...), and per source
op type whether it computes in int8 or fp32.

Building, scoring and timing the candidates (:func:`compare_variants`) and the
fastest-with-ties rule (:func:`fastest`) are shared with the pose lifter's
export (``export.lifter_assets``), which brings its own candidates and scores
them by MPJPE instead of argmax agreement.
"""
from __future__ import annotations

import contextlib
import json
import logging
import tempfile
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import onnx
import onnxruntime as ort
from onnxruntime.quantization import (
    CalibrationDataReader,
    CalibrationMethod,
    QuantFormat,
    QuantType,
    quantize_dynamic,
    quantize_static,
)
from onnxruntime.quantization.shape_inference import quant_pre_process

from bench.timing import interleaved_calls
from edge_runtime.core.onnx import open_session, session_options
from export.onnx_export import INPUT_NAME, PROBS, get_metadata, op_counts, set_metadata
from export.opsets import declare_used_opsets
from export.variants import Variant

MIN_AGREEMENT = 0.98
MAX_F1_DELTA = 0.01
TIE = 0.03  # candidates within 3 % of the fastest count as equally fast (timing noise)

INTEGER_OPS = {"ConvInteger", "MatMulInteger", "DynamicQuantizeLSTM", "DynamicQuantizeMatMul",
               "MatMulIntegerToFloat", "QLinearConv", "QLinearMatMul", "QGemm", "QLinearAdd",
               "QLinearMul", "QLinearSoftmax", "QLinearGlobalAveragePool", "QLinearAveragePool",
               "QLinearConcat", "QLinearLeakyRelu", "QLinearSigmoid", "DynamicQuantizeLinear",
               "QuantizeLinear", "DequantizeLinear", "NhwcMaxPool", "QLinearReduceMean"}
_QUANT_IO = {"QuantizeLinear", "DequantizeLinear", "DynamicQuantizeLinear"}


class QuantizeError(ValueError):
    """Quantisation failed in a way the user can act on (one line)."""


# --------------------------------------------------------------------------- calibration data

class WindowReader(CalibrationDataReader):
    """Calibration batches of preprocessed windows (N, 6, 33, 3) float32 m/s^2."""

    def __init__(self, windows: np.ndarray, batch_size: int = 64, input_name: str = INPUT_NAME):
        self.windows = np.ascontiguousarray(windows, dtype=np.float32)
        self.batch_size = batch_size
        self.input_name = input_name
        self._i = 0

    def get_next(self):
        if self._i >= len(self.windows):
            return None
        b = self.windows[self._i:self._i + self.batch_size]
        self._i += self.batch_size
        return {self.input_name: b}

    def rewind(self):
        self._i = 0

    def __len__(self):
        return -(-len(self.windows) // self.batch_size)


class FeedReader(CalibrationDataReader):
    """Calibration batches given as feeds ({input name: array}), for a graph of several inputs (the
    ConvLSTM step model's sub-window and LSTM state: ``export.step_model.step_states``)."""

    def __init__(self, feeds: list[dict[str, np.ndarray]], batch_size: int = 64):
        self.items = [{k: np.ascontiguousarray(v[i:i + batch_size], dtype=np.float32) for k, v in f.items()}
                      for f in feeds for i in range(0, len(next(iter(f.values()))), batch_size)]
        self._i = 0

    def get_next(self):
        if self._i >= len(self.items):
            return None
        self._i += 1
        return self.items[self._i - 1]

    def rewind(self):
        self._i = 0


def pick_windows(y: np.ndarray, n: int, seed: int = 0) -> np.ndarray:
    """Indices of up to n windows, stratified by class (every class represented)."""
    y = np.asarray(y)
    rng = np.random.default_rng(seed)
    if len(y) <= n:
        return np.arange(len(y))
    classes, counts = np.unique(y, return_counts=True)
    quota = np.maximum(1, np.round(counts / counts.sum() * n)).astype(int)
    idx = []
    for c, q in zip(classes, quota):
        members = np.flatnonzero(y == c)
        idx.append(rng.choice(members, size=min(q, len(members)), replace=False))
    return np.sort(np.concatenate(idx))[:n]


# --------------------------------------------------------------------------- variants

def _first_conv(model: onnx.ModelProto) -> list[str]:
    return [n.name for n in model.graph.node if n.op_type == "Conv"][:1]


_CONV_STACK = ("Conv", "Relu", "MaxPool", "Squeeze", "Transpose", "Reshape", "Flatten")
VARIANTS: dict[str, Variant] = {v.name: v for v in (
    Variant("dynamic", "dynamic int8 on every supported op (ConvInteger, DynamicQuantizeLSTM, MatMulInteger)",
            dynamic_ops=("Conv", "LSTM", "MatMul", "Gemm")),
    Variant("qdq_conv", "static QDQ conv stack (per-channel int8 weights, uint8 activations); LSTM, head fp32",
            static_ops=_CONV_STACK),
    Variant("qdq_conv_pt", "static QDQ conv stack, per-tensor weights; LSTM, head fp32",
            static_ops=_CONV_STACK, per_channel=False),
    Variant("qdq_conv_s8", "static QDQ conv stack, int8 activations (S8S8); LSTM, head fp32",
            static_ops=_CONV_STACK, activation="int8"),
    Variant("qdq_conv2", "static QDQ on the second conv only; first conv, LSTM, head fp32",
            static_ops=_CONV_STACK, keep_fp32=_first_conv),
    Variant("qdq_conv+dyn_lstm", "static QDQ conv stack + dynamic LSTM (DynamicQuantizeLSTM); head fp32",
            static_ops=_CONV_STACK, dynamic_ops=("LSTM",)),
    Variant("qdq_all", "static QDQ conv stack and dense head (QGemm); LSTM fp32",
            static_ops=_CONV_STACK + ("Gemm", "MatMul")),
    Variant("qdq_all+dyn_lstm", "static QDQ conv stack and head + dynamic LSTM",
            static_ops=_CONV_STACK + ("Gemm", "MatMul"), dynamic_ops=("LSTM",)),
)}


def _preprocess_model(src: Path, dst: Path) -> Path:
    try:
        quant_pre_process(str(src), str(dst), skip_symbolic_shape=False)
    except Exception:  # symbolic shape inference can fail on exotic graphs: fall back
        quant_pre_process(str(src), str(dst), skip_symbolic_shape=True)
    return dst


@contextlib.contextmanager
def _quiet_root_logger():
    """onnxruntime.quantization logs advice on the root logger; keep the CLI output clean."""
    root = logging.getLogger()
    level = root.level
    root.setLevel(logging.ERROR)
    try:
        yield
    finally:
        root.setLevel(level)


def build_variant(fp32_path: str | Path, out_path: str | Path, variant: Variant | str,
                  calib: np.ndarray | list[dict[str, np.ndarray]], *, pre_processed: str | Path | None = None,
                  describe: bool = True, reduce_range: bool | None = None) -> Path:
    """Quantise ``fp32_path`` with ``variant`` into ``out_path``; metadata carried over.

    ``calib`` holds calibration inputs of the graph's (single) input, or feeds of all its inputs
    (a list of {input name: array}, :class:`FeedReader`). ``describe`` appends the
    variant's description to the doc string (the ConvLSTM assets carry it; the lifter's never
    did, and their bytes stay as shipped). ``reduce_range`` overrides the variant's (to rebuild
    an entry made before 7-bit weights, see :attr:`export.variants.Variant.reduce_range`)."""
    v = VARIANTS[variant] if isinstance(variant, str) else variant
    rr = v.reduce_range if reduce_range is None else reduce_range
    fp32_path, out_path = Path(fp32_path), Path(out_path)
    out_path.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as td:
        src = Path(pre_processed) if pre_processed else _preprocess_model(fp32_path, Path(td) / "pre.onnx")
        cur = src
        with warnings.catch_warnings(), _quiet_root_logger():
            warnings.simplefilter("ignore")
            if v.static:
                model = onnx.load(str(src))
                present = {n.op_type for n in model.graph.node}
                ops = None if v.static_ops is None else [o for o in v.static_ops if o in present]
                stage = Path(td) / "static.onnx"
                reader = FeedReader(calib) if isinstance(calib, list) else \
                    WindowReader(calib, input_name=model.graph.input[0].name)
                quantize_static(str(cur), str(stage), reader,
                                quant_format=QuantFormat.QDQ, op_types_to_quantize=ops, per_channel=v.per_channel,
                                activation_type=QuantType.QInt8 if v.activation == "int8" else QuantType.QUInt8,
                                weight_type=QuantType.QInt8, reduce_range=rr,
                                calibrate_method=CalibrationMethod.MinMax,
                                nodes_to_exclude=v.keep_fp32(model) if v.keep_fp32 else None,
                                extra_options={"CalibTensorRangeSymmetric": False})
                cur = stage
            if v.dynamic_ops:
                stage = Path(td) / "dynamic.onnx"
                quantize_dynamic(str(cur), str(stage), op_types_to_quantize=list(v.dynamic_ops),
                                 per_channel=False, weight_type=QuantType.QInt8, reduce_range=rr)
                cur = stage
        q = onnx.load(str(cur))
    meta = get_metadata(fp32_path)
    meta.update(precision="int8", quantization=v.name)
    set_metadata(q, meta)
    if describe:
        q.doc_string = onnx.load(str(fp32_path), load_external_data=False).doc_string + f" [int8: {v.description}]"
    declare_used_opsets(q)  # the quantiser declares nine domains; older onnxruntimes refuse some
    out_path.write_bytes(q.SerializeToString(deterministic=True))
    return out_path


# --------------------------------------------------------------------------- what became int8

def runtime_op_types(model_path: str | Path) -> dict[str, int]:
    """Op types onnxruntime runs after its graph optimisations (level ALL, CPU provider)."""
    with tempfile.TemporaryDirectory() as td:
        optimized = Path(td) / "opt.onnx"
        open_session(model_path, optimized_model_path=optimized)
        return op_counts(onnx.load(str(optimized)))


def int8_report(model_path: str | Path) -> dict:
    """Which source operators compute in int8, which stay fp32, and what onnxruntime runs."""
    m = onnx.load(str(model_path))
    g = m.graph
    producers = {o: n for n in g.node for o in n.output}
    consumers: dict[str, list] = {}
    for n in g.node:
        for i in n.input:
            consumers.setdefault(i, []).append(n)
    inits = {i.name for i in g.initializer}
    graph_outputs = {o.name for o in g.output}
    int8: dict[str, int] = {}
    fp32: dict[str, int] = {}
    integer_map = {"ConvInteger": "Conv", "MatMulInteger": "MatMul", "DynamicQuantizeLSTM": "LSTM",
                   "DynamicQuantizeMatMul": "MatMul", "QLinearConv": "Conv", "QLinearMatMul": "MatMul",
                   "QGemm": "Gemm"}
    for n in g.node:
        if n.op_type in _QUANT_IO:
            continue
        if n.op_type in integer_map or n.op_type.startswith("QLinear"):
            key = integer_map.get(n.op_type, n.op_type.replace("QLinear", ""))
            int8[key] = int8.get(key, 0) + 1
            continue
        if n.op_type in ("Cast", "Mul", "Add") and any(
                p is not None and p.op_type in ("ConvInteger", "MatMulInteger", "DynamicQuantizeLinear")
                for p in (producers.get(i) for i in n.input)):
            continue  # rescaling glue of dynamic quantisation
        data_in = [i for i in n.input if i and i not in inits and
                   not (producers.get(i) is not None and producers[i].op_type == "Constant")]
        ins_q = bool(data_in) and all(producers.get(i) is not None and producers[i].op_type == "DequantizeLinear"
                                      for i in data_in)
        outs_q = all(o not in graph_outputs and consumers.get(o) and
                     all(c.op_type == "QuantizeLinear" for c in consumers[o]) for o in n.output if o)
        if ins_q and outs_q:
            int8[n.op_type] = int8.get(n.op_type, 0) + 1
        else:
            fp32[n.op_type] = fp32.get(n.op_type, 0) + 1
    return {"int8_operators": dict(sorted(int8.items())), "fp32_operators": dict(sorted(fp32.items())),
            "graph_op_types": op_counts(m), "runtime_op_types": runtime_op_types(model_path)}


# --------------------------------------------------------------------------- measurement

def latency_stats(times_ns: np.ndarray) -> dict:
    """Median, 99th percentile and mean of per-call times in microseconds, and how many calls."""
    return {"p50_us": float(np.median(times_ns) / 1e3), "p99_us": float(np.percentile(times_ns, 99) / 1e3),
            "mean_us": float(times_ns.mean() / 1e3), "n": int(len(times_ns))}


def integer_kernel_drift(model_path: str | Path, feed: dict[str, np.ndarray]) -> float:
    """Mean absolute difference, over all outputs at ``feed``, between onnxruntime running the int8
    graph with its integer kernels (QLinearConv, QGemm, ...: what the box runs) and the same QDQ
    graph computed in float (graph optimisations off: DequantizeLinear, the fp32 op, QuantizeLinear).
    Near 0 where the CPU's int8 dot products are exact; large where they saturate (u8 x s8 with
    8-bit weights on x86 without VNNI, :attr:`export.variants.Variant.reduce_range`). The drift of
    a dynamic graph is 0 by construction (its integer ops have no float form)."""
    so = session_options(1)
    so.graph_optimization_level = ort.GraphOptimizationLevel.ORT_DISABLE_ALL
    as_float = ort.InferenceSession(str(model_path), so, providers=["CPUExecutionProvider"])
    integer = open_session(model_path)
    return float(np.mean([np.abs(a - b).mean() for a, b in zip(integer.run(None, feed), as_float.run(None, feed))]))


def _probe(calib: np.ndarray | list[dict[str, np.ndarray]], input_name: str, n: int = 64) -> dict[str, np.ndarray]:
    """The first ``n`` calibration inputs as a feed (realistic, and inside the calibrated ranges)."""
    first = calib[0] if isinstance(calib, list) else {input_name: calib}
    return {k: np.ascontiguousarray(v[:n], dtype=np.float32) for k, v in first.items()}


@dataclass
class Comparison:
    """What :func:`compare_variants` found.

    ``paths``: the variants that built and quantised something; ``results``: per variant, its
    description, the caller's scores, ``size_bytes`` and :func:`int8_report` (or only ``error``);
    ``latency``: :func:`latency_stats` of "fp32" and of every variant in ``paths``."""

    paths: dict[str, Path]
    results: dict[str, dict]
    latency: dict[str, dict]


def compare_variants(fp32_path: str | Path, variants: Sequence[Variant], calib: np.ndarray, out_dir: str | Path, *,
                     score: Callable[[ort.InferenceSession], dict], feed: dict[str, np.ndarray],
                     outputs: list[str] | None = None, threads: int = 1, n_timing: int, warmup: int,
                     stem: str = "", describe: bool = True, log: Callable[[str], None] = lambda s: None
                     ) -> Comparison:
    """Build every variant of ``fp32_path`` into ``out_dir/<stem><name>.onnx``, score each
    (``score(session)``: the caller's accuracy against fp32), then time fp32 and the variants at
    ``feed`` on ``threads`` onnxruntime thread(s), interleaved in rounds so that they share the
    machine's noise. A variant the graph does not support is skipped, not fatal. Each result also
    records the variant's ``reduce_range`` and its :func:`integer_kernel_drift` on this CPU at
    the first calibration inputs."""
    fp32_path, out_dir = Path(fp32_path), Path(out_dir)
    paths: dict[str, Path] = {}
    results: dict[str, dict] = {}
    sessions = {"fp32": open_session(fp32_path, threads)}
    probe = _probe(calib, sessions["fp32"].get_inputs()[0].name)
    with tempfile.TemporaryDirectory() as td:
        pre = _preprocess_model(fp32_path, Path(td) / "pre.onnx")
        for v in variants:
            path = out_dir / f"{stem}{v.name}.onnx"
            try:
                build_variant(fp32_path, path, v, calib, pre_processed=pre, describe=describe)
            except Exception as e:  # onnxruntime.quantization raises whatever its passes raise
                results[v.name] = {"error": f"{type(e).__name__}: {str(e).splitlines()[0] if str(e) else ''}"}
                log(f"  {v.name}: failed ({results[v.name]['error']})")
                continue
            rep = int8_report(path)
            if not rep["int8_operators"]:
                results[v.name] = {"error": "no operator was quantised"}
                continue
            paths[v.name] = path
            sessions[v.name] = open_session(path, threads)
            results[v.name] = {"description": v.description, **score(sessions[v.name]),
                               "reduce_range": v.reduce_range, "size_bytes": path.stat().st_size,
                               "integer_kernel_drift": integer_kernel_drift(path, probe), **rep}
    runners = {k: (lambda s=s: s.run(outputs, feed)) for k, s in sessions.items()}
    times = interleaved_calls(runners, n_timing, rounds=5, warmup=warmup)
    return Comparison(paths, results, {k: latency_stats(t) for k, t in times.items()})


def fastest(p50_us: dict[str, float], among: Sequence[str], tie: float = 0.0) -> str:
    """The fastest of ``among``; of those within ``tie`` (a fraction) of it, the first in
    ``among``'s order (so that timing noise does not flip a choice between equally fast ones)."""
    best = min(p50_us[k] for k in among)
    return next(k for k in among if p50_us[k] <= best * (1 + tie))


def _macro_f1(y_true: np.ndarray, y_pred: np.ndarray) -> float:
    labels = np.union1d(y_true, y_pred)
    f1 = []
    for c in labels:
        tp = np.sum((y_pred == c) & (y_true == c))
        fp = np.sum((y_pred == c) & (y_true != c))
        fn = np.sum((y_pred != c) & (y_true == c))
        f1.append(2 * tp / (2 * tp + fp + fn) if tp + fp + fn else 0.0)
    return float(np.mean(f1)) if f1 else float("nan")


def probs_of(model: str | Path | ort.InferenceSession, x: np.ndarray, batch: int = 512) -> np.ndarray:
    s = model if isinstance(model, ort.InferenceSession) else open_session(model)
    return np.concatenate([s.run([PROBS], {INPUT_NAME: x[i:i + batch]})[0] for i in range(0, len(x), batch)])


def choose(fp32_path: str | Path, out_path: str | Path, calib: np.ndarray, *, eval_x: np.ndarray,
           eval_y: np.ndarray | None = None, variants: Sequence[str] | None = None, threads: int = 1,
           n_timing: int = 3000, log: Callable[[str], None] = lambda s: None,
           early_min_agreement: float | None = None, early_steps: Sequence[int] = (1, 2, 3, 4, 5),
           min_agreement: float = MIN_AGREEMENT) -> dict:
    """Build every candidate, time and check each, keep the fastest faithful one at ``out_path``.
    With ``early_min_agreement``, a candidate must also agree with fp32 on that share of the
    early decisions, the first S (``early_steps``) of the 6 sub-windows of ``eval_x`` (the
    ConvLSTM's dynamic-S input): after few steps many decisions are near ties that int8 can flip.
    ``min_agreement``: the argmax agreement with fp32 a candidate needs on ``eval_x``.

    Returns the quantisation report (JSON-ready)."""
    fp32_path, out_path = Path(fp32_path), Path(out_path)
    names = list(variants or VARIANTS)
    for v in names:
        if v not in VARIANTS:
            raise QuantizeError(f"unknown quantisation variant {v!r}; choose from {', '.join(VARIANTS)}")
    eval_x = np.ascontiguousarray(eval_x, np.float32)
    early_refs = None if early_min_agreement is None else {
        s: probs_of(fp32_path, np.ascontiguousarray(eval_x[:, :s])) for s in early_steps}
    with tempfile.TemporaryDirectory() as td:
        comp = compare_variants(fp32_path, [VARIANTS[n] for n in names], calib, td,
                                score=_drift_from(probs_of(fp32_path, eval_x), eval_x, eval_y, early_refs),
                                feed={INPUT_NAME: np.ascontiguousarray(eval_x[:1])}, outputs=[PROBS],
                                threads=threads, n_timing=n_timing, warmup=200, log=log)
        ok = _faithful(comp, eval_y, log, early_min_agreement, min_agreement)
        if not ok:
            raise QuantizeError(f"{fp32_path}: no int8 variant keeps predictions within "
                                f"agreement {min_agreement} / macro-F1 {MAX_F1_DELTA} of fp32")
        chosen = fastest({k: comp.latency[k]["p50_us"] for k in ok}, ok, TIE)
        out_path.parent.mkdir(parents=True, exist_ok=True)
        out_path.write_bytes(comp.paths[chosen].read_bytes())
    return _choice_report(chosen, comp, n_calib=len(calib), n_eval=len(eval_x), labelled=eval_y is not None,
                          threads=threads, early_min_agreement=early_min_agreement, early_steps=early_steps,
                          min_agreement=min_agreement)


def _drift_from(ref_probs: np.ndarray, eval_x: np.ndarray, eval_y: np.ndarray | None,
                early_refs: dict[int, np.ndarray] | None = None) -> Callable[[ort.InferenceSession], dict]:
    """The score of a variant: argmax agreement with fp32's ``ref_probs`` and the largest
    probability change on ``eval_x``; with labels, macro-F1 and its change from fp32's; with
    ``early_refs`` (fp32's probabilities on the first S sub-windows, by S), the smallest
    agreement over those prefixes."""
    ref_pred = ref_probs.argmax(1)
    f1_fp32 = _macro_f1(np.asarray(eval_y), ref_pred) if eval_y is not None else None

    def score(session: ort.InferenceSession) -> dict:
        pr = probs_of(session, eval_x)
        pred = pr.argmax(1)
        r = {"agreement": float(np.mean(pred == ref_pred)), "max_abs_probs": float(np.abs(pr - ref_probs).max())}
        if eval_y is not None:
            r["macro_f1"] = _macro_f1(np.asarray(eval_y), pred)
            r["macro_f1_delta"] = r["macro_f1"] - f1_fp32
        if early_refs:
            r["early_agreement"] = min(
                float(np.mean(probs_of(session, np.ascontiguousarray(eval_x[:, :s])).argmax(1) == ref.argmax(1)))
                for s, ref in early_refs.items())
        return r

    return score


def _faithful(comp: Comparison, eval_y: np.ndarray | None, log: Callable[[str], None],
              early_min_agreement: float | None = None, min_agreement: float = MIN_AGREEMENT) -> list[str]:
    """The variants whose predictions stay with fp32's, in candidate order; each variant's
    result gains its latency and ``accepted``, and a log line."""
    ok = []
    for k in comp.paths:
        r = comp.results[k]
        r.update(comp.latency[k])
        r["accepted"] = (r["agreement"] >= min_agreement
                         and (eval_y is None or abs(r["macro_f1_delta"]) <= MAX_F1_DELTA)
                         and (early_min_agreement is None or r["early_agreement"] >= early_min_agreement))
        if r["accepted"]:
            ok.append(k)
        log(f"  {k:18s} p50 {r['p50_us']:7.1f} us  agreement {r['agreement']:.4f}"
            + (f"  dF1 {r['macro_f1_delta']:+.4f}" if eval_y is not None else "")
            + (f"  early {r['early_agreement']:.4f}" if "early_agreement" in r else "")
            + ("" if r["accepted"] else "  (refused)"))
    return ok


def _choice_report(chosen: str, comp: Comparison, *, n_calib: int, n_eval: int, labelled: bool, threads: int,
                   early_min_agreement: float | None = None, early_steps: Sequence[int] = (),
                   min_agreement: float = MIN_AGREEMENT) -> dict:
    """The quantisation report of :func:`choose` (the manifest's ``quantization``)."""
    c, v = comp.results[chosen], VARIANTS[chosen]
    return {
        "method": chosen,
        "description": c["description"],
        "format": "QDQ" if v.static else "dynamic",
        "dynamic_ops": list(v.dynamic_ops),
        "per_channel": v.per_channel if v.static else False,
        "activation_type": v.activation,
        "weight_type": "int8",
        "reduce_range": v.reduce_range,
        "integer_kernel_drift": c["integer_kernel_drift"],
        "calibration": {"method": "MinMax", "windows": int(n_calib),
                        "reader": "export.quantize.WindowReader (preprocessed capture windows)"},
        "pre_process": "onnxruntime.quantization.shape_inference.quant_pre_process",
        "int8_operators": c["int8_operators"],
        "fp32_operators": c["fp32_operators"],
        "graph_op_types": c["graph_op_types"],
        "runtime_op_types": c["runtime_op_types"],
        "agreement_with_fp32": c["agreement"],
        "selection": {"rule": f"fastest p50 at batch 1 with {threads} thread(s) among variants with argmax "
                              f"agreement >= {min_agreement}" + (f" and |dF1| <= {MAX_F1_DELTA}" if labelled else "")
                              + (f" and argmax agreement >= {early_min_agreement} after every S in "
                                 f"{list(early_steps)} sub-windows" if early_min_agreement is not None else "")
                              + f"; variants within {TIE:.0%} of the fastest are tied and the first in the "
                              "candidate order wins",
                      "eval_windows": int(n_eval), "threads": threads, "fp32": comp.latency["fp32"],
                      "candidates": {k: {f: v for f, v in r.items() if f not in ("graph_op_types", "fp32_operators")}
                                     for k, r in comp.results.items()}},
        "onnxruntime": ort.__version__,
    }


def quantize_file(fp32_path: str | Path, calib_npz: str | Path, out_path: str | Path, *,
                  n_calib: int = 1000, seed: int = 0, variants: Sequence[str] | None = None,
                  log: Callable[[str], None] = lambda s: None) -> dict:
    """CLI path: calibrate on part of an NPZ of capture windows, check on the rest, choose."""
    from edge_runtime.wearable.classifier import preprocess
    from models.dataset import load_npz

    ws = load_npz(calib_npz)
    meta = get_metadata(fp32_path)
    if "classes" in meta and json.loads(meta["classes"]) != list(ws.classes):
        raise QuantizeError(f"{calib_npz}: field 'classes': {list(ws.classes)} differ from the model's "
                            f"{json.loads(meta['classes'])}")
    X = preprocess(ws.X)
    idx = pick_windows(ws.y, n_calib, seed)
    rest = np.setdiff1d(np.arange(len(X)), idx)
    held = rest if len(rest) >= 50 else np.arange(len(X))
    return choose(fp32_path, out_path, X[idx], eval_x=X[held], eval_y=ws.y[held], variants=variants, log=log)
