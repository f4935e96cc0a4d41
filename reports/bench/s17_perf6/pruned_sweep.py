"""The escape plan's sphere pruning that perf4 proposed (session 16, report section 4), tried and NOT kept: every
candidate's per-person separations without weighing the spheres that cannot be anyone's nearest, by the clearance's
1-Lipschitz property (a few pivot spheres per person first; a sphere s' is skipped at a candidate when
pivot value + r_s - |c_s - c_s'| - r_s' exceeds the smallest so far by more than a margin). Exact: the per-candidate
separations are asserted equal to the full sweep's to the bit on every captured call. Slower: numpy's per-call
overhead of the two extra passes (pivots, then the gathered rest) costs more than the arithmetic it saves.

    cd TREE && OMP_NUM_THREADS=1 PYTHONPATH=. /work/main/.venv/bin/python reports/bench/s17_perf6/pruned_sweep.py \
        /work/notes/perf6/plans_bench.pkl [more captures] [--repeat 30]
"""
from __future__ import annotations

import argparse
import math
import pickle
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from edge_runtime.robot.hazard import _capsule_terms, _clearance_rest, point_clearance_m


def _turned_clearance(c, s_, x, z, apy, apy_by, terms) -> np.ndarray:
    """plan_escape_turn's clearance of the points turned by each candidate (c, s_: cos and sin of minus the turn),
    the same arithmetic element by element: (chunk, 1) x (spheres,) with terms (K, 1, 1), or (n,) x (n,) pairs
    with terms (K, 1)."""
    ax, _, az, bx, by, bz, den, r = terms
    moved_x, moved_z = c * x + s_ * z, -s_ * x + c * z
    apx = moved_x - ax
    t = apx * bx
    t += apy_by
    return _clearance_rest(apx, apy, moved_z - az, t, (bx, by, bz, den, r))


ESCAPE_PIVOTS = 4
""":class:`_PrunedSweep` weighs this many of each person's spheres (his pivots) at every candidate first."""
ESCAPE_PRUNE_MIN_SPHERES = 3 * ESCAPE_PIVOTS
""":class:`_PrunedSweep` prunes only people of at least this many spheres on average (fewer: nothing to gain)."""
ESCAPE_PRUNE_MAX_M = 1e4
""":class:`_PrunedSweep` prunes only when every coordinate and radius is finite and within this (m) of zero: the
rounding of the clearance's arithmetic then stays far below its margin (:attr:`_PrunedSweep.margin_m`), and no
product overflows (inf - inf would be a NaN, which a skipped sphere must never have been)."""

ESCAPE_PRUNE_MARGIN_M = 1e-5
""":class:`_PrunedSweep` skips a sphere only when its bound exceeds the smallest clearance so far by more than this
(m), plus 1e-9 of the largest magnitude: the clearance as computed is within a few ulps of the largest magnitude
of the exact one, except that :func:`_capsule_terms`' floor of 1e-12 m^2 on |ab|^2 can put a capsule shorter than
1 um its length farther than it is (the computed nearest point is still on the segment)."""


@dataclass(frozen=True)
class _PrunedSweep:
    """The escape plan's per-candidate separations ((chunk, P), each person's smallest sphere clearance) without
    weighing every sphere: a point's clearance from the arm is 1-Lipschitz in the point (the distance from a
    union of capsules), and a turn moves every sphere rigidly, so at any candidate a sphere s' is at least its
    person's pivot s's clearance - |c_s - c_s'| - r_s' + r_s away. Each candidate weighs the pivots first; a
    sphere whose bound exceeds the smallest so far by more than ``margin_m`` cannot be the nearest and is
    skipped; the rest are weighed as before, each with the same arithmetic (:func:`_turned_clearance`), so
    every minimum is the one the full sweep finds, to the bit (asserted below)."""
    x: np.ndarray
    y: np.ndarray
    z: np.ndarray
    radii: np.ndarray
    starts: np.ndarray
    pivots: np.ndarray       # (V,) sphere indices, each person's contiguous
    pivot_starts: np.ndarray  # (P,) where each person's pivots start in ``pivots``
    bound: np.ndarray        # (V, spheres): r_s - |c_s - c_s'| - r_s' for a pivot s of s''s person, -inf otherwise
    owner: np.ndarray        # (spheres,) each sphere's person
    others: np.ndarray       # (spheres,) bool: not a pivot
    apy_piv: np.ndarray      # the pivots' ap_y and ap_y b_y, (K, 1, V)
    apy_by_piv: np.ndarray
    terms2: tuple            # _capsule_terms(capsules, 2) and (capsules, 1)
    terms1: tuple
    margin_m: float

    @classmethod
    def of(cls, capsules, centres: np.ndarray, radii: np.ndarray, starts: np.ndarray, own: np.ndarray,
           apy: np.ndarray, apy_by: np.ndarray) -> _PrunedSweep | None:
        """The pruning of everyone's spheres (``centres`` (N, 3), ``radii`` (N,), each person's from ``starts``)
        against the arm's ``capsules``, ``own`` their clearances where it is now; None when it does not apply
        (:data:`ESCAPE_PRUNE_MIN_SPHERES`, :data:`ESCAPE_PRUNE_MAX_M`): the full sweep then."""
        a, b, r = capsules
        ends = np.append(starts[1:], len(radii))
        if len(radii) < ESCAPE_PRUNE_MIN_SPHERES * len(starts) or (ends <= starts).any():
            return None
        scale = max(float(np.abs(v).max(initial=0.0)) for v in (centres, radii, a, b, r))
        if not scale <= ESCAPE_PRUNE_MAX_M:  # NaN too
            return None
        pivots, owner = [], np.repeat(np.arange(len(starts)), ends - starts)
        for lo, hi in zip(starts.tolist(), ends.tolist()):
            pivots.extend(lo + k for k in _spread(centres[lo:hi], int(np.argmin(own[lo:hi])), ESCAPE_PIVOTS))
        pivots = np.array(pivots)
        gap = np.sqrt(((centres[pivots][:, None] - centres[None]) ** 2).sum(-1))       # (V, spheres)
        bound = np.where(owner[pivots][:, None] == owner[None], radii[pivots][:, None] - gap - radii[None], -np.inf)
        others = np.ones(len(radii), bool)
        others[pivots] = False
        pivot_starts = np.searchsorted(owner[pivots], np.arange(len(starts)))
        return cls(centres[:, 0], centres[:, 1], centres[:, 2], radii, starts, pivots, pivot_starts, bound, owner,
                   others, apy[..., pivots], apy_by[..., pivots], _capsule_terms(capsules, 2),
                   _capsule_terms(capsules, 1), ESCAPE_PRUNE_MARGIN_M + 1e-9 * scale)

    def separations(self, c: np.ndarray, s_: np.ndarray) -> np.ndarray:
        """(chunk, P) separations at the candidates ``c``, ``s_`` ((chunk, 1): cos and sin of minus the turns)."""
        x, z, radii, piv = self.x, self.z, self.radii, self.pivots
        first = _turned_clearance(c, s_, x[piv], z[piv], self.apy_piv, self.apy_by_piv, self.terms2) - radii[piv]
        nearest = np.minimum.reduceat(first, self.pivot_starts, axis=1)                        # (chunk, P)
        lowest = (first[:, :, None] + self.bound[None]).max(axis=1)                            # (chunk, spheres)
        ii, jj = np.nonzero((lowest <= nearest[:, self.owner] + self.margin_m) & self.others[None])
        clear = np.full((len(c), len(radii)), np.inf)
        clear[:, piv] = first
        if len(ii):
            ay, by = self.terms1[1], self.terms1[4]
            apy = self.y[jj] - ay                                                               # (K, n)
            cc, ss = c[:, 0], s_[:, 0]
            clear[ii, jj] = _turned_clearance(cc[ii], ss[ii], x[jj], z[jj], apy, apy * by, self.terms1) - radii[jj]
        return np.minimum.reduceat(clear, self.starts, axis=1)


def _spread(centres: np.ndarray, first: int, n: int) -> list[int]:
    """``n`` of ``centres`` (or all, if fewer) spread over them: ``first``, then each time the one farthest from
    those taken (so that every sphere has a pivot near it)."""
    taken = [first]
    gap = np.sqrt(((centres - centres[first]) ** 2).sum(-1))
    while len(taken) < min(n, len(centres)):
        k = int(np.argmax(gap))
        taken.append(k)
        gap = np.minimum(gap, np.sqrt(((centres - centres[k]) ** 2).sum(-1)))
    return sorted(taken)


def measure(call: dict, repeat: int) -> tuple[dict, int, int]:
    """One captured call: (each way's best CPU ms over all its chunks, clearances the pruned way weighed, of)."""
    caps, people = call["capsules"], call["people"]
    centres = np.concatenate([c for c, _ in people])
    radii = np.concatenate([r for _, r in people])
    starts = np.cumsum([0] + [len(r) for _, r in people[:-1]])
    own = point_clearance_m(centres, caps) - radii
    terms = _capsule_terms(caps, 2)
    apy = centres[:, 1] - terms[1]
    apy_by = apy * terms[4]
    x, z = centres[:, 0], centres[:, 2]
    # every candidate of both directions, in session 16's chunks (the first 8, then the rest)
    j0, step_deg, _, _, max_turn_deg = call["args"][:5]
    chunks = []
    for sign in (1.0, -1.0):
        room = min(math.radians(max_turn_deg), math.radians(170.0) - sign * j0)
        n = int(math.floor(room / math.radians(step_deg) + 1e-9))
        turns = sign * math.radians(step_deg) * np.arange(1, n + 1)
        cos, sin = np.cos(-turns), np.sin(-turns)
        chunks += [(cos[lo:hi, None], sin[lo:hi, None]) for lo, hi in ((0, min(n, 8)), (min(n, 8), n)) if lo < hi]

    def full():
        return [np.minimum.reduceat(_turned_clearance(c, s_, x, z, apy, apy_by, terms) - radii[None], starts, axis=1)
                for c, s_ in chunks]

    def pruned():
        sweep = _PrunedSweep.of(caps, centres, radii, starts, own, apy, apy_by)
        return [sweep.separations(c, s_) for c, s_ in chunks]

    for a, b in zip(full(), pruned()):
        assert a.tobytes() == b.tobytes()
    sweep = _PrunedSweep.of(caps, centres, radii, starts, own, apy, apy_by)
    weighed = total = 0
    for c, s_ in chunks:
        piv = sweep.pivots
        first = _turned_clearance(c, s_, x[piv], z[piv], sweep.apy_piv, sweep.apy_by_piv, sweep.terms2) - radii[piv]
        nearest = np.minimum.reduceat(first, sweep.pivot_starts, axis=1)
        lowest = (first[:, :, None] + sweep.bound[None]).max(axis=1)
        weighed += len(piv) * len(c) + int(((lowest <= nearest[:, sweep.owner] + sweep.margin_m)
                                            & sweep.others[None]).sum())
        total += len(c) * len(radii)
    times = {"full": math.inf, "pruned": math.inf}
    for _ in range(repeat):
        for k, fn in (("full", full), ("pruned", pruned)):
            c0 = time.thread_time()
            fn()
            times[k] = min(times[k], time.thread_time() - c0)
    return {k: v * 1e3 for k, v in times.items()}, weighed, total


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("calls", nargs="+")
    ap.add_argument("--repeat", type=int, default=30)
    args = ap.parse_args()
    calls = [c for f in args.calls for c in pickle.loads(Path(f).read_bytes())]
    best = {"full": [], "pruned": []}
    weighed = total = 0
    for call in calls:
        times, w, t = measure(call, args.repeat)
        weighed, total = weighed + w, total + t
        for k, v in times.items():
            best[k].append(v)
    print(f"{len(calls)} calls, every chunk's separations identical to the bit; sphere clearances weighed "
          f"{weighed}/{total} ({100 * weighed / total:.1f} %, pivots included)")
    for k, v in best.items():
        print(f"{k:7s} p50 {np.median(v):.3f}  mean {np.mean(v):.3f} ms (all chunks of a call, best of {args.repeat})")


if __name__ == "__main__":
    main()
