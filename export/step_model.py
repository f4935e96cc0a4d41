"""The ConvLSTM as a streaming step model: one sub-window and the LSTM state in, the decision and
the next state out (issues 12 and 15).

The conv stack reads each of the 6 sub-windows alone and the LSTM is causal, so the decision after
S sub-windows is the conv features of sub-window S, one LSTM cell step from the state after S - 1,
and the head. The box runs this graph once per sub-window as it arrives instead of the whole model
on the prefix each time.

Graph contract (``python -m export assets`` builds it from the same checkpoint as the one-shot model):

* inputs  ``imu`` float32 (N, 33, 3): one sub-window in m/s^2 (a row of
  ``edge_runtime.wearable.classifier.preprocess``'s (N, 6, 33, 3)); ``h``, ``c`` float32 (N, 100):
  the LSTM state after the previous sub-windows (zeros before the first);
* outputs ``probs`` float32 (N, K): the softmax of the decision after this sub-window; ``h_out``,
  ``c_out`` (N, 100): the state to pass with the next sub-window.

The LSTM cell is written out as MatMul, Add, Sigmoid, Tanh and Mul (not an ONNX ``LSTM`` node), so
that onnxruntime's static quantiser can make its two matmuls int8 (QDQ) like the conv stack; the
cell's element-wise arithmetic and the state stay fp32. Gate order is PyTorch's (i, f, g, o).
"""
from __future__ import annotations

import io
import warnings
from pathlib import Path
from typing import Callable, Sequence

import numpy as np
import onnx
import torch
import torch.nn.functional as F
from torch import nn

from edge_runtime.core.manifest import STEP_ARCH
from edge_runtime.wearable.classifier import STEP_INPUTS, STEP_OUTPUTS, zero_state
from edge_runtime.wearable.classifier import run_steps as runtime_run_steps
from export.onnx_export import (
    DEFAULT_OPSET,
    PROBS,
    ExportError,
    _prune_dead,
    model_metadata,
    package_version,
    set_metadata,
)
from models import nets

# the graph's names are the runtime's (edge_runtime.wearable.classifier.StepModel reads them)
INPUT_NAME, H_IN, C_IN = STEP_INPUTS
_, H_OUT, C_OUT = STEP_OUTPUTS
STEP_INPUT_LAYOUT = ("N,33,3 (one sub-window: frame, axis x/y/z), m/s^2; h, c (N,hidden): the LSTM state after "
                     "the sub-windows before it (zeros before the first)")
PARITY_TOL = 1e-4


class StepConvLSTM(nn.Module):
    """(sub-window (N, 33, 3), h, c) -> (probs, h', c') with the weights of a ``nets.ConvLSTM``.

    Written for few graph nodes, since each costs onnxruntime about a microsecond at batch 1: the
    conv stack as Conv1d over (N, 3, 33) (the input scale 1/g folded into the first conv), the
    global max as one MaxPool, the two gate matmuls as one Gemm over [features, h] with the two
    PyTorch biases summed, and the gates reordered (i, f, o | g) so that one Sigmoid covers three."""

    def __init__(self, m: nets.ConvLSTM):
        super().__init__()
        lstm = m.lstm
        if lstm.num_layers != 1 or lstm.bidirectional or lstm.proj_size or not lstm.bias:
            raise ExportError("only a single-layer unidirectional LSTM with biases is exported as a step model")
        conv = [c for c in m.features.conv if isinstance(c, nn.Conv1d)]
        if len(conv) != 2:
            raise ExportError(f"expected 2 Conv1d layers in the feature stack, found {len(conv)}")
        self.c1, self.c2 = (_conv1d_copy(c, s) for c, s in zip(conv, (1.0 / nets.ACC_SCALE_MPS2, 1.0)))
        self.pool_t = nets.SUBSEQ_FRAMES - sum(c.kernel_size[0] - 1 for c in conv)
        hid = self.hidden = lstm.hidden_size
        order = torch.cat([torch.arange(0, 2 * hid), torch.arange(3 * hid, 4 * hid), torch.arange(2 * hid, 3 * hid)])
        with torch.no_grad():  # PyTorch's gate rows (i, f, g, o) -> (i, f, o, g)
            w = torch.cat([lstm.weight_ih_l0, lstm.weight_hh_l0], dim=1)[order]
            self.gates = nn.Linear(w.shape[1], 4 * hid)
            self.gates.weight.copy_(w)
            self.gates.bias.copy_((lstm.bias_ih_l0 + lstm.bias_hh_l0)[order])
        self.head = m.head

    def forward(self, x, h, c):
        y = torch.relu(self.c2(torch.relu(self.c1(x.transpose(1, 2)))))  # (N, C, 29)
        f = F.max_pool1d(y, self.pool_t).flatten(1)  # (N, C): the global max over time
        ifo, g = self.gates(torch.cat([f, h], dim=1)).split([3 * self.hidden, self.hidden], dim=1)
        i, fg, o = torch.sigmoid(ifo).split(self.hidden, dim=1)
        c_new = fg * c + i * torch.tanh(g)
        h_new = o * torch.tanh(c_new)
        return torch.softmax(self.head(h_new), dim=1), h_new, c_new


def _conv1d_copy(conv: nn.Conv1d, scale: float) -> nn.Conv1d:
    """The same Conv1d with its input scaled by ``scale`` (folded into the weights)."""
    out = nn.Conv1d(conv.in_channels, conv.out_channels, conv.kernel_size[0])
    with torch.no_grad():
        out.weight.copy_(conv.weight.detach() * scale)
        out.bias.copy_(conv.bias.detach())
    return out


def to_step_onnx(model: nets.ConvLSTM, classes: Sequence[str], *, opset: int = DEFAULT_OPSET,
                 model_version: str | None = None, commit: str | None = None, extra_meta: dict | None = None
                 ) -> onnx.ModelProto:
    """The step graph of a trained ConvLSTM (same weights), with metadata."""
    if type(model) is not nets.ConvLSTM:
        raise ExportError(f"a step model needs a ConvLSTM, got {type(model).__name__}")
    step = StepConvLSTM(model.eval()).eval()
    hidden = step.hidden
    x = torch.zeros(2, nets.SUBSEQ_FRAMES, nets.N_CHANNELS)
    h = torch.zeros(2, hidden)
    buf = io.BytesIO()
    with warnings.catch_warnings(), torch.no_grad():
        warnings.simplefilter("ignore")
        torch.onnx.export(step, (x, h, h.clone()), buf, dynamo=False, opset_version=opset, do_constant_folding=True,
                          input_names=[INPUT_NAME, H_IN, C_IN], output_names=[PROBS, H_OUT, C_OUT],
                          dynamic_axes={k: {0: "N"} for k in (INPUT_NAME, H_IN, C_IN, PROBS, H_OUT, C_OUT)})
    onx = onnx.load_from_string(buf.getvalue())
    _prune_dead(onx.graph)
    onx.producer_name = "edge-safety-export"
    onx.producer_version = package_version()
    onx.doc_string = (f"convlstm wearable distraction classifier, one step per sub-window: inputs {INPUT_NAME}, "
                      f"{H_IN}, {C_IN} ({STEP_INPUT_LAYOUT}); outputs {PROBS} softmax over {list(classes)}, "
                      f"{H_OUT}, {C_OUT}")
    meta = model_metadata(model, classes, arch=STEP_ARCH, model_version=model_version, commit=commit,
                          extra=extra_meta)
    meta.update(input_layout=STEP_INPUT_LAYOUT, hidden=str(hidden),
                outputs=f"{PROBS}: softmax (N,K) in classes order; {H_OUT}, {C_OUT}: the LSTM state (N,{hidden})")
    set_metadata(onx, meta)
    onnx.checker.check_model(onx)
    return onx


def state_size(session) -> int:
    """The LSTM state size of an onnxruntime step session (its ``h`` input's last dimension)."""
    return next(i.shape[-1] for i in session.get_inputs() if i.name == H_IN)


def session_step(session) -> Callable[[np.ndarray, np.ndarray, np.ndarray], list[np.ndarray]]:
    """``(x, h, c) -> (probs, h', c')`` by an onnxruntime step session's public run."""
    outputs = list(STEP_OUTPUTS)
    return lambda x, h, c: session.run(outputs, {INPUT_NAME: x, H_IN: h, C_IN: c})


def _subs(X: np.ndarray) -> list[np.ndarray]:
    return [X[:, s] for s in range(np.shape(X)[1])]


def run_steps(session, X: np.ndarray) -> np.ndarray:
    """(S, N, K): an onnxruntime step session run over sub-windows X (N, S, 33, 3) from the zero state
    (the runtime's own loop, ``edge_runtime.wearable.classifier.run_steps``)."""
    return np.stack(runtime_run_steps(session_step(session), _subs(X), state_size(session)))


def step_states(session, X: np.ndarray) -> list[dict[str, np.ndarray]]:
    """The step model's feeds (sub-window, state before it) over sub-windows X (N, S, 33, 3): its
    calibration inputs, the states those windows really lead to."""
    feeds = []
    run = session_step(session)

    def step(x, h, c):
        feeds.append({INPUT_NAME: x, H_IN: h, C_IN: c})
        return run(x, h, c)

    runtime_run_steps(step, _subs(X), state_size(session))
    return feeds


def check_step_parity(model: nets.ConvLSTM, onx: onnx.ModelProto, X: np.ndarray, tol: float = PARITY_TOL) -> dict:
    """Max |probs| between the step graph run S = 1..6 times and the torch ConvLSTM on every prefix."""
    from edge_runtime.core.onnx import open_session

    sess = open_session(onx.SerializeToString())
    X = np.asarray(X, np.float32)
    steps = run_steps(sess, X)
    with torch.no_grad():
        ref = torch.softmax(model.eval()(torch.from_numpy(X), all_steps=True), dim=2).numpy()  # (N, S, K)
    d = float(np.abs(steps - ref.transpose(1, 0, 2)).max())
    return {"max_abs_probs": d, "n": int(len(X)), "steps": int(X.shape[1]), "tol": tol, "ok": bool(d < tol)}


# --------------------------------------------------------------------------- int8

STEP_CANDIDATES = ("qdq_conv2", "qdq_conv", "qdq_conv_s8", "qdq_all")
"""The int8 recipes tried on the step graph (``export.quantize.VARIANTS``): the conv stack static QDQ
with the first conv fp32 (the one-shot model's recipe), the whole conv stack, the same with int8
activations, and the conv stack plus the gate and head Gemms (the LSTM's matmuls int8; its state and
element-wise arithmetic stay fp32 in every candidate)."""


def quantise_step(fp32_path: Path, int8_path: Path, calib_X: np.ndarray, eval_X: np.ndarray, eval_y: np.ndarray, *,
                  gate_steps: Sequence[int], min_agreement: float, max_f1_delta: float = 0.01,
                  candidates: Sequence[str] = STEP_CANDIDATES, n_timing: int = 3000,
                  log=lambda s: None) -> dict:
    """Every candidate built (calibrated on the states ``calib_X``'s sub-windows lead to), run over the
    6 sub-windows of ``eval_X`` step by step and compared with fp32: accepted when its class agrees
    with fp32's on >= ``min_agreement`` of the decisions after every S in ``gate_steps`` and its
    full-window macro-F1 is within ``max_f1_delta``; the fastest accepted one (batch 1, 1 thread,
    ties within ``export.quantize.TIE`` to the first in candidate order) is written to ``int8_path``.
    Returns the quantisation report; raises QuantizeError when none is accepted."""
    import tempfile

    from edge_runtime.core.onnx import open_session
    from export.quantize import TIE, VARIANTS, QuantizeError, _macro_f1, compare_variants, fastest

    fp32 = open_session(fp32_path)
    ref = run_steps(fp32, eval_X)
    f1_ref = [_macro_f1(eval_y, p.argmax(1)) for p in ref]

    def score(session) -> dict:
        out = run_steps(session, eval_X)
        agree = {str(s + 1): float(np.mean(out[s].argmax(1) == ref[s].argmax(1))) for s in range(len(out))}
        f1 = [_macro_f1(eval_y, p.argmax(1)) for p in out]
        return {"agreement_by_steps": agree, "macro_f1_by_steps": {str(s + 1): v for s, v in enumerate(f1)},
                "macro_f1_delta": f1[-1] - f1_ref[-1], "max_abs_probs": float(np.abs(out - ref).max())}

    feeds = step_states(fp32, calib_X)
    h, c = zero_state(1, state_size(fp32))
    feed = {INPUT_NAME: np.ascontiguousarray(eval_X[:1, 0]), H_IN: h, C_IN: c}
    with tempfile.TemporaryDirectory() as td:
        comp = compare_variants(fp32_path, [VARIANTS[k] for k in candidates], feeds, td, score=score, feed=feed,
                                outputs=[PROBS, H_OUT, C_OUT], n_timing=n_timing, warmup=200, stem="step-", log=log)
        ok = []
        for k in comp.paths:
            r = comp.results[k]
            r.update(comp.latency[k])
            worst = min(r["agreement_by_steps"][str(s)] for s in gate_steps)
            r["accepted"] = worst >= min_agreement and abs(r["macro_f1_delta"]) <= max_f1_delta
            ok += [k] if r["accepted"] else []
            log(f"  step {k:14s} p50 {r['p50_us']:6.1f} us  agreement after S = {list(gate_steps)} >= {worst:.4f}  "
                f"dF1 {r['macro_f1_delta']:+.4f}" + ("" if r["accepted"] else "  (refused)"))
        if not ok:
            raise QuantizeError(f"{fp32_path}: no int8 step model agrees with fp32 on >= {min_agreement} of the "
                                f"decisions after {list(gate_steps)} sub-windows with macro-F1 within {max_f1_delta}")
        chosen = fastest({k: comp.latency[k]["p50_us"] for k in ok}, ok, TIE)
        int8_path.write_bytes(comp.paths[chosen].read_bytes())
    c = comp.results[chosen]
    keep = ("int8_operators", "fp32_operators", "runtime_op_types", "agreement_by_steps", "macro_f1_by_steps",
            "macro_f1_delta", "reduce_range", "integer_kernel_drift")
    return {"method": chosen, "description": c["description"], **{k: c[k] for k in keep},
            "calibration": {"method": "MinMax", "windows": int(len(calib_X)),
                            "reader": "export.quantize.FeedReader: each sub-window with the fp32 state before it"},
            "selection": {"rule": f"fastest p50 at batch 1 with 1 thread among candidates whose class agrees with "
                                  f"fp32 on >= {min_agreement} of the decisions after every S in {list(gate_steps)} "
                                  f"sub-windows and whose full-window macro-F1 is within {max_f1_delta}; candidates "
                                  f"within {TIE:.0%} of the fastest are tied and the first in order wins",
                          "eval_windows": int(len(eval_X)), "fp32": comp.latency["fp32"],
                          "candidates": {k: {f: v for f, v in r.items() if f not in ("graph_op_types", "fp32_operators")}
                                         for k, r in comp.results.items()}}}
