"""The bench's robot scenario frame by frame, in-process, on its simulated clock: every frame's and tick's CPU time
and, to the bit, what each decided and sent (session 24, issue 13/14: a cheaper frame, the same decisions).

Drives bench.robot_cycle's own pieces as session 23's prof_frame.py does (``_box``, ``_Frames``,
``_known_calibration``, ``arm_on_bus``, ``RobotLoop``, ``_schedule``: two simulated workers, the shipped box
configuration, the int8 lifter on 1 thread, the product's CAN link to the arm stand-in), so two trees get the same
inputs in the same order. Run from a tree (its code is imported):

    cd TREE && OMP_NUM_THREADS=1 /work/main/.venv/bin/python reports/bench/s24_react/frame24.py \\
        --seconds 60 --npz /tmp/react24/workers60.npz --out OUT.json [--mode trace|lockstep|stages]

Writes OUT.json: per frame its CPU (``time.thread_time``, this thread's), its command kind (bench.robot_cycle's
kinds: speed, alarm, stop, retract, escape, resume, move; None) and per tick its CPU; and the trace: per frame the
state, reason, distance (``float.hex``), command, the per-person log (``FrameRecord.people``, read after the frame),
and the id and bytes of every CAN frame the runtime handed to the bus in that frame or tick (E2E counter and CRC
included). ``--mode stages`` also hashes what the stages hand each other (tracker ids, lifted poses, calibrated
people, the monitor's inputs, decisions, head estimates and kept bodies) into ``stage_digest``; ``--mode lockstep``
runs each slot when a line comes on stdin and prints its CPU (``lockstep24.py``).
"""
from __future__ import annotations

import argparse
import hashlib
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path.cwd()))
sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "s23_perf"))

from prof_frame import PAYLOADS, _frames_and_ticks, _record_payloads, bench_config  # noqa: E402 - session 23's pieces

import bench.robot_cycle as rc  # noqa: E402
import edge_runtime.robot.calibration as calmod  # noqa: E402
import edge_runtime.robot.hazard as hz  # noqa: E402
import edge_runtime.robot.keypoints as kpmod  # noqa: E402
import edge_runtime.robot.lifter as liftmod  # noqa: E402

STAGES = hashlib.sha256()


def _feed(*values) -> None:
    for v in values:
        STAGES.update(v.tobytes() if isinstance(v, np.ndarray) else repr(v).encode())


def _wrap(owner, name: str, before=None, after=None) -> None:
    """``owner.name`` wrapped: ``before(self, *args, **kwargs)`` and ``after(self, result)`` feed the stage digest
    (whatever the signature: a tree may have added arguments)."""
    fn = getattr(owner, name)

    def wrapped(self, *args, **kwargs):
        if before:
            before(self, *args, **kwargs)
        out = fn(self, *args, **kwargs)
        if after:
            after(self, out)
        return out

    setattr(owner, name, wrapped)


def _observed(self, t_s, people, effector_m, arm_q_rad=None, unseen=None, rays=None, *rest, **kw):
    _feed("observe", t_s, sorted(people), *people.values(), effector_m, arm_q_rad, unseen, rays)


def _decided(self, d) -> None:
    _feed(d.state, d.reason, d.distance_m, d.worker, d.speed_scale, d.coming, self._scale)
    for wid, est in self.estimates.items():
        _feed(wid, est.position_m, est.velocity_mps, est.predicted_m)
    for wid, seen in self._seen.items():
        _feed(wid, seen.t_s, seen.person_m, seen.speed_mps, *seen.spheres,
              None if seen.clear_of is None else float(seen.clear_of[1]))


def _digest_stages() -> None:
    """What each stage hands the next, into :data:`STAGES` (session 23's digest, signature-agnostic)."""
    _wrap(kpmod.PersonTracker, "update", after=lambda self, out: _feed("tracker", [(p.id, p.source_id) for p in out]))

    def lifted(self, out):
        for pid, pose in out:
            _feed("lift", pid, pose.valid, pose.reason, pose.joints_cam_m, pose.root_cam_m, pose.observed, pose.held,
                  pose.joints_model_cam_m, pose.missing, pose.warming_up)

    _wrap(liftmod.PeopleLifter, "push", after=lifted)
    _wrap(calmod.Calibration, "to_robot", before=lambda self, j, observed=None, ids=None: _feed("cal", j, observed, ids),
          after=lambda self, out: _feed(out))
    _wrap(hz.HazardMonitor, "observe", before=_observed, after=_decided)


def _bytes(payloads: list) -> list:
    return [[fid, data.hex()] for fid, data in payloads]


def run(seconds: float, npz: Path, mode: str) -> dict:
    from edge_runtime.core import heap

    cfg = bench_config(seconds, npz)
    _record_payloads()
    if mode == "stages":
        _digest_stages()
    sim = rc._SimClock()
    box = rc._box(cfg.zones)
    feed = rc._Frames(cfg, box, np.load(cfg.worker_npz))
    frames, ticks, trace = [], [], []
    with rc_arm(cfg, sim) as (bus, echo, link):
        mode_id = {m.name: m.frame_id for m in link.codec.db.messages}["ROBOT_MODE_CMD"]
        loop = rc.bench_loop(link, box, feed, sim)
        heap.settle()  # as the bench and `python -m edge_runtime robot` do once the loop is built
        for k in _frames_and_ticks(cfg.seconds, sim, echo):
            if mode == "lockstep":  # wait for lockstep24.py's turn (outside the timed slot)
                sys.stdin.readline()
            before = rc._counters(loop)
            c0 = time.thread_time()
            rec = loop.tick() if k == rc.TICK else feed(loop, k)
            cpu = time.thread_time() - c0
            if mode == "lockstep":
                print("tick" if k == rc.TICK else "frame", cpu, flush=True)
            sent = [fid for _, fid in bus.sent]
            del bus.sent[:]
            payloads = _bytes(PAYLOADS)
            del PAYLOADS[:]
            if k == rc.TICK:
                ticks.append(cpu)
                if payloads:
                    trace.append({"tick_after_frame": len(frames) - 1, "sent": payloads})
                continue
            kind = None if rec.command is None else rc._kind(rec.command, before, rc._counters(loop), set(sent),
                                                                mode_id)
            frames.append({"cpu": cpu, "kind": kind})
            trace.append({"frame": k, "state": rec.state, "reason": rec.reason, "distance": rec.distance_m.hex(),
                          "command": rec.command, "kind": kind, "sent": payloads,
                          "people": json.loads(json.dumps(rec.people))})  # the log, made outside the timed frame
        status = {k: v for k, v in loop.status().items() if isinstance(v, (int, float, str))}
    digest = hashlib.sha256(json.dumps(trace, sort_keys=True).encode()).hexdigest()
    out = {"tree": str(Path.cwd()), "seconds": seconds, "mode": mode, "frames": frames, "ticks": ticks,
           "trace": trace, "trace_digest": digest, "status": status}
    if mode == "stages":
        out["stage_digest"] = STAGES.hexdigest()
    return out


def rc_arm(cfg, sim):
    """bench.arm_echo.arm_on_bus on the simulated clock, on a channel of this run's own."""
    import bench.arm_echo as ae

    return ae.arm_on_bus(f"s24-{id(cfg)}", cfg.arm_posture_rad or rc.ARM_POSTURE_RAD, sim)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seconds", type=float, default=60.0)
    ap.add_argument("--npz", default="/tmp/react24/workers60.npz")
    ap.add_argument("--out", required=True)
    ap.add_argument("--mode", choices=("trace", "stages", "lockstep"), default="trace")
    args = ap.parse_args()
    out = run(args.seconds, Path(args.npz), args.mode)
    Path(args.out).write_text(json.dumps(out))
    cpu = np.array([f["cpu"] for f in out["frames"]]) * 1e3
    print(f"{out['tree']}: trace {out['trace_digest']} stages {out.get('stage_digest', '-')} status "
          f"{json.dumps({k: out['status'][k] for k in ('commands', 'retracts', 'escapes', 'speed_changes', 'stops')})}"
          f"; frames {len(cpu)} CPU p50 {np.median(cpu):.3f} ms mean {cpu.mean():.3f} ms",
          file=sys.stderr if args.mode == "lockstep" else sys.stdout)


if __name__ == "__main__":
    main()
