"""edge_runtime.core.heap: what start-up leaves is collected, what survives is frozen."""
import gc
import weakref

from edge_runtime.core import heap


class _Node:
    pass


def test_settle_collects_startup_cycles_and_freezes_the_survivors():
    dead, alive = _Node(), _Node()
    dead.me = dead  # a reference cycle only the collector frees
    gone = weakref.ref(dead)
    del dead
    try:
        frozen = heap.settle()
        assert gone() is None
        assert frozen == gc.get_freeze_count() > 0
        assert not any(o is alive for o in gc.get_objects(generation=2))  # later collections never walk it
    finally:
        gc.unfreeze()
