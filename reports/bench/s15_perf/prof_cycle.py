"""Per-frame CPU profile of the bench's robot scenario (bench/robot_cycle.py), stage by stage.

Run from a tree (its code is imported):  cd TREE && OMP_NUM_THREADS=1 nice -n 10 \
    /work/main/.venv/bin/python /work/notes/perf/prof_cycle.py --seconds 60 --out OUT.json [--cprofile OUT.prof]

Drives bench.robot_cycle's own pieces (_box, _Frames, _known_calibration, arm_on_bus, RobotLoop, _schedule) on
its simulated clock (the same frames, ticks and arm slots; deterministic, so two trees get the same inputs), and
times every frame and tick with time.thread_time (CPU of this thread), and inside them the stages by wrapping
stable entry points (inclusive CPU time, outermost call only). A frame is an "escape" frame when
plan_escape_turn ran in it. Also writes a digest of every frame's decision and every command sent, to show
two trees decide the same.
"""
from __future__ import annotations

import argparse
import functools
import hashlib
import json
import sys
import time
from collections import defaultdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path.cwd()))

import bench.robot_cycle as rc  # noqa: E402
import edge_runtime.robot.calibration as calmod  # noqa: E402
import edge_runtime.robot.hazard as hz  # noqa: E402
import edge_runtime.robot.keypoints as kpmod  # noqa: E402
import edge_runtime.robot.lifter as liftmod  # noqa: E402
import edge_runtime.robot.loop as loopmod  # noqa: E402

CUR: dict = defaultdict(float)
ACTIVE: set = set()
CALLS: dict = defaultdict(int)


def _wrap(owner, name: str, stage: str):
    fn = getattr(owner, name)

    @functools.wraps(fn)
    def w(*a, **k):
        if stage in ACTIVE:
            return fn(*a, **k)
        ACTIVE.add(stage)
        c0 = time.thread_time()
        try:
            return fn(*a, **k)
        finally:
            CUR[stage] += time.thread_time() - c0
            CALLS[stage] += 1
            ACTIVE.discard(stage)

    setattr(owner, name, w)


PAYLOADS: list = []


def instrument():
    import bench.arm_echo as ae

    send = ae.StampedBus.send

    def recorded(self, msg, timeout=None):  # every frame the runtime hands to the bus, with its bytes
        PAYLOADS.append((msg.arbitration_id, bytes(msg.data)))
        return send(self, msg, timeout)

    ae.StampedBus.send = recorded
    _wrap(kpmod.PersonTracker, "update", "tracker")
    _wrap(liftmod.PeopleLifter, "push", "lifter")
    _wrap(loopmod, "lifter_rays", "rays")
    _wrap(calmod.Calibration, "to_robot", "calibration")
    _wrap(hz.HazardMonitor, "observe", "monitor")            # head trackers + separation + level
    _wrap(hz.HazardMonitor, "_speed_and_separation", "separation")
    _wrap(loopmod.RobotLoop, "_people", "people_log")
    _wrap(loopmod.RobotLoop, "_poll_link", "link_poll")
    _wrap(loopmod.RobotLoop, "_act", "act")                  # motion decision + link sends
    _wrap(loopmod.RobotLoop, "_escape", "escape")
    _wrap(loopmod, "plan_escape_turn", "plan_escape_turn")
    _wrap(hz.HazardMonitor, "escape_people", "escape_people")
    _wrap(loopmod.RobotLoop, "_retract_backfires", "backfires")
    _wrap(loopmod.RobotLoop, "_call", "link_send")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--npz", default="/work/notes/perf/workers.npz")
    ap.add_argument("--out", required=True)
    ap.add_argument("--cprofile", default=None)
    args = ap.parse_args()

    from edge_runtime.core.manifest import ASSETS_DIR, load_manifest

    entries = load_manifest(ASSETS_DIR)["models"]
    lifter = rc.lifter_entry(entries)
    npz = Path(args.npz)
    if not npz.exists():
        rc.prepare_workers(npz, args.seconds, lifter, args.seed, *rc.box_camera(rc._box()))
    posture = rc._arm_posture()
    cfg = rc.RobotConfig(str(npz), args.seconds, "", lifter["precision"], posture, simulated=True)
    instrument()

    sim = rc._SimClock()
    box = rc._box(cfg.zones)
    feed = rc._Frames(cfg, box, np.load(cfg.worker_npz))
    frames, ticks = [], []
    digest = hashlib.sha256()
    payloads = hashlib.sha256()  # every CAN frame's id and bytes the runtime sent, in order
    prof = None
    if args.cprofile:
        import cProfile
        prof = cProfile.Profile()
    from bench.arm_echo import arm_on_bus

    channel = f"perf-prof-{id(cfg)}"
    with arm_on_bus(channel, cfg.arm_posture_rad or rc.ARM_POSTURE_RAD, sim) as (bus, echo, link):
        loop = loopmod.RobotLoop(link, calibration=rc._known_calibration(box.calibration), zones=box.zones,
                                 tracker=box.tracker, params=box.robot_loop, clock=sim)
        t_start = sim()
        echo.serve(t_start)
        if prof:
            prof.enable()
        for due, k in rc._schedule(cfg.seconds):
            sim.wait_until(t_start + due)
            if k == rc.ARM:
                echo.serve(sim())
                continue
            CUR.clear()
            c0 = time.thread_time()
            rec = loop.tick() if k == rc.TICK else feed(loop, k)
            cpu = time.thread_time() - c0
            sent = [(fid) for _, fid in bus.sent]
            del bus.sent[:]
            payload = list(PAYLOADS)
            del PAYLOADS[:]
            item = {"cpu": cpu, **CUR, "escape_planned": "plan_escape_turn" in CUR, "n_sent": len(sent)}
            if k == rc.TICK:
                ticks.append(item)
                digest.update(repr(("T", sent)).encode())
                payloads.update(repr(payload).encode())
            else:
                item["command"] = rec.command
                frames.append(item)
                digest.update(repr((k, rec.state, rec.reason, round(rec.distance_m, 12), rec.command, sent,
                                    [(p["id"], p["nearest_distance_m"]) for p in rec.people])).encode())
                payloads.update(repr(payload).encode())
        if prof:
            prof.disable()
            prof.dump_stats(args.cprofile)
        st = loop.status()
    # every command the arm got, with its arguments (the echo's decoded commands, when it keeps them)
    out = {"tree": str(Path.cwd()), "seconds": args.seconds, "frames": frames, "ticks": ticks,
           "digest": digest.hexdigest(), "payload_digest": payloads.hexdigest(), "calls": dict(CALLS),
           "status": {k: v for k, v in st.items() if isinstance(v, (int, float, str))}}
    Path(args.out).write_text(json.dumps(out))
    summarize(out)


def pct(x, q):
    return float(np.percentile(x, q)) * 1e3 if len(x) else float("nan")


def summarize(out):
    frames = out["frames"]
    kinds = {"all frames": frames,
             "ordinary (no escape plan)": [f for f in frames if not f["escape_planned"]],
             "escape-planning frames": [f for f in frames if f["escape_planned"]],
             "commanding frames": [f for f in frames if f.get("command")],
             "ticks planning escape": [t for t in out["ticks"] if t["escape_planned"]],
             "all ticks": out["ticks"]}
    stages = ["tracker", "lifter", "rays", "calibration", "monitor", "separation", "people_log", "link_poll", "act",
              "escape", "escape_people", "plan_escape_turn", "backfires", "link_send"]
    print(f"digest {out['digest']}  payload digest {out.get('payload_digest')}")
    print(f"{'kind':28s} {'n':>5s} {'p50 ms':>7s} {'p99 ms':>7s} {'max ms':>7s} {'mean ms':>7s}")
    for name, fs in kinds.items():
        c = [f["cpu"] for f in fs]
        print(f"{name:28s} {len(c):5d} {pct(c, 50):7.3f} {pct(c, 99):7.3f} "
              f"{(max(c) * 1e3 if c else float('nan')):7.3f} {(np.mean(c) * 1e3 if c else float('nan')):7.3f}")
        if name in ("ordinary (no escape plan)", "escape-planning frames", "ticks planning escape") and fs:
            for s in stages:
                v = [f.get(s, 0.0) for f in fs]
                if any(v):
                    print(f"    {s:24s} p50 {pct(v, 50):7.3f}  p99 {pct(v, 99):7.3f}  mean {np.mean(v) * 1e3:7.3f}")


if __name__ == "__main__":
    if len(sys.argv) > 2 and sys.argv[1] == "--summarize":
        summarize(json.loads(Path(sys.argv[2]).read_text()))
    else:
        main()
