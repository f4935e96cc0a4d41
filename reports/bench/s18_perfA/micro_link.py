"""The robot CAN link alone, on captured traffic (capture_link.py): every poll's frames replayed through a fresh
CanRobotLink on a list-backed bus (no python-can transport: what is timed is the product's receive path, from
recv()'s return to the state), and every frame the runtime encoded, encoded again. Prints CPU per poll / frame /
encode and a digest of every state and every encoded frame (two trees must print the same digests).
    cd TREE && OMP_NUM_THREADS=1 nice -n 10 env PYTHONPATH=. python reports/bench/s18_perfA/micro_link.py CAP.pkl"""
from __future__ import annotations

import hashlib
import pickle
import sys
import time
from collections import defaultdict, deque

import can
import numpy as np

from edge_runtime.robot.link.base import LinkConfig
from edge_runtime.robot.link.can import CanRobotLink
from edge_runtime.robot.link.protocol import RobotCanCodec


class ListBus:
    """What CanRobotLink needs of a bus: recv(timeout=0) from a queue of ready messages, send() kept."""

    def __init__(self):
        self.rx: deque = deque()
        self.sent: list = []

    def recv(self, timeout=None):
        return self.rx.popleft() if self.rx else None

    def send(self, msg, timeout=None):
        self.sent.append((msg.arbitration_id, bytes(msg.data)))

    def shutdown(self):
        pass


def replay_polls(cap, digest):
    now = [0.0]
    bus = ListBus()
    link = CanRobotLink(bus=bus, config=LinkConfig(), clock=lambda: now[0])
    per_poll, per_full = [], []
    for t, frames in cap["polls"]:
        msgs = [can.Message(arbitration_id=i, data=d, is_extended_id=x) for i, d, x in frames]
        bus.rx.extend(msgs)
        now[0] = t
        c0 = time.thread_time()
        st = link.poll()
        dt = time.thread_time() - c0
        per_poll.append(dt)
        if len(frames) >= 7:
            per_full.append(dt)
        if digest is not None and st is not None:
            digest.update(repr(sorted((k, (v.tolist() if isinstance(v, np.ndarray) else v))
                                      for k, v in vars(st).items())).encode())
    if digest is not None:
        digest.update(repr((vars(link.stats), bus.sent, link.codec.checker.counts)).encode())
    return np.array(per_poll), np.array(per_full)


def replay_encodes(cap, digest):
    codec = RobotCanCodec()
    by_name = defaultdict(list)
    for name, signals in cap["encodes"]:
        c0 = time.thread_time()
        msg = codec.encode(name, **signals)
        by_name[name].append(time.thread_time() - c0)
        if digest is not None:
            digest.update(repr((msg.arbitration_id, bytes(msg.data), msg.is_extended_id)).encode())
    return by_name


def main():
    cap = pickle.load(open(sys.argv[1], "rb"))
    reps = int(sys.argv[2]) if len(sys.argv) > 2 else 5
    d_rx, d_tx = hashlib.sha256(), hashlib.sha256()
    polls, fulls, encs = [], [], defaultdict(list)
    for r in range(reps):
        p, f = replay_polls(cap, d_rx if r == 0 else None)
        polls.append(p)
        fulls.append(f)
        for name, v in replay_encodes(cap, d_tx if r == 0 else None).items():
            encs[name].append(np.median(v))
    polls = np.min(polls, axis=0)  # each poll's best over the runs: a preempted or disturbed poll is left out
    fulls = np.min(fulls, axis=0)
    n_frames = sum(len(f) for _, f in cap["polls"])
    print(f"rx digest {d_rx.hexdigest()[:16]}  tx digest {d_tx.hexdigest()[:16]}")
    print(f"receive: {len(cap['polls'])} polls, {n_frames} frames, each poll's best of {reps} runs: "
          f"{polls.sum() / n_frames * 1e6:.2f} us/frame (incl. its poll), "
          f"a poll of a whole state p50 {np.median(fulls) * 1e6:.1f} us, an empty poll p50 "
          f"{np.median(polls[[not f for _, f in cap['polls']]]) * 1e6:.1f} us")
    for name, v in sorted(encs.items()):
        print(f"encode {name:22s} p50 {min(v) * 1e6:6.1f} us")


if __name__ == "__main__":
    main()
