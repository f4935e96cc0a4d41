"""What a control tick costs, and in what (session 19, task "tick").

Run from a tree (its code is imported):  cd TREE && OMP_NUM_THREADS=1 nice -n 10 env PYTHONPATH=. \
    /work/main/.venv/bin/python reports/bench/s19_tick/tick_prof.py --seconds 60 --out OUT.json [--cprofile OUT.prof]

The bench's robot scenario on its simulated clock, as reports/bench/s15_perf/prof_cycle.py drives it (the same
schedule, frames, ticks and arm slots), with every tick timed by time.thread_time and split into its parts
(inclusive CPU, outermost call only): the loop's link poll (of which the link's own poll: the bus receive and
decode, its heartbeat, its supervision), the loop's acknowledgement checks, the monitor's staleness check, _act
(the motion decision and any command sent), and the loop's own heartbeat call. Each tick is classed by what it
found: a new arm state (the loop took a new report), the link's heartbeat due (sent in this tick), an
acknowledgement pending at its start, a command sent. ``--cprofile`` profiles the ticks only; ``--bare`` times
the ticks without the stage wrappers.
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "s15_perf"))
import prof_cycle as pc  # noqa: E402 - its instrumentation (stage wrappers) and scenario pieces

rc, loopmod, hz = pc.rc, pc.loopmod, pc.hz


def instrument():
    import edge_runtime.robot.link.base as linkbase
    import edge_runtime.robot.link.can as linkcan

    pc.instrument()
    pc._wrap(linkbase.RobotLink, "poll", "link.poll")
    pc._wrap(linkcan.CanRobotLink, "_receive", "link.receive")
    pc._wrap(linkbase.RobotLink, "heartbeat", "link.heartbeat")
    pc._wrap(linkbase.RobotLink, "_supervise", "link.supervise")
    pc._wrap(loopmod.RobotLoop, "_check_ack", "check_ack")
    pc._wrap(loopmod.RobotLoop, "_check_speed_ack", "check_speed_ack")
    pc._wrap(loopmod.RobotLoop, "_check_link_up", "check_link_up")
    pc._wrap(hz.HazardMonitor, "check", "stale_check")
    pc._wrap(loopmod.RobotLoop, "_report_runtime_state", "runtime_state")


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--npz", default="/work/notes/perf/workers.npz")
    ap.add_argument("--out", required=True)
    ap.add_argument("--cprofile", default=None)
    ap.add_argument("--bare", action="store_true", help="no stage wrappers: each tick's whole CPU only (their "
                    "timer calls add ~1-2 us per wrapped call)")
    args = ap.parse_args()

    from bench.arm_echo import HEARTBEAT_FRAME, arm_on_bus
    from edge_runtime.core.manifest import ASSETS_DIR, load_manifest

    lifter = rc.lifter_entry(load_manifest(ASSETS_DIR)["models"])
    cfg = rc.RobotConfig(args.npz, args.seconds, "", lifter["precision"], rc._arm_posture(), simulated=True)
    if not args.bare:
        instrument()
    sim = rc._SimClock()
    box = rc._box(cfg.zones)
    feed = rc._Frames(cfg, box, np.load(cfg.worker_npz))
    prof = None
    if args.cprofile:
        import cProfile
        prof = cProfile.Profile()
    ticks = []
    with arm_on_bus(f"tick-prof-{id(cfg)}", cfg.arm_posture_rad or rc.ARM_POSTURE_RAD, sim) as (bus, echo, link):
        hb_id = next(m.frame_id for m in link.codec.db.messages if m.name == HEARTBEAT_FRAME)
        loop = loopmod.RobotLoop(link, calibration=rc._known_calibration(box.calibration), zones=box.zones,
                                 tracker=box.tracker, params=box.robot_loop, clock=sim)
        t_start = sim()
        echo.serve(t_start)
        for due, k in rc._schedule(cfg.seconds):
            sim.wait_until(t_start + due)
            if k == rc.ARM:
                echo.serve(sim())
                continue
            if k != rc.TICK:
                feed(loop, k)
                del bus.sent[:], pc.PAYLOADS[:]
                continue
            seen, pending = loop._seen_state, (loop._pending is not None or loop._speed_pending is not None)
            pc.CUR.clear()
            if prof:
                prof.enable()
            c0 = time.thread_time()
            loop.tick()
            cpu = time.thread_time() - c0
            if prof:
                prof.disable()
            ids = [fid for _, fid in bus.sent]
            del bus.sent[:], pc.PAYLOADS[:]
            ticks.append({"cpu": cpu, **pc.CUR, "new_state": loop._seen_state is not seen, "ack_pending": pending,
                          "heartbeat": hb_id in ids, "command": any(i != hb_id for i in ids),
                          "escape_planned": "plan_escape_turn" in pc.CUR})
    if prof:
        prof.dump_stats(args.cprofile)
    Path(args.out).write_text(json.dumps({"tree": str(Path.cwd()), "seconds": args.seconds, "ticks": ticks}))
    summarize(ticks)


PARTS = ("link_poll", "link.poll", "link.receive", "link.heartbeat", "link.supervise", "check_link_up", "check_ack",
         "check_speed_ack", "stale_check", "act", "link_send", "runtime_state", "escape", "plan_escape_turn")


def summarize(ticks):
    def row(name, ts):
        c = np.array([t["cpu"] for t in ts]) * 1e6
        if not len(c):
            return
        print(f"{name:44s} n {len(c):5d}  p50 {np.percentile(c, 50):7.1f}  p99 {np.percentile(c, 99):7.1f}  "
              f"mean {c.mean():7.1f} us")
        parts = []
        for s in PARTS:
            v = np.array([t.get(s, 0.0) for t in ts]) * 1e6
            if v.any():
                parts.append(f"{s} {np.percentile(v, 50):.1f}/{v.mean():.1f}")
        print("      parts p50/mean us: " + ", ".join(parts))

    quiet = [t for t in ticks if not t["command"] and not t["escape_planned"]]
    row("all ticks", ticks)
    row("ticks sending a command", [t for t in ticks if t["command"]])
    row("no command: all", quiet)
    for ns in (True, False):
        for hb in (True, False):
            for ack in (True, False):
                row(f"no command: new_state={ns:d} heartbeat={hb:d} ack_pending={ack:d}",
                    [t for t in quiet if t["new_state"] == ns and t["heartbeat"] == hb and t["ack_pending"] == ack])


if __name__ == "__main__":
    if len(sys.argv) > 2 and sys.argv[1] == "--summarize":
        summarize(json.loads(Path(sys.argv[2]).read_text())["ticks"])
    else:
        main()
