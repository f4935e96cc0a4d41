"""Session 19: the wearable loop's CPU share at 100 Hz, A/B in one script, variants in separate processes.

Mirrors bench.loops._realtime (blocks of 5 samples every 50 ms on absolute deadlines, the int8 model on
1 thread, AlertPublisher with its heartbeat thread on a virtual bus), pinned to CPU 0, and splits the
process's CPU into the feeding thread's and the rest (the heartbeat thread). Variants:
  base   - the loop's numpy block path, the heartbeat thread sends every heartbeat (session 18's code paths)
  ride   - the heartbeat on the feeding thread's wake-ups (AlertPublisher.beat_if_due), numpy block path
  new    - ride + the block's samples as floats (WearableLoop.feed, SAMPLEWISE_ROWS)
Usage: PYTHONPATH=. python reports/bench/s19_wearable/ab.py VARIANT [SECONDS] [--busy]
"""
import os
import sys
import time

import numpy as np

from bench.loops import WearableConfig, _Wearable, prepare_drive, source_block_samples
from bench.timing import sleep_until
from edge_runtime.wearable import loop as loop_module
from edge_runtime.wearable.sources import SAMPLE_RATE_HZ, ImuBlock

variant = sys.argv[1]
seconds = float(sys.argv[2]) if len(sys.argv) > 2 and not sys.argv[2].startswith("--") else 15.0
load = None
if "--busy" in sys.argv:
    from bench.machine import LoadGenerator

    load = LoadGenerator([1])
    load.__enter__()
npy, start = prepare_drive(3, 1, f"/tmp/s19_wearable_drive_{os.getpid()}.npy")
acc = np.load(npy).astype(np.float32)
os.sched_setaffinity(0, {0})
if variant != "new":
    loop_module.SAMPLEWISE_ROWS = 0  # every block through the numpy path
w = _Wearable(WearableConfig(str(npy), start))
bs = source_block_samples(None)
period_s = bs / SAMPLE_RATE_HZ
blocks = int(seconds * SAMPLE_RATE_HZ) // bs
w.pub.start()
time.sleep(0.3)
busy = np.empty(blocks)
c0, thread0, t0 = time.process_time(), time.thread_time(), time.perf_counter()
for k in range(blocks):
    sleep_until(t0 + k * period_s)
    a = time.perf_counter()
    i = start + k * bs
    if variant == "base":  # the heartbeat thread alone
        w.t_fed = time.monotonic()
        w.loop.feed(ImuBlock(i / SAMPLE_RATE_HZ, acc[i:i + bs], True, w.t_fed))
    else:
        w.feed(i, bs, acc)
    busy[k] = time.perf_counter() - a
wall_s = time.perf_counter() - t0
cpu_s, main_s = time.process_time() - c0, time.thread_time() - thread0
w.pub.close()
if load is not None:
    load.__exit__(None, None, None)
os.unlink(npy)
print(f"{variant:5s} {time.strftime('%H:%M:%S', time.gmtime())} process {100 * cpu_s / wall_s:.3f} % "
      f"(feeding thread {100 * main_s / wall_s:.3f}, rest {100 * (cpu_s - main_s) / wall_s:.3f}); "
      f"block p50 {np.median(busy) * 1e6:.0f} us, mean {busy.mean() * 1e6:.0f} us; heartbeats {w.pub.heartbeats_sent}; "
      f"captures {w.loop.stats.captures}; load {os.getloadavg()[0]:.2f}")
