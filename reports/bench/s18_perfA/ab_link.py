"""The CAN link's receive and encode, this tree against another, in ONE process, poll by poll (the machine is
shared: two processes run minutes apart see different loads, one process alternating A and B sees the same).

The other tree's link modules (canbus/e2e.py, robot/link/protocol.py, base.py, can.py) are loaded from their files
under their own names, each bound to the others of its tree. Every captured poll (capture_link.py) is replayed
through both links, in alternating order, each on a list-backed bus (no python-can transport); every captured
encode likewise through both codecs. Prints the per-poll and per-encode CPU of each and checks that both give the
same states, counters and bytes.
    cd TREE && OMP_NUM_THREADS=1 nice -n 10 env PYTHONPATH=. python reports/bench/s18_perfA/ab_link.py CAP.pkl OTHER_TREE \
        [RUNS] [EVICT_MB]
EVICT_MB > 0: before each timed poll and encode, untimed, a pass over that many MB of memory, so that each runs
with cold caches, as in a frame after the tracker and the lifter (warm by default).
"""
from __future__ import annotations

import importlib.util
import pickle
import sys
import time
from collections import defaultdict
from pathlib import Path

import can
import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from micro_link import ListBus  # noqa: E402

import edge_runtime.canbus.e2e  # noqa: E402,F401
import edge_runtime.robot.link.base  # noqa: E402,F401
import edge_runtime.robot.link.can  # noqa: E402,F401
import edge_runtime.robot.link.protocol  # noqa: E402,F401

COMMANDS = {"ROBOT_TARGET_ORIENT", "ROBOT_TARGET_POS", "ROBOT_MODE_CMD", "ROBOT_ALARM_CMD", "ROBOT_SPEED_CMD"}
MODULES = ("edge_runtime.canbus.e2e", "edge_runtime.robot.link.protocol", "edge_runtime.robot.link.base",
           "edge_runtime.robot.link.can")


def load_tree(root: Path) -> dict:
    """The link modules of the tree at ``root``, each importing the others of that tree."""
    saved = {name: sys.modules[name] for name in MODULES}
    out = {}
    try:
        for name in MODULES:
            path = root / (name.replace(".", "/") + ".py")
            spec = importlib.util.spec_from_file_location(name, path)
            mod = importlib.util.module_from_spec(spec)
            sys.modules[name] = mod  # what the next module imports by this name: this tree's
            spec.loader.exec_module(mod)
            out[name] = mod
    finally:
        sys.modules.update(saved)
    return out


def _state_key(st):
    return None if st is None else repr(sorted((k, (v.tolist() if isinstance(v, np.ndarray) else v))
                                               for k, v in vars(st).items()))


def main():
    cap = pickle.load(open(sys.argv[1], "rb"))
    other = load_tree(Path(sys.argv[2]))
    sides = {"other": other, "this": {name: sys.modules[name] for name in MODULES}}
    reps = int(sys.argv[3]) if len(sys.argv) > 3 else 3
    evict_mb = float(sys.argv[4]) if len(sys.argv) > 4 else 0.0
    junk = np.ones(int(evict_mb * (1 << 20) / 8))

    def evict():
        if junk.size:
            junk.sum()  # reads every cache line of it: the caches hold junk, not the link's code and data
    poll_t = {s: [] for s in sides}
    enc_t = {s: defaultdict(list) for s in sides}
    now = [0.0]  # the replayed poll's time: both links' clock
    for _rep in range(reps):
        now[0] = 0.0
        links = {}
        for s, mods in sides.items():
            bus = ListBus()
            links[s] = (bus, mods["edge_runtime.robot.link.can"].CanRobotLink(
                bus=bus, config=mods["edge_runtime.robot.link.base"].LinkConfig(), clock=lambda: now[0]))
        pt = {s: np.zeros(len(cap["polls"])) for s in sides}
        for i, (t, frames) in enumerate(cap["polls"]):
            now[0] = t
            got = {}
            for s in (("other", "this") if i % 2 else ("this", "other")):
                bus, link = links[s]
                bus.rx.extend(can.Message(arbitration_id=a, data=d, is_extended_id=x) for a, d, x in frames)
                evict()
                c0 = time.thread_time()
                st = link.poll()
                pt[s][i] = time.thread_time() - c0
                got[s] = _state_key(st)
            assert got["this"] == got["other"], (i, got)
        for s in sides:
            poll_t[s].append(pt[s])
            assert repr(vars(links[s][1].stats)) == repr(vars(links["this"][1].stats))
            assert links[s][0].sent == links["this"][0].sent
            assert links[s][1].codec.checker.counts == links["this"][1].codec.checker.counts
        codecs = {s: mods["edge_runtime.robot.link.protocol"].RobotCanCodec() for s, mods in sides.items()}
        for i, (name, signals) in enumerate(cap["encodes"]):
            out = {}
            for s in (("other", "this") if i % 2 else ("this", "other")):
                evict()
                # a command frame as the tree's codec makes one (_command where it has it: no payload cache)
                encode = getattr(codecs[s], "_command", codecs[s].encode) if name in COMMANDS else codecs[s].encode
                c0 = time.thread_time()
                msg = encode(name, **signals)
                enc_t[s][name].append(time.thread_time() - c0)
                out[s] = (msg.arbitration_id, bytes(msg.data), msg.is_extended_id)
            assert out["this"] == out["other"], (name, out)
    n_frames = np.array([len(f) for _, f in cap["polls"]])
    print(f"{len(cap['polls'])} polls, {n_frames.sum()} frames, {reps} runs, {evict_mb:g} MB evicted before each; states, stats, counters, sent and "
          f"encoded bytes identical")
    for s in sides:
        best = np.min(poll_t[s], axis=0)  # each poll's best over the runs
        print(f"{s:6s} ({sys.argv[2] if s == 'other' else 'cwd'}): {best.sum() / n_frames.sum() * 1e6:6.2f} us/frame "
              f"| whole-state poll p50 {np.median(best[n_frames >= 7]) * 1e6:6.1f} us | empty poll p50 "
              f"{np.median(best[n_frames == 0]) * 1e6:5.2f} us")
        print("        encode p50 us: " + ", ".join(f"{k} {np.median(v) * 1e6:.1f}" for k, v in sorted(enc_t[s].items())))


if __name__ == "__main__":
    main()
