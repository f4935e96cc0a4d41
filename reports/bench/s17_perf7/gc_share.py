"""How much of each stage's tail is the garbage collector, from prof_gc.py runs.

    python gc_share.py RUN.json [RUN.json ...]

Per run: the collections that ran inside frames (count, CPU by generation); per stage, its p50 / p99 / max
over all frames and its p99 / max with the collector's CPU inside it taken out; and the frames whose stage
exceeds its own p50 by more than 0.7 ms, with how much of that was the collector.
"""
from __future__ import annotations

import json
import sys

import numpy as np

STAGES = ["tracker", "lifter", "calibration", "monitor", "people_log", "link_poll", "act", "link_send", "backfires"]


def main(paths):
    for path in paths:
        d = json.loads(open(path).read())
        frames = d["frames"][1:]  # frame 0 is the warm-up
        print(f"== {path}")
        for g in (0, 1, 2):
            v = [f.get(f"gc{g}", 0.0) for f in frames if f.get(f"gc{g}")]
            print(f"  gen{g} collections in frames: {len(v)}, CPU {sum(v) * 1e3:.2f} ms, max {max(v, default=0) * 1e3:.2f} ms")
        cpu = np.array([f["cpu"] for f in frames]) * 1e3
        nogc = cpu - np.array([sum(f.get(f"gc{g}", 0.0) for g in (0, 1, 2)) for f in frames]) * 1e3
        print(f"  frame CPU p50 {np.percentile(cpu, 50):.3f} p99 {np.percentile(cpu, 99):.3f} max {cpu.max():.3f}; "
              f"without the collector p99 {np.percentile(nogc, 99):.3f} max {nogc.max():.3f}")
        print(f"  {'stage':12s} {'p50':>7s} {'p99':>7s} {'max':>7s} {'p99-gc':>7s} {'max-gc':>7s} {'gc ms':>7s} {'n':>3s}")
        for s in STAGES:
            v = np.array([f.get(s, 0.0) for f in frames]) * 1e3
            g = np.array([f.get(f"gc@{s}", 0.0) for f in frames]) * 1e3
            w = v - g
            print(f"  {s:12s} {np.percentile(v, 50):7.3f} {np.percentile(v, 99):7.3f} {v.max():7.3f} "
                  f"{np.percentile(w, 99):7.3f} {w.max():7.3f} {g.sum():7.2f} {int((g > 0).sum()):3d}")
        base = {s: np.percentile([f.get(s, 0.0) for f in frames if f.get(s)], 50) if any(f.get(s) for f in frames) else 0
                for s in STAGES}
        spikes = []
        for i, f in enumerate(frames, start=1):
            for s in STAGES:
                ex = f.get(s, 0.0) - base[s]
                if f.get(s) and ex > 0.7e-3:
                    spikes.append((ex, i, s, f.get(f"gc@{s}", 0.0)))
        spikes.sort(reverse=True)
        n_gc = sum(1 for ex, _, _, g in spikes if g > 0.5 * ex)
        print(f"  stage spikes > p50 + 0.7 ms: {len(spikes)}, of which mostly the collector: {n_gc}")
        for ex, i, s, g in spikes[:15]:
            print(f"    frame {i:5d} {s:12s} +{ex * 1e3:.2f} ms, collector {g * 1e3:.2f} ms")


if __name__ == "__main__":
    main(sys.argv[1:])
