"""prof_cycle.py with the garbage collector's passes recorded per frame (CPU per generation, and how many).

Run like prof_cycle.py (same arguments): each frame/tick item gets gc0/gc1/gc2 (thread CPU of the
collector's passes in that frame, s), n_gc0.. counts, and gc@STAGE (the collector's CPU inside each stage
that was running, which that stage's own figure includes), so a stage's spike can be told from a collection
that happened to run inside it. The callback itself allocates a little, so collections fall a few
allocations away from where they fall in prof_cycle.py's runs.

``--freeze`` (a candidate, not in the product): ``gc.collect()`` then ``gc.freeze()`` once the RobotLoop is built,
so the start-up's objects (modules, the DBC, the models' wrappers: about 90,000) leave the collector's
generations and a full collection walks only what the run made since. ``--no-callbacks``: the same run
without the collector callbacks (prof_cycle.py's own figures, for the candidate's A/B).
"""
from __future__ import annotations

import gc
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path.cwd()))
sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "s15_perf"))

import prof_cycle as pc  # noqa: E402

_start: list = []
FULL: list = []  # (frames so far, CPU s) of every full (generation 2) collection, wherever it ran


def _cb(phase, info):
    if phase == "start":
        _start.append(time.thread_time())
    else:
        g = info["generation"]
        t0 = _start.pop()
        pc.CUR[f"gc{g}"] += time.thread_time() - t0
        pc.CUR[f"n_gc{g}"] += 1
        if g == 2:
            FULL.append((pc.N_FRAMES[0], time.thread_time() - t0))
        for stage in pc.ACTIVE:
            pc.CUR[f"gc@{stage}"] += time.thread_time() - t0


def _count_frames():
    """Counts the frames fed (pc.N_FRAMES), so a full collection outside any frame can be placed."""
    import bench.robot_cycle as rc

    pc.N_FRAMES = [0]
    feed = rc._Frames.__call__

    def counted(self, *a, **k):
        pc.N_FRAMES[0] += 1
        return feed(self, *a, **k)

    rc._Frames.__call__ = counted


def _freeze_after_init():
    """RobotLoop.__init__ followed by a full collection and gc.freeze() (the --freeze candidate)."""
    import edge_runtime.robot.loop as loopmod

    init = loopmod.RobotLoop.__init__

    def frozen(self, *a, **k):
        init(self, *a, **k)
        gc.collect()
        gc.freeze()

    loopmod.RobotLoop.__init__ = frozen


if __name__ == "__main__":
    if "--freeze" in sys.argv:
        sys.argv.remove("--freeze")
        _freeze_after_init()
    if "--no-callbacks" in sys.argv:
        sys.argv.remove("--no-callbacks")
    else:
        gc.callbacks.append(_cb)
        _count_frames()
    pc.main()
    print("full collections (frames fed before it, CPU ms):", [(n, round(c * 1e3, 2)) for n, c in FULL])
