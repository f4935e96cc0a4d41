"""The distraction classifier: a shipped ONNX model on onnxruntime (numpy + onnxruntime only).

    engine = Engine.from_manifest(ASSETS_DIR, "int8", threads=1)
    probs = engine.classify(x)            # (6, 33, 3) -> (K,), or (N, 6, 33, 3) -> (N, K)
    probs = engine.classify_capture(x700) # (700, 3) or (N, 700, 3) m/s^2 at 100 Hz

Loading goes through ``assets/manifest.json``: the file's sha256 is checked
against the manifest before the bytes are handed to onnxruntime (the bytes
that were hashed are the bytes that are loaded); a mismatch raises
:class:`ModelIntegrityError` naming the file. The session is set up for a
small edge box: ``threads`` intra-op threads (default 1), one inter-op
thread, sequential execution, no spin-waiting (idle threads sleep instead of
burning a core), all graph optimisations.

The model's input is ``imu`` (N, 6, 33, 3) float32 in m/s^2, the output of
:func:`edge_runtime.wearable.preprocess.preprocess`; its output ``probs`` (N, K) is a
softmax in ``classes`` order. This module never imports torch.
"""
from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Sequence

import numpy as np
import onnxruntime as ort

from edge_runtime.core.manifest import (
    ASSETS_DIR,
    CLASSIFIER_ARCHS,
    ModelIntegrityError,
    load_verified,
)
from edge_runtime.core.onnx import open_session
from edge_runtime.wearable.preprocess import preprocess

__all__ = ["Engine", "ModelIntegrityError", "ASSETS_DIR"]

INPUT_NAME = "imu"
OUTPUT_NAME = "probs"


class Engine:
    """One ONNX classifier on onnxruntime's CPU provider."""

    def __init__(self, model: bytes | str | os.PathLike, *, classes: Sequence[str] | None = None,
                 name: str = "", precision: str = "", threads: int = 1, entry: dict | None = None,
                 source: str = ""):
        source = source or (str(model) if not isinstance(model, bytes) else "<model bytes>")
        self.source = source
        self.threads = threads
        self.session = open_session(model, threads, source)
        self.metadata: dict[str, str] = dict(self.session.get_modelmeta().custom_metadata_map)
        inputs = self.session.get_inputs()
        outputs = [o.name for o in self.session.get_outputs()]
        self.input_name = INPUT_NAME if any(i.name == INPUT_NAME for i in inputs) else inputs[0].name
        self.output_name = OUTPUT_NAME if OUTPUT_NAME in outputs else outputs[0]
        shape = next(i.shape for i in inputs if i.name == self.input_name)
        self.input_shape = tuple(d if isinstance(d, int) else None for d in shape)
        self._item_shape = self.input_shape[1:]
        meta_classes = self._meta_json("classes")
        if classes is None:
            classes = meta_classes
        if classes is None:
            raise ModelIntegrityError(f"{source}: no class list (neither manifest nor ONNX metadata 'classes')")
        self.classes: list[str] = [str(c) for c in classes]
        if meta_classes is not None and list(meta_classes) != self.classes:
            raise ModelIntegrityError(f"{source}: manifest classes {self.classes} differ from the model's "
                                      f"metadata {meta_classes}")
        self.name = name or self.metadata.get("arch", Path(source).stem)
        self.precision = precision or self.metadata.get("precision", "")
        self.entry = entry or {}
        self._run = self.session.run
        self._outputs = [self.output_name]
        self._run_options = ort.RunOptions()
        probe = self.classify(np.zeros(self._item_shape, np.float32)) if None not in self._item_shape else None
        if probe is not None and probe.shape != (len(self.classes),):
            raise ModelIntegrityError(f"{source}: model has {probe.shape[-1]} outputs but "
                                      f"{len(self.classes)} classes are listed")

    # ------------------------------------------------------------------ construction

    @classmethod
    def from_manifest(cls, assets_dir: str | os.PathLike = ASSETS_DIR, name_or_precision: str = "int8",
                      threads: int = 1, arch: str | tuple[str, ...] | None = CLASSIFIER_ARCHS) -> "Engine":
        """The manifest entry named ``name_or_precision`` (or the first of that precision)
        among the ``arch`` entries (default: the classifiers; None: any), hash-checked, on
        onnxruntime with ``threads`` intra-op threads."""
        entry, data, path = load_verified(assets_dir, name_or_precision, arch=arch)
        return cls(data, classes=entry["classes"], name=entry["name"], precision=entry["precision"],
                   threads=threads, entry=entry, source=str(path))

    @classmethod
    def from_file(cls, path: str | os.PathLike, threads: int = 1, classes: Sequence[str] | None = None
                  ) -> "Engine":
        """An ONNX file without a manifest (no hash check); classes from its metadata."""
        p = Path(path)
        if not p.is_file():
            raise ModelIntegrityError(f"{p}: model file not found")
        return cls(p, classes=classes, threads=threads, source=str(p))

    # ------------------------------------------------------------------ inference

    def classify(self, x: np.ndarray) -> np.ndarray:
        """Class probabilities for model input(s) in m/s^2: (6, 33, 3) -> (K,), (N, 6, 33, 3) -> (N, K)."""
        a = x if type(x) is np.ndarray and x.dtype == np.float32 else np.asarray(x, dtype=np.float32)
        single = a.ndim == len(self._item_shape)
        if single:
            a = a[None]
        if a.ndim != len(self.input_shape) or (a.shape[1:] != self._item_shape and any(
                want is not None and got != want for got, want in zip(a.shape[1:], self._item_shape))):
            raise ValueError(f"{self.name}: input shape {np.shape(x)}, expected "
                             f"{tuple(d or 'N' for d in self._item_shape)} or (N, ...) of it")
        if not np.isfinite(a).all():
            raise ValueError(f"{self.name}: input holds NaN or infinite values")
        if a.shape[0] == 0:
            return np.zeros((0, len(self.classes)), np.float32)
        if not a.flags.c_contiguous:
            a = np.ascontiguousarray(a)
        out = self._run(self._outputs, {self.input_name: a}, self._run_options)[0]
        return out[0] if single else out

    __call__ = classify

    def classify_capture(self, x700: np.ndarray) -> np.ndarray:
        """Probabilities for detector capture(s) (700, 3) or (N, 700, 3), m/s^2 at 100 Hz."""
        return self.classify(preprocess(np.asarray(x700, dtype=np.float32)))

    def predict(self, x: np.ndarray) -> list[str] | str:
        """Top class name(s) for model input(s)."""
        p = self.classify(x)
        if p.ndim == 1:
            return self.classes[int(p.argmax())]
        return [self.classes[i] for i in p.argmax(axis=1)]

    # ------------------------------------------------------------------ description

    def _meta_json(self, key: str):
        raw = self.metadata.get(key)
        if raw is None:
            return None
        try:
            return json.loads(raw)
        except json.JSONDecodeError:
            raise ModelIntegrityError(f"{self.source}: ONNX metadata {key!r} is not valid JSON") from None

    def describe(self) -> dict:
        return {"name": self.name, "precision": self.precision, "source": self.source,
                "threads": self.threads, "classes": self.classes, "input": self.input_name,
                "input_shape": ["N" if d is None else d for d in self.input_shape],
                "output": self.output_name, "metadata": self.metadata}

    def __repr__(self) -> str:
        return f"Engine({self.name!r}, precision={self.precision!r}, threads={self.threads})"
