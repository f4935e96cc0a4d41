"""torch -> ONNX for every neural architecture of ``models.nets``.

Graph contract (what ``edge_runtime.core.onnx`` and integrators rely on)
---------------------------------------------------------------------
* input  ``imu``    float32 (N, 6, 33, 3): 6 subsequences x 33 frames x axis x/y/z, m/s^2
  (``edge_runtime.wearable.classifier.preprocess`` of a 700-frame capture at 100 Hz); for the
  ConvLSTM (N, S, 33, 3) with S = 1..6 a dynamic axis: the first S sub-windows, and ``probs``
  is the decision after them (S = 6: the full capture; issue 12's early decisions);
* output ``probs``  float32 (N, K): softmax, appended in the graph;
* output ``logits`` float32 (N, K): the pre-softmax scores (parity checks, calibration);
* the batch axis N is dynamic; opset 17 by default;
* metadata_props: ``classes`` (JSON), ``input_layout``, ``sample_rate_hz``,
  ``resampled_rate_hz``, ``model_version``, ``arch``, ``parameters_torch``,
  ``parameters_keras``, ``git_commit``, ``precision`` ... (see :func:`model_metadata`).

Export-friendly rewrites
------------------------
The training modules are written for readability; for export each one is
re-expressed as an equivalent module with the *same weights* whose graph is
lean and static apart from the batch axis (no Shape/Gather/Concat chains, no
zero-state ConstantOfShape) -- every node costs microseconds at batch 1:

* the input scale 1/g (``ACC_SCALE_MPS2``) is folded into the first layer's weights;
* Conv1d over the 33 frames of each subsequence becomes Conv2d with a (1, 3)
  kernel over (N, 3, 6, 33): the input (N, 6, 33, 3) is already NHWC, so
  onnxruntime's layout passes cancel the transposes;
* the global max over time becomes MaxPool (1, 29) (int8-capable in onnxruntime);
* the LSTM runs time-major and stays one ONNX ``LSTM`` node (TorchScript
  exporter, ``dynamo=False``); its zero initial state is dropped from the graph
  (ONNX's default initial state is zero).

:func:`check_parity` compares the ONNX graph with the *original* module in
eval mode (max |delta| of logits and probs; must be < 1e-4).
"""
from __future__ import annotations

import io
import json
import subprocess
import warnings
from pathlib import Path
from typing import Sequence

import numpy as np
import onnx
import torch
import torch.nn.functional as F
from torch import nn

from edge_runtime.wearable.classifier import CAPTURE_FRAMES, DOWN, MODEL_INPUT_SHAPE, RESAMPLED_FRAMES, UP
from export.opsets import declare_used_opsets
from models import nets

DEFAULT_OPSET = 17
PARITY_TOL = 1e-4
INPUT_NAME, PROBS, LOGITS = "imu", "probs", "logits"
INPUT_LAYOUT = "N,6,33,3 (subsequence, frame, axis x/y/z), m/s^2"
EARLY_INPUT_LAYOUT = ("N,S,33,3 (the first S = 1..6 of the capture's 6 subsequences, frame, axis x/y/z), m/s^2; "
                      "S is dynamic: S = 6 is the full-capture decision, fewer an early one")
EARLY_ARCHS = ("convlstm",)
"""Architectures whose input's subsequence axis is dynamic (a causal LSTM over sub-windows)."""


def input_layout(arch: str) -> str:
    return EARLY_INPUT_LAYOUT if arch in EARLY_ARCHS else INPUT_LAYOUT
SAMPLE_RATE_HZ = 100
RESAMPLED_RATE_HZ = SAMPLE_RATE_HZ * UP / DOWN  # 200/7
REPO_ROOT = Path(__file__).resolve().parent.parent


class ExportError(ValueError):
    """Export failed in a way the user can act on (one line)."""


# --------------------------------------------------------------------------- export-friendly modules

def _conv2d_from(conv: nn.Conv1d, scale: float = 1.0) -> nn.Conv2d:
    c = nn.Conv2d(conv.in_channels, conv.out_channels, (1, conv.kernel_size[0]))
    with torch.no_grad():
        c.weight.copy_(conv.weight.detach().unsqueeze(2) * scale)
        c.bias.copy_(conv.bias.detach())
    return c


class _ConvStack(nn.Module):
    """(N, 6, 33, 3) m/s^2 -> (N, C, 6): conv, ReLU, conv, ReLU, max over time, per subsequence."""

    def __init__(self, feats: nets.ConvFeatures):
        super().__init__()
        conv = [m for m in feats.conv if isinstance(m, nn.Conv1d)]
        if len(conv) != 2:
            raise ExportError(f"expected 2 Conv1d layers in the feature stack, found {len(conv)}")
        self.c1 = _conv2d_from(conv[0], 1.0 / nets.ACC_SCALE_MPS2)
        self.c2 = _conv2d_from(conv[1])
        self.pool_t = nets.SUBSEQ_FRAMES - (conv[0].kernel_size[0] - 1) - (conv[1].kernel_size[0] - 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        y = x.permute(0, 3, 1, 2)  # NHWC -> NCHW: (N, 3, 6, 33)
        y = torch.relu(self.c2(torch.relu(self.c1(y))))  # (N, C, 6, 29)
        return F.max_pool2d(y, (1, self.pool_t)).squeeze(3)  # (N, C, 6)


def _lstm_copy(src: nn.LSTM, input_scale: float = 1.0) -> nn.LSTM:
    """The same LSTM, time-major (batch_first=False), optionally with the input scale folded in."""
    if src.num_layers != 1 or src.bidirectional or src.proj_size:
        raise ExportError("only single-layer unidirectional LSTMs are exported")
    dst = nn.LSTM(src.input_size, src.hidden_size, bias=src.bias, batch_first=False)
    sd = {k: v.detach().clone() for k, v in src.state_dict().items()}
    sd["weight_ih_l0"] = sd["weight_ih_l0"] * input_scale
    dst.load_state_dict(sd)
    return dst


class ExportConvLSTM(nn.Module):
    def __init__(self, m: nets.ConvLSTM):
        super().__init__()
        self.features = _ConvStack(m.features)
        self.lstm = _lstm_copy(m.lstm)
        self.head = m.head

    def forward(self, x):
        f = self.features(x).permute(2, 0, 1)  # (6, N, C): time-major
        _, (h, _) = self.lstm(f)
        logits = self.head(h[0])
        return torch.softmax(logits, dim=1), logits


class ExportCNN(nn.Module):
    def __init__(self, m: nets.CNN):
        super().__init__()
        self.features = _ConvStack(m.features)
        c = m.features.channels
        # torch CNN flattens (N, 6, C) as s*C + c; here features are (N, C, 6) -> c*6 + s.
        w = m.head.weight.detach().reshape(-1, nets.N_SUBSEQ, c).transpose(1, 2).reshape(m.head.weight.shape)
        self.head = nn.Linear(m.head.in_features, m.head.out_features)
        with torch.no_grad():
            self.head.weight.copy_(w)
            self.head.bias.copy_(m.head.bias.detach())

    def forward(self, x):
        logits = self.head(self.features(x).flatten(1))
        return torch.softmax(logits, dim=1), logits


class ExportLSTM(nn.Module):
    def __init__(self, m: nets.LSTM):
        super().__init__()
        self.lstm = _lstm_copy(m.lstm, 1.0 / nets.ACC_SCALE_MPS2)
        self.head = m.head

    def forward(self, x):
        seq = x.reshape(-1, nets.N_SUBSEQ * nets.SUBSEQ_FRAMES, nets.N_CHANNELS).transpose(0, 1)
        _, (h, _) = self.lstm(seq)
        logits = self.head(h[0])
        return torch.softmax(logits, dim=1), logits


class ExportGeneric(nn.Module):
    """Any module mapping (N, 6, 33, 3) -> logits: exported as is, softmax appended."""

    def __init__(self, m: nn.Module):
        super().__init__()
        self.m = m

    def forward(self, x):
        logits = self.m(x)
        return torch.softmax(logits, dim=1), logits


def export_module(model: nn.Module) -> nn.Module:
    """The export-friendly equivalent of a ``models.nets`` module (same weights), in eval mode."""
    model = model.eval()
    for cls, wrap in ((nets.ConvLSTM, ExportConvLSTM), (nets.CNN, ExportCNN), (nets.LSTM, ExportLSTM)):
        if type(model) is cls:
            return wrap(model).eval()
    return ExportGeneric(model).eval()


def arch_of(model: nn.Module) -> str:
    for name, cls in nets.ARCHS.items():
        if type(model) is cls:
            return name
    return type(model).__name__.lower()


# --------------------------------------------------------------------------- graph clean-up

def _strip_zero_lstm_state(graph: onnx.GraphProto) -> None:
    """Drop LSTM initial_h / initial_c inputs produced from zeros (ONNX's default is zero)."""
    producers = {o: n for n in graph.node for o in n.output}
    inits = {i.name: i for i in graph.initializer}

    def is_zero(name: str) -> bool:
        if name in inits:
            return not np.any(onnx.numpy_helper.to_array(inits[name]))
        n = producers.get(name)
        if n is None:
            return False
        if n.op_type == "ConstantOfShape":
            vals = [onnx.numpy_helper.to_array(a.t) for a in n.attribute if a.name == "value"]
            return not vals or not np.any(vals[0])
        if n.op_type == "Constant":
            vals = [onnx.numpy_helper.to_array(a.t) for a in n.attribute if a.name == "value"]
            return bool(vals) and not np.any(vals[0])
        if n.op_type in ("Expand", "Reshape", "Unsqueeze", "Cast", "Identity", "Tile"):
            return is_zero(n.input[0])
        return False

    for n in graph.node:
        if n.op_type != "LSTM":
            continue
        ins = list(n.input)
        if len(ins) > 5 and all(not name or is_zero(name) for name in ins[5:7]):
            keep = ins[:5] + ([""] * 2 + ins[7:] if len(ins) > 7 else [])
            while keep and keep[-1] == "":
                keep.pop()
            del n.input[:]
            n.input.extend(keep)


def _prune_dead(graph: onnx.GraphProto) -> None:
    outs = {o.name for o in graph.output}
    while True:
        used = outs | {i for n in graph.node for i in n.input}
        dead = [n for n in graph.node if not any(o in used for o in n.output)]
        if not dead:
            break
        for n in dead:
            graph.node.remove(n)
    used = {i for n in graph.node for i in n.input} | outs
    for init in [i for i in graph.initializer if i.name not in used]:
        graph.initializer.remove(init)


def op_counts(model: onnx.ModelProto) -> dict[str, int]:
    counts: dict[str, int] = {}
    for n in model.graph.node:
        counts[n.op_type] = counts.get(n.op_type, 0) + 1
    return dict(sorted(counts.items()))


# --------------------------------------------------------------------------- metadata

def git_commit(root: Path = REPO_ROOT) -> str | None:
    """HEAD of the repository (``+dirty`` when the work tree has changes), or None."""
    try:
        head = subprocess.run(["git", "-C", str(root), "rev-parse", "HEAD"], capture_output=True, text=True,
                              timeout=10)
        if head.returncode != 0:
            return None
        dirty = subprocess.run(["git", "-C", str(root), "status", "--porcelain", "--untracked-files=no"],
                               capture_output=True, text=True, timeout=10)
        return head.stdout.strip() + ("+dirty" if dirty.stdout.strip() else "")
    except (OSError, subprocess.SubprocessError):
        return None


def package_version() -> str:
    try:
        from importlib.metadata import version

        return version("edge-safety")
    except Exception:
        return "0.0.0"


def model_metadata(model: nn.Module, classes: Sequence[str], *, arch: str | None = None,
                   model_version: str | None = None, precision: str = "fp32", commit: str | None = None,
                   extra: dict | None = None) -> dict[str, str]:
    arch = arch or arch_of(model)
    meta = {
        "classes": json.dumps(list(classes)),
        "input_name": INPUT_NAME,
        "input_layout": input_layout(arch),
        "input_units": "m/s^2",
        "outputs": f"{PROBS}: softmax (N,K) in classes order; {LOGITS}: pre-softmax scores (N,K)",
        "sample_rate_hz": str(SAMPLE_RATE_HZ),
        "resampled_rate_hz": repr(RESAMPLED_RATE_HZ),
        "resampling": f"{CAPTURE_FRAMES} -> {RESAMPLED_FRAMES} frames, polyphase {UP}/{DOWN} "
                      "(edge_runtime.wearable.classifier), first 198 frames -> 6 x 33",
        "capture_frames": str(CAPTURE_FRAMES),
        "arch": arch,
        "model_version": model_version or f"{package_version()}+{arch}",
        "parameters_torch": str(nets.torch_param_count(model)),
        "parameters_keras": str(nets.keras_param_count(model)),
        "precision": precision,
        "producer": "edge-safety export (torch.onnx TorchScript exporter)",
        "torch_version": torch.__version__,
    }
    commit = commit if commit is not None else git_commit()
    if commit:
        meta["git_commit"] = commit
    for k, v in (extra or {}).items():
        meta[k] = v if isinstance(v, str) else json.dumps(v, sort_keys=True)
    return meta


def set_metadata(model: onnx.ModelProto, meta: dict[str, str]) -> None:
    existing = {p.key: p for p in model.metadata_props}
    for k, v in meta.items():
        if k in existing:
            existing[k].value = v
        else:
            model.metadata_props.add(key=k, value=v)


def get_metadata(model: onnx.ModelProto | str | Path) -> dict[str, str]:
    if not isinstance(model, onnx.ModelProto):
        model = onnx.load(str(model), load_external_data=False)
    return {p.key: p.value for p in model.metadata_props}


# --------------------------------------------------------------------------- export

def example_input(n: int = 4, seed: int = 0) -> np.ndarray:
    """Plausible wrist windows (N, 6, 33, 3) m/s^2: gravity on z plus motion."""
    rng = np.random.default_rng(seed)
    x = rng.normal(0.0, 3.0, size=(n, *MODEL_INPUT_SHAPE)) + np.array([0.0, 0.0, nets.ACC_SCALE_MPS2])
    return x.astype(np.float32)


def to_onnx(model: nn.Module, classes: Sequence[str], *, opset: int = DEFAULT_OPSET,
            model_version: str | None = None, commit: str | None = None, extra_meta: dict | None = None
            ) -> onnx.ModelProto:
    """The ONNX graph of ``model`` (a models.nets module) with softmax and metadata."""
    model = model.eval()
    k = len(classes)
    out_features = getattr(getattr(model, "head", None), "out_features", k)
    if out_features != k:
        raise ExportError(f"model has {out_features} outputs but {k} classes were given")
    wrapped = export_module(model)
    x = torch.from_numpy(example_input(2))
    arch = arch_of(model)
    in_axes = {0: "N", 1: "S"} if arch in EARLY_ARCHS else {0: "N"}
    buf = io.BytesIO()
    with warnings.catch_warnings(), torch.no_grad():
        warnings.simplefilter("ignore")
        torch.onnx.export(
            wrapped, (x,), buf, dynamo=False, opset_version=opset, do_constant_folding=True,
            input_names=[INPUT_NAME], output_names=[PROBS, LOGITS],
            dynamic_axes={INPUT_NAME: in_axes, PROBS: {0: "N"}, LOGITS: {0: "N"}},
        )
    model.eval()
    onx = onnx.load_from_string(buf.getvalue())
    _strip_zero_lstm_state(onx.graph)
    _prune_dead(onx.graph)
    onx.producer_name = "edge-safety-export"
    onx.producer_version = package_version()
    onx.doc_string = (f"{arch} wearable distraction classifier: input {INPUT_NAME} "
                      f"({input_layout(arch)}); output {PROBS} softmax over {list(classes)}")
    set_metadata(onx, model_metadata(model, classes, model_version=model_version, commit=commit,
                                     extra=extra_meta))
    onnx.checker.check_model(onx)
    return onx


def save_onnx(onx: onnx.ModelProto, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(declare_used_opsets(onx).SerializeToString(deterministic=True))
    return path


def check_parity(model: nn.Module, onnx_model: onnx.ModelProto | str | Path, x: np.ndarray | None = None,
                 tol: float = PARITY_TOL) -> dict:
    """Max |torch - onnxruntime| over logits and probs (torch module in eval mode, 1 thread)."""
    from edge_runtime.core.onnx import open_session

    x = example_input(64, seed=1) if x is None else np.asarray(x, np.float32)
    sess = open_session(onnx_model.SerializeToString() if isinstance(onnx_model, onnx.ModelProto) else onnx_model)
    probs, logits = sess.run([PROBS, LOGITS], {INPUT_NAME: x})
    was = model.training
    model.eval()
    with torch.no_grad():
        ref_logits = model(torch.from_numpy(x))
        ref_probs = torch.softmax(ref_logits, dim=1).numpy()
    model.train(was)
    d_logits = float(np.abs(logits - ref_logits.numpy()).max())
    d_probs = float(np.abs(probs - ref_probs).max())
    # single-window path too (batch 1 takes other kernels)
    p1 = sess.run([PROBS], {INPUT_NAME: x[:1]})[0]
    d_probs = max(d_probs, float(np.abs(p1 - ref_probs[:1]).max()))
    if arch_of(model) in EARLY_ARCHS:  # and every early decision: the first S sub-windows
        for s in range(1, x.shape[1]):
            ps, ls = sess.run([PROBS, LOGITS], {INPUT_NAME: np.ascontiguousarray(x[:, :s])})
            with torch.no_grad():
                ref = model(torch.from_numpy(np.ascontiguousarray(x[:, :s])))
            d_logits = max(d_logits, float(np.abs(ls - ref.numpy()).max()))
            d_probs = max(d_probs, float(np.abs(ps - torch.softmax(ref, dim=1).numpy()).max()))
    res = {"max_abs_logits": d_logits, "max_abs_probs": d_probs, "n": int(len(x)), "tol": tol,
           "ok": bool(max(d_logits, d_probs) < tol)}
    return res


def export_checkpoint(checkpoint: str | Path, out: str | Path, *, opset: int = DEFAULT_OPSET,
                      parity_x: np.ndarray | None = None, model_version: str | None = None) -> dict:
    """models.train checkpoint -> ONNX file; returns {"path", "parity", "meta", "ops"}."""
    from models.train import load_checkpoint

    ckpt = Path(checkpoint)
    if not ckpt.exists():
        raise ExportError(f"{ckpt}: checkpoint not found")
    try:
        model, meta = load_checkpoint(ckpt)
    except ExportError:
        raise
    except Exception as e:  # torch.load / state_dict errors
        raise ExportError(f"{ckpt}: not a readable model checkpoint ({type(e).__name__}: "
                          f"{str(e).splitlines()[0] if str(e) else ''})") from None
    if not isinstance(model, nn.Module):
        raise ExportError(f"{ckpt}: field 'arch': {meta.get('arch')!r} is not a neural model (nothing to export)")
    classes = meta.get("classes") or []
    if not classes:
        raise ExportError(f"{ckpt}: field 'classes': missing")
    version = model_version or f"{package_version()}+{meta.get('arch')}.seed{meta.get('seed')}"
    onx = to_onnx(model, classes, opset=opset, model_version=version,
                  extra_meta={"training": {k: meta.get(k) for k in ("seed", "epochs")}})
    path = save_onnx(onx, out)
    parity = check_parity(model, onx, parity_x)
    if not parity["ok"]:
        raise ExportError(f"{path}: torch/onnxruntime parity {max(parity['max_abs_logits'], parity['max_abs_probs']):.2e} "
                          f"exceeds {PARITY_TOL:g}")
    return {"path": str(path), "parity": parity, "meta": meta, "ops": op_counts(onx), "model": model}
