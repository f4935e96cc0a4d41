"""export.lifter_fold.fold_input_centering of an fp32 lifter graph into a file (quantise it with
lifter_candidates.py --fp32).

    PYTHONPATH=. python reports/bench/s18_ortperf/fold_centering.py edge_runtime/assets/lifter.fp32.onnx OUT.onnx
"""
from __future__ import annotations

import sys

import onnx

from export.lifter_fold import fold_input_centering

if __name__ == "__main__":
    onnx.save(fold_input_centering(onnx.load(sys.argv[1])), sys.argv[2])
