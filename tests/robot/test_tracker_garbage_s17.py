"""Session 17 (perf7): the tracker's assignment without a reference cycle, pinned to the form it replaced.

The exhaustive search of ``keypoints._assign`` was a closure that called itself: a function -> cell ->
function cycle, with the frame's cost dict, detections and options hanging off it, that reference counting
never frees. One per frame made the garbage collector run every few dozen frames, for 1-4 ms, inside whatever
stage allocated next (the calibration spike of the bench's frame 928, the lifter's of 1202 and 1298:
reports/bench/s17_perf7/report.md). The search is now a module function; these tests hold it to session 16's
answers and check that an assignment leaves nothing for the collector."""
import gc
import itertools
import math

import numpy as np
import pytest

from edge_runtime.robot import keypoints as kpm


def session16_assign(costs):
    """keypoints._assign as session 16 left it (the closure that calls itself)."""
    pairs = {k: c for k, c in costs.items() if math.isfinite(c)}
    dets = sorted({d for _, d in pairs})
    if len(dets) > kpm.MAX_EXACT_ASSIGNMENT:
        assigned = {}
        for (tid, i), _ in sorted(pairs.items(), key=lambda kv: kv[1]):
            if i not in assigned and tid not in assigned.values():
                assigned[i] = tid
        return assigned
    options = {d: [t for t, dd in pairs if dd == d] for d in dets}

    def best(k, taken):
        if k == len(dets):
            return 0, 0.0, {}
        d = dets[k]
        n, c, m = best(k + 1, taken)
        result = (n, c, m)
        for t in options[d]:
            if t not in taken:
                n, c, m = best(k + 1, taken | {t})
                n, c = n + 1, c + pairs[(t, d)]
                if (n, -c) > (result[0], -result[1]):
                    result = (n, c, {**m, d: t})
        return result

    return best(0, frozenset())[2]


def random_costs(rng, n_tracks, n_dets, share_inf=0.3, ties=False):
    """Gated costs as PersonTracker.update builds them: (track id, detection index) -> cost or inf."""
    tids = sorted(rng.choice(1000, n_tracks, replace=False).tolist())
    costs = {}
    for tid, i in itertools.product(tids, range(n_dets)):
        if rng.random() < share_inf:
            costs[tid, i] = math.inf
        elif ties:
            costs[tid, i] = float(rng.integers(0, 3)) * 0.25  # exact ties between assignments
        else:
            costs[tid, i] = float(rng.random())
    return costs


@pytest.mark.parametrize("ties", [False, True])
def test_assign_is_session16s(ties):
    rng = np.random.default_rng(17 + ties)
    for _ in range(1500):
        costs = random_costs(rng, int(rng.integers(0, 7)), int(rng.integers(0, 7)), float(rng.choice([0, 0.3, 0.8])),
                             ties)
        got = kpm._assign(costs)
        assert got == session16_assign(costs)
        assert list(got.items()) == list(session16_assign(costs).items())  # the same order too


def test_assign_odd_inputs():
    for costs in ({}, {(3, 0): math.inf}, {(3, 0): math.nan, (4, 0): 0.5}, {(3, 0): 0.0, (4, 0): -0.0},
                  {(1, 0): 0.2, (2, 0): 0.2, (1, 1): 0.2, (2, 1): 0.2}, {(1, i): 0.1 * i for i in range(5)}):
        assert kpm._assign(costs) == session16_assign(costs)


def test_assign_leaves_no_garbage():
    """Reference counting frees everything an assignment made: the collector finds nothing after it
    (session 16's form left a cycle per call)."""
    rng = np.random.default_rng(5)
    costs = random_costs(rng, 3, 3, 0.0)
    was = gc.isenabled()
    gc.disable()
    try:
        gc.collect()
        session16_assign(costs)
        assert gc.collect() > 0  # the test can see the old form's cycle
        for _ in range(10):
            kpm._assign(costs)
        assert gc.collect() == 0
    finally:
        if was:
            gc.enable()
