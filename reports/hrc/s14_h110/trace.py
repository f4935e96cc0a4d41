"""Frame-by-frame trace of one hard:200 scenario through hrc's own per-scenario path (hrc._run_one),
with hooks (monkeypatches, no product edits) on the runtime loop, the hazard monitor and the simulated arm.
usage: trace.py SEED NAME OUT.json [--suite hard:200|random:200] [--link can|mavlink] [--config BOX.toml] [--fix NAME|PATH.py]
(--fix NAME loads fix_NAME.py beside this file; a path loads that file: session 20's are in ../s20_contact/)"""
import argparse
import json
import math
import time
from pathlib import Path

import numpy as np

from edge_runtime.core.skeleton import HEAD
from edge_runtime.robot import loop as loop_mod
from edge_runtime.robot.hazard import arm_capsules, body_spheres, separation_m
from firmware_sim.scenarios import hrc, hrc_world
from firmware_sim.scenarios.hrc_world import WorldParams, scene_joints

ap = argparse.ArgumentParser()
ap.add_argument("seed", type=int)
ap.add_argument("name")
ap.add_argument("out")
ap.add_argument("--config", default=None)
ap.add_argument("--fix", default="")
ap.add_argument("--suite", default="hard:200")
ap.add_argument("--link", default="can")
a = ap.parse_args()

box = hrc.load_box(a.config)
sc = next(s for s in hrc.scenarios_for(a.suite, a.seed, 2.0) if s.name == a.name)
world = WorldParams(camera_hz=30.0, latency_s=None, labelled_calibration=True)
dt = world.dt_s
n_pre = int(round(world.pre_roll_s / dt))
J = scene_joints(sc, round(1.0 / dt))  # (W, T, 17, 3) the truth, as run_scenario builds it

EV = []      # runtime events (commands, decisions in _desired_motion)
FR = []      # per pose frame: monitor's view
ST = []      # per physics step: arm
CTX = {}


def t_of(clock_s):
    return round(clock_s - n_pre * dt, 3)


RL = loop_mod.RobotLoop
orig_feed, orig_send_motion, orig_send_speed = RL.feed_poses, RL._send_motion, RL._send_speed
orig_escape, orig_backfires, orig_again, orig_refused = RL._escape, RL._retract_backfires, RL._retract_again, \
    RL._retract_refused


def feed_poses(self, poses, t_in_s=None, rays=None):
    CTX["loop"] = self
    rec = orig_feed(self, poses, t_in_s, rays)
    m = self.monitor
    t = t_of(self.clock())
    q = self._last_q
    caps = arm_capsules(q) if q is not None else None
    people = {}
    for wid, out in poses:
        d = {"valid": bool(out.valid)}
        if wid in m._seen and abs(m._seen[wid].t_s - m._last_pose_s) < 1e-9:
            body = m._seen[wid].person_m
            d["lifted_head"] = np.round(body[HEAD], 3).tolist()
            d["lifted_sep_m"] = round(separation_m(*body_spheres(body), caps), 3) if caps is not None else None
        elif wid in m._seen:
            d["lost_age_s"] = round(m._last_pose_s - m._seen[wid].t_s, 3)
        if wid in m._bounded:
            tb, db, pt = m._bounded[wid]
            d["ray_bound_m"] = round(db, 3)
            d["ray_age_s"] = round(m._last_pose_s - tb, 3)
        people[wid] = d
    dec = m.last
    FR.append({"t": t, "state": m.state.name, "reason": m.reason, "level": m.level.name,
               "d": None if not math.isfinite(dec.distance_m) else round(dec.distance_m, 3),
               "worker": dec.worker, "coming": dec.coming, "scale": round(m._scale, 2),
               "lost_stop": list(m._lost_stop), "unlifted_stop": list(m._unlifted_stop),
               "people": people,
               "head_est": None if dec.head is None else np.round(dec.head.position_m, 3).tolist()})
    return rec


def send_motion(self, motion):
    ok = orig_send_motion(self, motion)
    EV.append({"t": t_of(self.clock()), "ev": "motion", "kind": motion.kind.value,
               "pos": None if motion.position_m is None else [round(x, 3) for x in motion.position_m],
               "yaw": None if motion.yaw_rad is None else round(motion.yaw_rad, 3), "ok": ok,
               "escaping": self._escaping, "fallback": self._retract_fallback,
               "state": self.monitor.state.name, "reason": self.monitor.reason})
    return ok


def send_speed(self, v):
    ok = orig_send_speed(self, v)
    EV.append({"t": t_of(self.clock()), "ev": "speed", "v": v, "ok": ok})
    return ok


def escape(self, decision):
    r = orig_escape(self, decision)
    if r is not None:
        EV.append({"t": t_of(self.clock()), "ev": "escape_planned", "pos": list(r.position_m),
                   "yaw": round(r.yaw_rad, 3), "d": round(decision.distance_m, 3), "worker": decision.worker})
    return r


def backfires(self):
    r = orig_backfires(self)
    if r:
        EV.append({"t": t_of(self.clock()), "ev": "backfires", "escaping": self._escaping})
    return r


def again(self, decision):
    r = orig_again(self, decision)
    if r:
        EV.append({"t": t_of(self.clock()), "ev": "retract_again", "d": round(decision.distance_m, 3)})
    return r


def refused(self):
    EV.append({"t": t_of(self.clock()), "ev": "retract_refused"})
    return orig_refused(self)


RL.feed_poses, RL._send_motion, RL._send_speed = feed_poses, send_motion, send_speed
RL._escape, RL._retract_backfires, RL._retract_again, RL._retract_refused = escape, backfires, again, refused


class TracedRobot(hrc_world.SimulatedRobot):
    def step(self, dt_s, advance_clock=True):
        c = self.controller
        arm = c.arm
        t = t_of(self.clock())
        k = int(round(t / dt))
        if 0 <= k < J.shape[1]:
            centres, radii = arm.collision_spheres()
            ee = arm.pose().position_m
            per = {}
            for w in range(J.shape[0]):
                if not np.isfinite(J[w, k, 0, 0]):
                    continue
                dj = np.linalg.norm(J[w, k][:, None] - centres[None], axis=-1) - radii[None]
                de = np.linalg.norm(J[w, k] - ee, axis=-1)
                i, s = np.unravel_index(np.argmin(dj), dj.shape)
                best = float(min(dj.min(), de.min()))
                caps = arm_capsules(arm.q_rad)
                per[w] = {"clear_m": round(best, 4), "joint": int(i) if dj.min() <= de.min() else int(np.argmin(de)),
                          "sphere": int(s) if dj.min() <= de.min() else "ee",
                          "sphere_y": round(float(centres[s, 1]), 3),
                          "true_sep_caps_m": round(separation_m(*body_spheres(J[w, k]), caps), 3),
                          "head": np.round(J[w, k, HEAD], 3).tolist()}
            ST.append({"t": t, "mode": c.mode, "moving": arm.moving, "q": np.round(arm.q_rad, 4).tolist(),
                       "qd": np.round(arm.qd_radps, 3).tolist(), "ee": np.round(ee, 3).tolist(),
                       "limit": round(arm.speed_limit_mps, 3), "last_cmd": c.last_command, "per": per})
        return super().step(dt_s, advance_clock)


hrc_world.SimulatedRobot = TracedRobot

if a.fix:
    import importlib.util
    spec = importlib.util.spec_from_file_location("fix", a.fix if a.fix.endswith(".py") else str(Path(__file__).with_name(f"fix_{a.fix}.py")))
    fix = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(fix)
    fix.apply(EV, J=J, t_of=t_of)

t0 = time.time()
r = hrc._run_one((sc, a.link, True, hrc.resolve_perception("lifter"), world, box))
s = r.summary
print(json.dumps({k: s[k] for k in ("collision", "collision_steps", "first_collision_s", "arm_still_at_contact_s",
                                    "arm_moved_in_contact", "min_separation_m", "stops", "retracts",
                                    "productive_time_share", "halt_reasons")}), f"wall {time.time() - t0:.1f}s")
with open(a.out, "w") as f:
    json.dump({"summary": s, "events": EV, "frames": FR, "steps": ST}, f, default=float)
