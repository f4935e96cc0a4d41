"""Where a robot frame's CPU time goes, without wall-clock percentiles (session 23, issue 13's latency must-hold).

Drives bench.robot_cycle's own pieces (``_box``, ``_Frames``, ``_known_calibration``, ``arm_on_bus``, ``RobotLoop``,
``_schedule``: the bench's scenario, frames, ticks and arm slots) on its simulated clock, so two trees get the same
inputs in the same order and must send the same commands. Three figures, none of them a wall-clock percentile:

* ``--mode stages`` (default): every frame's and tick's CPU time (``time.thread_time``, this thread only: another
  process on the core does not lengthen it) and, inside, the stages by wrapping stable entry points (inclusive, the
  outermost call only); p50/p99/mean per kind of frame.
* ``--mode cprofile``: cProfile on only inside the timed frames (and, separately, the ticks): the top functions by own
  time per frame, and the number of function calls per frame (deterministic: the same code on the same input makes
  the same calls however busy the machine is).
* ``--mode digest``: besides, a digest of what the stages hand each other, to the bit: the tracker's ids, every lifted
  pose (joints, validity), the calibrated robot-frame people, the monitor's head estimates and decisions, the arm
  joint angles and effector it judged against (wrapping the same entry points; the timings then mean nothing).
* ``--mode plain``: the frames' and ticks' CPU time alone (no wrappers: the figure to compare two trees by).
* ``--mode lockstep``: ``plain``, each frame and tick run when a line comes on stdin and its CPU time printed on
  stdout (``lockstep.py`` runs two trees so, alternately, slot by slot).
* always: a digest of every frame's decision (state, reason, distance to the bit, command, the log's per-person
  beliefs) and of every CAN frame the runtime handed to the bus (id and bytes, E2E counter and CRC included), and
  the loop's counters: two trees that print the same digests decided and sent the same.

    cd TREE && OMP_NUM_THREADS=1 /work/main/.venv/bin/python reports/bench/s23_perf/prof_frame.py \
        --seconds 60 --npz /tmp/perf23/workers60.npz --out OUT.json [--mode cprofile]
"""
from __future__ import annotations

import argparse
import cProfile
import hashlib
import json
import pstats
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path.cwd()))

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "s15_perf"))
from prof_cycle import CUR, _wrap  # noqa: E402 - session 15's stage wrapper (inclusive CPU, outermost call only)

import bench.arm_echo as ae  # noqa: E402
import bench.robot_cycle as rc  # noqa: E402
import edge_runtime.robot.calibration as calmod  # noqa: E402
import edge_runtime.robot.hazard as hz  # noqa: E402
import edge_runtime.robot.keypoints as kpmod  # noqa: E402
import edge_runtime.robot.lifter as liftmod  # noqa: E402
import edge_runtime.robot.loop as loopmod  # noqa: E402

STAGES = (  # (owner, attribute, stage name)
    (kpmod.PersonTracker, "update", "tracker"),
    (liftmod.PeopleLifter, "push", "lifter"),
    (liftmod, "_lift", "onnx"),
    (loopmod, "lifter_rays", "rays"),
    (calmod.Calibration, "to_robot", "calibration"),
    (hz.HazardMonitor, "observe", "monitor"),
    (hz.HazardMonitor, "_speed_and_separation", "separation"),
    (loopmod.RobotLoop, "_poll_link", "link_poll"),
    (loopmod.RobotLoop, "_act", "act"),
    (loopmod.RobotLoop, "_escape", "escape"),
    (loopmod, "plan_escape_turn", "plan_escape_turn"),
    (loopmod.RobotLoop, "_retract_backfires", "backfires"),
    (loopmod.RobotLoop, "_call", "link_send"),
)
PAYLOADS: list = []
INNER = hashlib.sha256()


def _feed_inner(*values) -> None:
    for v in values:
        INNER.update(v.tobytes() if isinstance(v, np.ndarray) else repr(v).encode())


def _digest_stages() -> None:
    """Wrap the stages' entry points so that what each hands on goes into :data:`INNER`."""
    update = kpmod.PersonTracker.update

    def tracker(self, t_s, people):
        out = update(self, t_s, people)
        _feed_inner("tracker", [(p.id, p.source_id) for p in out])
        return out

    push = liftmod.PeopleLifter.push

    def lifter(self, t_s, people):
        out = push(self, t_s, people)
        for pid, pose in out:
            _feed_inner("lift", pid, pose.valid, pose.reason, pose.joints_cam_m, pose.root_cam_m, pose.observed,
                        pose.held, pose.joints_model_cam_m, pose.missing, pose.warming_up)
        return out

    to_robot = calmod.Calibration.to_robot

    def calibration(self, joints, observed=None, ids=None):
        out = to_robot(self, joints, observed, ids)
        _feed_inner("calibration", joints, observed, ids, out)
        return out

    observe = hz.HazardMonitor.observe

    def monitor(self, t_s, people, effector_m, arm_q_rad=None, unseen=None, rays=None):
        _feed_inner("observe", t_s, sorted(people), *people.values(), effector_m, arm_q_rad, unseen, rays)
        d = observe(self, t_s, people, effector_m, arm_q_rad, unseen, rays)
        _feed_inner(d.state, d.reason, d.distance_m, d.worker, d.speed_scale, d.coming, self._scale)
        for wid, est in self.estimates.items():
            _feed_inner(wid, est.position_m, est.velocity_mps, est.predicted_m)
        for wid, seen in self._seen.items():
            _feed_inner(wid, seen.t_s, seen.person_m, seen.speed_mps, *seen.spheres,
                        None if seen.clear_of is None else seen.clear_of[1])
        return d

    kpmod.PersonTracker.update = tracker
    liftmod.PeopleLifter.push = lifter
    calmod.Calibration.to_robot = calibration
    hz.HazardMonitor.observe = monitor


def _record_payloads() -> None:
    send = ae.StampedBus.send

    def recorded(self, msg, timeout=None):  # every frame the runtime hands to the bus, with its bytes
        PAYLOADS.append((msg.arbitration_id, bytes(msg.data)))
        return send(self, msg, timeout)

    ae.StampedBus.send = recorded


def bench_config(seconds: float, npz: Path) -> rc.RobotConfig:
    """The bench's robot scenario on its simulated clock (its workers made into ``npz`` when it is not there)."""
    from edge_runtime.core.manifest import ASSETS_DIR, load_manifest

    lifter = rc.lifter_entry(load_manifest(ASSETS_DIR)["models"])
    if not npz.exists():
        rc.prepare_workers(npz, seconds, lifter, 1, *rc.box_camera(rc._box()))
    return rc.RobotConfig(str(npz), seconds, "", lifter["precision"], rc._arm_posture(), simulated=True)


def run(seconds: float, npz: Path, mode: str, dump: str = "") -> dict:
    cfg = bench_config(seconds, npz)
    _record_payloads()
    if mode == "stages":
        for owner, name, stage in STAGES:
            _wrap(owner, name, stage)
    if mode == "digest":
        _digest_stages()
    prof = {"frame": cProfile.Profile(), "tick": cProfile.Profile()} if mode == "cprofile" else None
    sim = rc._SimClock()
    box = rc._box(cfg.zones)
    feed = rc._Frames(cfg, box, np.load(cfg.worker_npz))
    frames, ticks = [], []
    decisions, payloads = hashlib.sha256(), hashlib.sha256()
    with ae.arm_on_bus(f"perf23-{id(cfg)}", cfg.arm_posture_rad or rc.ARM_POSTURE_RAD, sim) as (bus, echo, link):
        loop = loopmod.RobotLoop(link, calibration=rc._known_calibration(box.calibration), zones=box.zones,
                                 tracker=box.tracker, params=box.robot_loop, clock=sim)
        from edge_runtime.core import heap

        heap.settle()  # as the bench and `python -m edge_runtime robot` do once the loop is built
        for k in _frames_and_ticks(cfg.seconds, sim, echo):
            if mode == "lockstep":  # wait for lockstep.py's turn (outside the timed frame)
                sys.stdin.readline()
            CUR.clear()
            p = prof and prof["tick" if k == rc.TICK else "frame"]
            if p:
                p.enable()
            c0 = time.thread_time()
            rec = loop.tick() if k == rc.TICK else feed(loop, k)
            cpu = time.thread_time() - c0
            if p:
                p.disable()
            if mode == "lockstep":
                print("tick" if k == rc.TICK else "frame", cpu, flush=True)
            sent = [fid for _, fid in bus.sent]
            del bus.sent[:]
            payloads.update(repr(PAYLOADS).encode())
            del PAYLOADS[:]
            item = {"cpu": cpu, **CUR, "escape_planned": "plan_escape_turn" in CUR}
            if k == rc.TICK:
                ticks.append(item)
                decisions.update(repr(("T", sent)).encode())
            else:
                item["command"] = rec.command
                frames.append(item)
                decisions.update(repr((k, rec.state, rec.reason, rec.distance_m.hex(), rec.command, sent,
                                       rec.people)).encode())  # the log made here, outside the timed frame
        status = {k: v for k, v in loop.status().items() if isinstance(v, (int, float, str))}
    out = {"tree": str(Path.cwd()), "seconds": seconds, "mode": mode, "frames": frames, "ticks": ticks,
           "digest": decisions.hexdigest(), "payload_digest": payloads.hexdigest(), "status": status}
    if mode == "digest":
        out["stage_digest"] = INNER.hexdigest()
    if prof and dump:
        for kind, pr in prof.items():
            pr.dump_stats(f"{dump}.{kind}.prof")
    if prof:
        out["cprofile"] = {kind: _top(p, len(frames if kind == "frame" else ticks)) for kind, p in prof.items()}
    return out


def _frames_and_ticks(seconds: float, sim, echo):
    """The bench's schedule on its simulated clock: yields each frame's index (or ``rc.TICK``) at its due time,
    the arm stand-in serving its own slots in between (outside every timed frame and tick)."""
    t_start = sim()
    echo.serve(t_start)
    for due, k in rc._schedule(seconds):
        sim.wait_until(t_start + due)
        if k != rc.ARM:
            yield k
        else:
            echo.serve(sim())


def _top(p: cProfile.Profile, n: int, rows: int = 40) -> dict:
    """Per frame (or tick): function calls, and the top functions by own time (us) with their calls."""
    st = pstats.Stats(p)
    table = sorted(((tt, cc, nc, f"{Path(f).name}:{line}({fn})") for (f, line, fn), (cc, nc, tt, ct, _)
                    in st.stats.items()), reverse=True)
    return {"n": n, "calls_per": round(st.total_calls / n, 1), "own_us_per": round(st.total_tt / n * 1e6, 1),
            "top": [{"fn": name, "own_us_per": round(tt / n * 1e6, 2), "calls_per": round(nc / n, 2)}
                    for tt, cc, nc, name in table[:rows]]}


def _ms(x, q) -> float:
    return float(np.percentile(x, q)) * 1e3 if len(x) else float("nan")


def summarize(out: dict) -> str:
    lines = [f"tree {out['tree']}  mode {out['mode']}  {out['seconds']:g} s simulated",
             f"digest {out['digest']}", f"payload digest {out['payload_digest']}",
             f"stage digest {out.get('stage_digest', '-')}",
             "status " + json.dumps({k: out["status"][k] for k in ("commands", "stops", "retracts", "escapes",
                                                                     "speed_changes", "acked", "backfired")}),
             f"{'kind':28s} {'n':>5s} {'p50 ms':>7s} {'p99 ms':>7s} {'max ms':>7s} {'mean ms':>7s}"]
    frames = out["frames"]
    kinds = {"all frames": frames, "ordinary frames": [f for f in frames if not f["escape_planned"]],
             "escape-planning frames": [f for f in frames if f["escape_planned"]],
             "commanding frames": [f for f in frames if f.get("command")], "all ticks": out["ticks"]}
    for name, fs in kinds.items():
        c = [f["cpu"] for f in fs]
        if not c:
            continue
        lines.append(f"{name:28s} {len(c):5d} {_ms(c, 50):7.3f} {_ms(c, 99):7.3f} {max(c) * 1e3:7.3f} "
                     f"{np.mean(c) * 1e3:7.3f}")
        if name in ("all frames", "escape-planning frames", "all ticks") and out["mode"] == "stages":
            for _, _, s in STAGES:
                v = [f.get(s, 0.0) for f in fs]
                if any(v):
                    lines.append(f"    {s:24s} p50 {_ms(v, 50):7.3f}  p99 {_ms(v, 99):7.3f}  "
                                 f"mean {np.mean(v) * 1e3:7.3f}")
    for kind, t in out.get("cprofile", {}).items():
        lines.append(f"cProfile per {kind} ({t['n']}): {t['calls_per']} function calls, {t['own_us_per']} us "
                     "(profiled: inflated by the profiler's own cost)")
        lines += [f"    {r['own_us_per']:8.2f} us {r['calls_per']:8.2f} calls  {r['fn']}" for r in t["top"]]
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--npz", default="/tmp/perf23/workers60.npz")
    ap.add_argument("--out", required=True)
    ap.add_argument("--mode", choices=("stages", "cprofile", "plain", "digest", "lockstep"), default="stages")
    ap.add_argument("--dump", default="", help="cprofile: write DUMP.frame.prof and DUMP.tick.prof")
    args = ap.parse_args()
    out = run(args.seconds, Path(args.npz), args.mode, args.dump)
    Path(args.out).write_text(json.dumps(out))
    print(summarize(out), file=sys.stderr if args.mode == "lockstep" else sys.stdout)


if __name__ == "__main__":
    if len(sys.argv) > 2 and sys.argv[1] == "--summarize":
        print(summarize(json.loads(Path(sys.argv[2]).read_text())))
    else:
        main()
