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
    reduce_range: bool = True
    """7-bit weights. On x86 CPUs without VNNI (AVX2, AVX-512F) onnxruntime's u8 x s8 kernels add
    pairs of products in int16 (vpmaddubsw), which saturates when 2 x 255 x |w| > 32767: a model
    faithful on the machine that built it can drift on such a box (the toy lifter's int8 error
    grew 2.6x on an AVX2-only EPYC). With |w| <= 64 no pair can saturate, on every CPU. The
    shipped entries that lack ``quantization.reduce_range`` were built before, with 8-bit weights."""

    @property
    def static(self) -> bool:
        return self.static_ops is None or bool(self.static_ops)
