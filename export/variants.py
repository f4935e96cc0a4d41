"""How to make an fp32 graph int8: one :class:`Variant` per recipe tried (the ConvLSTM's
``export.quantize.VARIANTS``, the lifter's ``export.lifter_assets.CANDIDATES``), built by
``export.quantize.build_variant`` and compared by ``export.quantize.compare_variants``.

Apart from :mod:`export.quantize` so that ``python -m export`` can set up its commands (the
lifter's module lists its recipes) without importing onnxruntime.quantization, which takes
seconds.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, Callable

if TYPE_CHECKING:
    import onnx


@dataclass(frozen=True)
class Variant:
    """One way to make an fp32 graph int8 with onnxruntime.quantization."""

    name: str
    description: str
    static_ops: tuple[str, ...] | None = ()  #: op types quantised static QDQ; None: every op type; (): none
    dynamic_ops: tuple[str, ...] = ()        #: op types then quantised dynamically
    per_channel: bool = True                 #: per-channel weight scales (static)
    activation: str = "uint8"                #: static activations, "uint8" or "int8" (weights are int8)
    keep_fp32: Callable[[onnx.ModelProto], list[str]] | None = None  #: names of the nodes left fp32

    @property
    def static(self) -> bool:
        return self.static_ops is None or bool(self.static_ops)
