"""Timing and memory primitives shared by every bench measurement (numpy and the standard library).

* :func:`time_calls` times each call alone with ``time.perf_counter_ns``, the
  garbage collector paused, after an untimed warm-up; :func:`interleaved_calls` does the
  same for several functions in turn (``export.quantize`` compares int8 variants with it);
* :func:`summarize` turns per-call nanoseconds into the reported statistics
  (microseconds: p50, p99, mean, min, max);
* :func:`rss_mb` / :func:`peak_rss_mb` read the process's resident memory now and
  at its peak (``VmRSS`` / ``VmHWM`` in ``/proc/self/status``; ``ru_maxrss`` elsewhere).
"""
from __future__ import annotations

import gc
import resource
import time
from typing import Callable

import numpy as np


def time_calls(fn: Callable[[], object], n: int, warmup: int) -> np.ndarray:
    """Wall time of ``n`` single calls of ``fn`` in ns, after ``warmup`` untimed calls."""
    return interleaved_calls({"": fn}, n, rounds=1, warmup=warmup)[""]


def interleaved_calls(fns: dict[str, Callable[[], object]], n: int, rounds: int, warmup: int
                      ) -> dict[str, np.ndarray]:
    """Wall time in ns of each single call of every function of ``fns``, after ``warmup`` untimed
    calls of each: ``rounds`` rounds in which each function in turn makes ``n // rounds`` calls
    (at least one), so that functions compared with each other share the machine's noise."""
    for fn in fns.values():
        for _ in range(warmup):
            fn()
    per = max(1, n // rounds) if n > 0 else 0
    times = {k: np.empty(per * rounds, np.int64) for k in fns}
    clock = time.perf_counter_ns
    was = gc.isenabled()
    gc.disable()
    try:
        for r in range(rounds):
            for k, fn in fns.items():
                buf = times[k]
                for i in range(r * per, (r + 1) * per):
                    t0 = clock()
                    fn()
                    buf[i] = clock() - t0
    finally:
        if was:
            gc.enable()
    return times


def summarize(times_ns) -> dict:
    """p50, p99, mean, min and max in microseconds (2 decimals), and n."""
    t = np.asarray(times_ns, dtype=np.float64) / 1e3
    if t.size == 0:
        return {"p50_us": None, "p99_us": None, "mean_us": None, "min_us": None, "max_us": None, "n": 0}
    return {"p50_us": round(float(np.median(t)), 2), "p99_us": round(float(np.percentile(t, 99)), 2),
            "mean_us": round(float(t.mean()), 2), "min_us": round(float(t.min()), 2),
            "max_us": round(float(t.max()), 2), "n": int(t.size)}


def _status_kb(key: str) -> float | None:
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith(key + ":"):
                    return float(line.split()[1])
    except OSError:
        pass
    return None


def rss_mb() -> float:
    """Resident memory of this process now (MiB)."""
    kb = _status_kb("VmRSS")
    return round((kb if kb is not None else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) / 1024, 1)


def peak_rss_mb() -> float:
    """Peak resident memory of this process so far (MiB): VmHWM, or ru_maxrss."""
    kb = _status_kb("VmHWM")
    return round((kb if kb is not None else resource.getrusage(resource.RUSAGE_SELF).ru_maxrss) / 1024, 1)


def sleep_until(due_s: float) -> None:
    """Sleep (never spin) until ``time.perf_counter()`` reaches ``due_s``."""
    delay = due_s - time.perf_counter()
    if delay > 0:
        time.sleep(delay)


class CpuShare:
    """``with CpuShare() as c: ...`` -> ``c.pct``: process CPU time (every thread) over wall
    time, in % of one core; ``c.wall_s`` the wall time."""

    def __enter__(self) -> "CpuShare":
        self._cpu0, self._t0 = time.process_time(), time.perf_counter()
        return self

    def __exit__(self, *exc) -> None:
        self.wall_s = time.perf_counter() - self._t0
        self.pct = round(100.0 * (time.process_time() - self._cpu0) / max(self.wall_s, 1e-9), 2)
