"""The Python heap of a real-time loop: collected and frozen once it is built.

CPython's cyclic garbage collector runs when allocations outnumber deallocations by a threshold,
inside whatever code is allocating then; a full collection walks every tracked object, and once
the models, codecs and buses are loaded that is hundreds of thousands of them (60-80 ms on the
robot box's CPU, reports/bench/s17_perf7/report.md). In the 30 Hz robot loop it landed inside a
frame. :func:`settle` collects what start-up left over and moves every object alive then into
the permanent generation (:func:`gc.freeze`), so later collections walk only what the loop
itself allocates: no collection of start-up objects lands inside a frame, and the small ones the
loop still causes stay small. Start-up objects are kept for the life of the process anyway.
"""
from __future__ import annotations

import gc


def settle() -> int:
    """Collect the garbage start-up left and freeze every surviving object; returns how many were
    frozen. Call once, after the loop and everything it holds are built, before the first frame."""
    gc.collect()
    gc.freeze()
    return gc.get_freeze_count()
