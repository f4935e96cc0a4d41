"""The streaming classifier (issue 12, :mod:`models.stream_net`) into ``edge_runtime/assets``: fp32 and int8 ONNX
and their manifest entries (``python -m export stream``), as ``export.assets`` does for the ConvLSTM.

1. the ``stream-train`` checkpoint exported to fp32 ONNX (the input scale 1/g folded into the first conv;
   parity with torch < 1e-4 on cohort windows of every length the runtime may run);
2. int8 by onnxruntime's quantiser (:func:`export.quantize.choose`: the candidates of ``CANDIDATES``,
   calibrated MinMax on cohort windows, refused when their top class agrees with fp32's on fewer than
   ``MIN_AGREEMENT`` of other cohort windows or their macro-F1 moves by more than 0.01, the fastest of the rest
   kept; none left: an error);
3. both files and their entries (``stream-fp32``, ``stream-int8``, arch ``STREAM_ARCH``) written into the
   assets next to the others; every other entry and file is left as it is.

``--figures`` (after ``firmware_sim drive-eval --decision stream`` on development drives) adds the drive
figures to the entry of the model they were measured with, without rebuilding anything: a figure is tied to
the sha256 of the file that produced it.

Graph contract (``edge_runtime.wearable.stream_decider.StreamModel`` reads it): input ``imu`` float32 (N, T, 3),
the last T steps of the wrist stream at 25 Hz (each the mean of 4 raw 100 Hz frames), oldest first, axis x/y/z last
as in the capture models' input, m/s^2, T >= 16 dynamic (the manifest's ``dims`` gives the runtime's T); outputs
``probs`` (N, K) softmax in classes order and ``logits`` (N, K).
"""
from __future__ import annotations

import io
import json
import shlex
import sys
import tempfile
import warnings
from pathlib import Path
from typing import Callable

import numpy as np
import onnx
import torch
from torch import nn

from edge_runtime.core.manifest import STREAM_ARCH, load_manifest, sha256_file, verify_all, write_manifest
from export.onnx_export import (
    DEFAULT_OPSET,
    INPUT_NAME,
    LOGITS,
    PARITY_TOL,
    PROBS,
    ExportError,
    git_commit,
    package_version,
    save_onnx,
    set_metadata,
)
from models import stream_net
from models.stream_train import load_stream_checkpoint, training_command

CANDIDATES = ("qdq_conv", "qdq_conv_pt", "qdq_conv_s8", "qdq_all", "dynamic", "qdq_conv2")
"""``export.quantize.VARIANTS`` that apply to a conv stack with a dense head (the LSTM ones do not). The
fastest that passes the gate is kept; ``qdq_conv2`` (first conv fp32: it sees the raw stream) is the slowest
and there for models whose whole conv stack in int8 misses the gate (session 23's c1: 0.9888 with qdq_conv,
0.9956 with qdq_conv2)."""
MIN_AGREEMENT = 0.99
"""int8's top class must be fp32's on at least this share of the gate windows (issue 12's must-hold)."""
N_CALIB, N_GATE = 1000, 5000
PARITY_WINDOW_S = (2.0, 3.0, 4.0)
WINDOW_S = 4.0
"""The window the calibration and gate windows have: stream B's, the runtime's default."""
INPUT_LAYOUT = ("N,T,3: the last T steps (T >= 16, dynamic) of the wrist stream at 25 Hz, each the mean of 4 raw "
                "100 Hz frames, oldest first, axis x/y/z, m/s^2")
NAMES = {"fp32": f"{STREAM_ARCH}-fp32", "int8": f"{STREAM_ARCH}-int8"}


class ExportStreamNet(nn.Module):
    """The StreamNet's graph for export: the same weights, 1/g folded into the first conv, the input's time and axis
    swapped in the graph (the box hands over its ring's (T, 3) rows as they are), softmax appended."""

    def __init__(self, m: stream_net.StreamNet):
        super().__init__()
        first = m.conv[0]
        self.conv = nn.Sequential(*[nn.Conv1d(first.in_channels, first.out_channels, first.kernel_size,
                                              padding=first.padding)] + list(m.conv)[1:])
        with torch.no_grad():
            self.conv[0].weight.copy_(first.weight / stream_net.ACC_SCALE_MPS2)
            self.conv[0].bias.copy_(first.bias)
        self.head = m.head

    def forward(self, x):
        f = self.conv(x.transpose(1, 2))
        z = torch.cat([f.amax(dim=2), f.mean(dim=2), f[:, :, -stream_net.NOW_STEPS:].mean(dim=2)], dim=1)
        logits = self.head(z)
        return torch.softmax(logits, dim=1), logits


def to_stream_onnx(model: stream_net.StreamNet, classes, meta: dict[str, str]) -> onnx.ModelProto:
    """The ONNX graph of a trained StreamNet (eval mode: no dropout) with ``meta`` as metadata."""
    x = torch.zeros(2, int(WINDOW_S / stream_net.STEP_S), 3)
    buf = io.BytesIO()
    with warnings.catch_warnings(), torch.no_grad():
        warnings.simplefilter("ignore")
        torch.onnx.export(ExportStreamNet(model.eval()).eval(), (x,), buf, dynamo=False, opset_version=DEFAULT_OPSET,
                          do_constant_folding=True, input_names=[INPUT_NAME], output_names=[PROBS, LOGITS],
                          dynamic_axes={INPUT_NAME: {0: "N", 1: "T"}, PROBS: {0: "N"}, LOGITS: {0: "N"}})
    onx = onnx.load_from_string(buf.getvalue())
    onx.producer_name = "edge-safety-export"
    onx.producer_version = package_version()
    onx.doc_string = (f"streaming wearable distraction classifier: input {INPUT_NAME} ({INPUT_LAYOUT}); "
                      f"output {PROBS} softmax over {list(classes)}")
    set_metadata(onx, {**meta, "classes": json.dumps(list(classes)), "input_layout": INPUT_LAYOUT, "arch": STREAM_ARCH,
                       "precision": "fp32"})
    onnx.checker.check_model(onx)
    return onx


def stream_parity(model: stream_net.StreamNet, onx: onnx.ModelProto, windows_by_length: list[np.ndarray]) -> dict:
    """Max |probs| and |logits| between onnxruntime and torch over windows (N, T, 3) of several lengths, and at
    batch 1."""
    from edge_runtime.core.onnx import open_session

    sess = open_session(onx.SerializeToString())
    d = {"max_abs_probs": 0.0, "max_abs_logits": 0.0}
    for x in windows_by_length:
        for batch in (x, x[:1]):
            probs, logits = sess.run([PROBS, LOGITS], {INPUT_NAME: batch})
            with torch.no_grad():
                ref = model(torch.from_numpy(batch).transpose(1, 2))
            d["max_abs_logits"] = max(d["max_abs_logits"], float(np.abs(logits - ref.numpy()).max()))
            d["max_abs_probs"] = max(d["max_abs_probs"], float(np.abs(probs - torch.softmax(ref, 1).numpy()).max()))
    return {**d, "tol": PARITY_TOL, "ok": max(d.values()) < PARITY_TOL,
            "window_s": list(PARITY_WINDOW_S), "n": int(sum(len(x) for x in windows_by_length))}


def cohort_windows(n: int, seed: int, window_s: float, subjects: int = 20, cohort_seed: int = 0, minutes: float = 15.0):
    """(windows (n, T, 3), labels (n,)) from the training cohort's streams, drawn as training draws its ends
    (half distractions, a quarter near Other motions, a quarter elsewhere), with their own seed."""
    from models.stream_train import cohort_recordings, stream_set

    data = stream_set(cohort_recordings(subjects, cohort_seed, minutes))
    rng = np.random.default_rng(seed)
    ends = np.concatenate([rng.choice(data.distraction, n // 2), rng.choice(data.near_other, n // 4),
                           rng.choice(data.far_other, n - n // 2 - n // 4)])
    x = stream_net.windows(data.x25, ends, int(round(window_s / stream_net.STEP_S)))  # (n, 3, T): the net's
    return np.ascontiguousarray(x.transpose(0, 2, 1)), data.y[ends]


def build_stream_assets(checkpoint: str | Path, out: str | Path, *, work: str | Path | None = None,
                        command: str | None = None, log: Callable[[str], None] = print) -> dict:
    """Steps 1-3 of the module docstring; returns the manifest written."""
    from export.quantize import choose

    out = Path(out)
    verify_all(out)  # the assets it adds to must be intact (every listed file, every hash)
    command = command or "python -m export " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    model, meta = load_stream_checkpoint(checkpoint)
    classes = list(meta["classes"])
    steps = int(round(WINDOW_S / stream_net.STEP_S))
    x, y = cohort_windows(N_CALIB + N_GATE, seed=1, window_s=WINDOW_S)
    calib, gate_x, gate_y = x[:N_CALIB], x[N_CALIB:], y[N_CALIB:]
    commit = git_commit()
    onnx_meta = {"model_version": f"{package_version()}+{STREAM_ARCH}.w{model.width}.seed{meta.get('seed')}",
                 "training": json.dumps({k: meta.get(k) for k in ("seed", "epochs", "data")}, sort_keys=True),
                 "sample_rate_hz": "100", "step_rate_hz": "25", **({"git_commit": commit} if commit else {})}
    onx = to_stream_onnx(model, classes, onnx_meta)
    parity = stream_parity(model, onx, [np.ascontiguousarray(gate_x[:256, steps - int(round(w / stream_net.STEP_S)):])
                                        for w in PARITY_WINDOW_S])
    log(f"[1/3] fp32: parity with torch max |d| probs {parity['max_abs_probs']:.2e}, logits {parity['max_abs_logits']:.2e}")
    if not parity["ok"]:
        raise ExportError(f"{checkpoint}: torch/onnxruntime parity exceeds {PARITY_TOL:g}")
    with tempfile.TemporaryDirectory(dir=work) as td:
        fp32_path = save_onnx(onx, Path(td) / f"{STREAM_ARCH}.fp32.onnx")
        int8_path = Path(td) / f"{STREAM_ARCH}.int8.onnx"
        log(f"[2/3] int8: candidates {', '.join(CANDIDATES)}, calibrated on {N_CALIB} cohort windows of {WINDOW_S:g} s, "
            f"gated on {N_GATE} others (agreement >= {MIN_AGREEMENT})")
        quant = choose(fp32_path, int8_path, calib, eval_x=gate_x, eval_y=gate_y, variants=CANDIDATES, log=log,
                       min_agreement=MIN_AGREEMENT)
        quant["calibration"].update(source=f"training-cohort windows of {WINDOW_S:g} s (seed 1 draw)", seed=1)
        provenance = {"command": command, "training": training_command(meta),
                      "checkpoint": str(checkpoint), "checkpoint_sha256": sha256_file(_checkpoint_file(checkpoint)),
                      "git_commit": commit, "seed": meta.get("seed"), "epochs": meta.get("epochs"),
                      "data": meta.get("data")}
        common = {"arch": STREAM_ARCH, "classes": classes, "model_version": onnx_meta["model_version"],
                  "parameters": {"torch": sum(p.numel() for p in model.parameters()), "width": model.width},
                  "inputs": [{"name": INPUT_NAME, "shape": ["N", "T", 3], "dtype": "float32", "units": "m/s^2",
                              "layout": INPUT_LAYOUT, "dims": {"T": steps}, "min_steps": stream_net.MIN_STEPS,
                              "step_s": stream_net.STEP_S}],
                  "outputs": [{"name": PROBS, "shape": ["N", len(classes)], "dtype": "float32",
                               "meaning": "softmax, classes order: the class of the last window"},
                              {"name": LOGITS, "shape": ["N", len(classes)], "dtype": "float32",
                               "meaning": "pre-softmax scores"}],
                  "provenance": provenance}
        train_metrics = {"training": meta.get("metrics", {}), "gate_windows": {"n": N_GATE, "window_s": WINDOW_S}}
        entries = [
            {"name": NAMES["fp32"], "file": fp32_path.name, "precision": "fp32", **common,
             "metrics": {**train_metrics, "parity": parity}},
            {"name": NAMES["int8"], "file": int8_path.name, "precision": "int8", "quantization": quant, **common,
             "metrics": {**train_metrics, "agreement_with_fp32": quant["agreement_with_fp32"]}}]
        for e, p in zip(entries, (fp32_path, int8_path)):
            e.update(sha256=sha256_file(p), size_bytes=p.stat().st_size)
            (out / p.name).write_bytes(p.read_bytes())
    manifest = load_manifest(out)
    kept = [e for e in manifest["models"] if e["name"] not in NAMES.values()]
    manifest["models"] = kept + entries
    write_manifest(out, manifest)
    log(f"[3/3] wrote {', '.join(e['file'] for e in entries)} ({quant['method']}, agreement with fp32 "
        f"{quant['agreement_with_fp32']:.4f}) and {out / 'manifest.json'}")
    return manifest


def _checkpoint_file(checkpoint: str | Path) -> Path:
    p = Path(checkpoint)
    return p / "model.pt" if p.is_dir() else p


def add_figures(out: str | Path, reports: list[str | Path], log: Callable[[str], None] = print) -> dict:
    """The stream decisions' drive figures of ``drive_eval.json`` reports, added to the manifest entry of the
    model that made them (matched by sha256: a figure belongs to one file), under ``metrics.drives`` (with the
    report's top-class agreement with another model at every hop, when it has one)."""
    out = Path(out)
    manifest = verify_all(out)
    by_sha = {e["sha256"]: e for e in manifest["models"] if e["arch"] == STREAM_ARCH}
    for path in map(Path, reports):
        try:
            r = json.loads(path.read_text())
            sha, score = r["stream_path"]["sha256"], r["scores"]["stream"]
        except (OSError, ValueError, KeyError, TypeError) as e:
            raise ExportError(f"{path}: not a drive-eval report with stream decisions ({type(e).__name__}: {e})") from None
        entry = by_sha.get(sha)
        if entry is None:
            raise ExportError(f"{path}: field 'stream_path.sha256': {sha[:12]}... is no stream model of {out}")
        keep = ("event_recall", "first_alert_class_accuracy", "onset_to_first_alert_s", "false_alerts_per_hour",
                "false_alerts", "repeat_alerts", "distractions", "driving_hours")
        entry.setdefault("metrics", {}).setdefault("drives", {})[f"seed {r['seed']}"] = {
            "command": r["command"], "git_commit": r.get("git_commit"), "stream": r["stream_path"]["settings"],
            **{k: score[k] for k in keep},
            **({"hop_agreement": r["class_agreement"]} if "class_agreement" in r else {})}
        log(f"{entry['name']}: drive seed {r['seed']} figures from {path}")
    write_manifest(out, manifest)
    return manifest
