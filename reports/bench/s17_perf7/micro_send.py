"""Where a command's link_send goes, warm, per call (thread CPU, best of 7 rounds of 300 calls):
the product's encoding (codec: cantools + E2E, payload cached or not), python-can's virtual bus send
(the bench's transport: a deepcopy of the message per receiving bus), and the link's whole call.

    cd TREE && PYTHONPATH=. /work/main/.venv/bin/python reports/bench/s17_perf7/micro_send.py
"""
from __future__ import annotations

import time

import numpy as np

from bench.arm_echo import arm_on_bus


def per_call_us(fn, n=300, rounds=7) -> float:
    best = float("inf")
    for _ in range(rounds):
        t0 = time.thread_time()
        for i in range(n):
            fn(i)
        best = min(best, (time.thread_time() - t0) / n)
    return best * 1e6


def main():
    rng = np.random.default_rng(1)
    targets = [(rng.uniform(-0.8, 0.8), rng.uniform(-0.3, 0.6), rng.uniform(0.3, 0.9)) for _ in range(300 * 7 * 3)]
    it = iter(range(10**9))
    with arm_on_bus("perf7-micro", np.zeros(7)) as (bus, echo, link):
        codec = link.codec
        msg = codec.speed_frame(1, 0.5)
        rows = {
            "codec.speed_frame (payload cached)": lambda i: codec.speed_frame(i % 16, 0.5),
            "codec.target_frames (new position: cantools encodes 2 messages)":
                lambda i: codec.target_frames(i % 16, targets[next(it)], 0.1, 0.2, False),
            "VirtualBus.send of one frame (bench transport)": lambda i: bus.send(msg),
            "link.set_speed (whole call, one frame)": lambda i: link.set_speed(0.5),
            "link.move_to (whole call, two frames, new position)":
                lambda i: link.move_to(targets[next(it)], 0.1, 0.2),
        }
        for name, fn in rows.items():
            us = per_call_us(fn)
            while echo.bus.recv(timeout=0) is not None:  # keep the echo's queue from growing
                pass
            del bus.sent[:]
            print(f"{us:8.1f} us  {name}")


if __name__ == "__main__":
    main()
