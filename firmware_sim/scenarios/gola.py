"""``python -m firmware_sim gola``: chapter 4's posture experiment on a simulated cohort.

Protocol (dissertation section 4.2.3), per participant (:mod:`firmware_sim.people.worker`):

1. **GOLA-HRC to convergence** (:class:`edge_runtime.posture.gola.GolaSession`): every task
   cycle the arm moves once to the proposed pose, the worker does the task there, and
   the CAP of that repetition (from the worker's joints) goes back to GOLA. The final
   pose is the **Learnt** position.
2. Four positions in a random order, three task repetitions each: **Fixed** (1.055 m,
   0 deg, the 50th-percentile elbow height), **Elbow Height** (the worker's right-elbow
   height standing upright, 0 deg; with ``--vision`` as the camera sees it), **Learnt**, **Worker-selected** (where the worker is
   most comfortable: :meth:`Worker.selected_position`).
3. Kruskal-Wallis across the four positions (scipy) and Steel-Dwass pairwise tests
   (scikit-posthocs ``posthoc_dscf``) on the CAP of every repetition.

The breadboard is held by its far edge: the tool points along the board toward the
worker, so the Sawyer's tool pitch is minus the board's pitch, and the flange sits
``GRIP_OFFSET_M`` behind the board's centre along the tool. ``--link none`` moves the
simulated Sawyer arm (:class:`firmware_sim.robot.sawyer.SawyerArm`: inverse kinematics,
refusal of unreachable targets) in process; ``can`` and ``mavlink`` send every move
through :mod:`edge_runtime.robot.link.base` (DBC + E2E frames, or signed MAVLink 2) to the
simulated controller (:class:`LinkedArm`), on a simulated clock.

The cost of one GOLA iteration (propose, CAP from the 17 joints, observe: everything
but the robot move and the simulated task) is timed and reported.
"""
from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from edge_runtime.cli import CliError, positive_int
from edge_runtime.core.skeleton import BASE_HEIGHT_M, R_ELBOW
from edge_runtime.posture.cap import CapParams, CapResult, cap_score, cycle_cap
from edge_runtime.posture.gola import GolaParams, GolaSession
from firmware_sim.people.worker import VisionPath, Worker, make_cohort

CONDITIONS = ("Fixed", "ElbowHeight", "Learnt", "WorkerSelected")
REPETITIONS = 3
GRIP_OFFSET_M = 0.10 + 0.0275
"""Flange to the board's centre along the tool (m): the gripper, then half the board's depth."""
FIXED_POSE = (1.055, 0.0)
"""The Fixed position: height above the floor (m), pitch (deg)."""
BAD_INPUT = (ValueError,)


# -- the arm ------------------------------------------------------------------------------------
def tool_target(workpiece_xz_m, height_m: float, pitch_deg: float) -> tuple[np.ndarray, float, float]:
    """(flange position in the robot frame (m), tool pitch (rad), tool yaw (rad)) that put the
    board's centre at ``height_m`` above the floor with the board pitched by ``pitch_deg``."""
    from firmware_sim.robot.sawyer import direction_from_pitch_yaw

    tool_pitch = -math.radians(pitch_deg)
    centre = np.array([workpiece_xz_m[0], height_m - BASE_HEIGHT_M, workpiece_xz_m[1]])
    return centre - GRIP_OFFSET_M * direction_from_pitch_yaw(tool_pitch, 0.0), tool_pitch, 0.0


class InProcessArm:
    """The simulated Sawyer without a link: ``move_to`` answers "ok" or "unreachable: why"."""

    def __init__(self):
        from firmware_sim.robot.sawyer import SawyerArm

        self.arm = SawyerArm()
        self.moves = 0

    def move_to(self, position_m, pitch_rad: float, yaw_rad: float) -> str:
        from firmware_sim.robot.sawyer import Unreachable

        try:
            self.arm.set_target(position_m, pitch_rad, yaw_rad)
        except Unreachable as e:
            return f"unreachable: {e}"
        self.arm.q_rad = self.arm.goal_rad.copy()        # between task cycles the arm has long arrived
        self.moves += 1
        return "ok"

    def close(self) -> None:
        pass


class LinkedArm:
    """The simulated Sawyer controller behind a real CAN or signed MAVLink link
    (:class:`firmware_sim.robot.controller.SimulatedRobot`, on a simulated clock): ``move_to``
    sends the target through :class:`edge_runtime.robot.link.base.RobotLink`, runs simulated time
    until the controller answers and, when accepted, until the arm is at the target."""

    ANSWER_TIMEOUT_S = 0.5
    """Simulated time to wait for the controller's answer to a move (s)."""
    MOTION_TIMEOUT_S = 15.0
    """Simulated time to wait for the arm to arrive (s)."""

    def __init__(self, kind: str):
        from firmware_sim.robot.controller import SimulatedRobot

        self.sim = SimulatedRobot(kind)
        self.sim.link.resume()
        self.sim.step(0.05)
        self.moves = 0

    def move_to(self, position_m, pitch_rad: float, yaw_rad: float) -> str:
        link = self.sim.link
        seq = link.move_to(position_m, pitch_rad, yaw_rad)
        t = 0.0
        while link.result(seq) is None and t < self.ANSWER_TIMEOUT_S:
            self.sim.step(0.01)
            t += 0.01
        answer = link.result(seq)
        if answer is None:
            return "no answer from the robot (link lost)"
        if answer != "ok":
            return answer
        t = 0.0
        while t < self.MOTION_TIMEOUT_S:
            self.sim.step(0.05)
            t += 0.05
            st = link.state
            if st is not None and st.last_seq == seq and st.at_target and not st.moving:
                self.moves += 1
                return "ok"
        return "the arm did not reach the target in time"

    def close(self) -> None:
        self.sim.close()


def open_arm(link: str):
    """The arm for ``--link``: ``none`` in process, ``can`` / ``mavlink`` over that robot link."""
    if link == "none":
        return InProcessArm()
    if link in ("can", "mavlink"):
        return LinkedArm(link)
    raise CliError(f"--link {link}: expected none, can or mavlink")


# -- one participant ----------------------------------------------------------------------------
@dataclass
class ParticipantResult:
    worker: Worker
    session: GolaSession
    iteration_cost_ns: list[int]
    positions: dict[str, tuple[float, float]]
    caps: dict[str, list[float]]
    parts: dict[str, dict[str, float]]
    order: list[str]

    def as_dict(self) -> dict:
        w = self.worker
        return {"id": w.label, "sex": w.body.sex, "height_m": round(w.body.height_m, 4), "style": w.style.kind,
                "iterations": self.session.iteration, "state": self.session.state,
                "positions": {k: {"height_m": round(h, 4), "pitch_deg": round(a, 2)}
                              for k, (h, a) in self.positions.items()},
                "cap": {k: [round(c, 4) for c in v] for k, v in self.caps.items()},
                "parts": {k: {p: round(x, 4) for p, x in v.items()} for k, v in self.parts.items()},
                "order": self.order, "refusals": self.session.refusals, "clamps": self.session.clamps}


def _move(arm, worker: Worker, height_m: float, pitch_deg: float) -> str:
    pos, pitch, yaw = tool_target(worker.workpiece_xz_m, height_m, pitch_deg)
    return arm.move_to(pos, pitch, yaw)


MAX_MISSED_CYCLES = 10
"""Task cycles in a row without a valid pose after which a participant's run is abandoned."""


def task_cycle(worker: Worker, height_m: float, pitch_deg: float, rng: np.random.Generator, vision=None) -> np.ndarray:
    """What the product sees of one repetition: the worker's true (17, 3) joints, or with
    ``vision`` (:class:`VisionPath`) the (T, 17, 3) joints the camera + lifter report."""
    joints = worker.perform(height_m, pitch_deg, rng)
    return joints if vision is None else vision.observe(joints, rng)


def _cap(seen: np.ndarray, cap_params: CapParams) -> CapResult:
    return cap_score(seen, cap_params) if seen.ndim == 2 else cycle_cap(seen, cap_params)


def measured_elbow_height_m(worker: Worker, rng: np.random.Generator, vision=None) -> float:
    """The Elbow Height position: the right elbow of the worker standing upright, from the true
    joints or, with ``vision``, as the camera and lifter see it (the dissertation's VideoPose3D
    right elbow); the true height if the vision path saw no valid frame."""
    if vision is None:
        return worker.elbow_height_m()
    y = vision.observe(worker.standing_joints(), rng)[:, R_ELBOW, 1]
    return float(np.nanmedian(y) + BASE_HEIGHT_M) if np.isfinite(y).any() else worker.elbow_height_m()


def run_gola(worker: Worker, arm, rng: np.random.Generator, params: GolaParams = GolaParams(),
             cap_params: CapParams = CapParams(), log=None, vision=None) -> tuple[GolaSession, list[int]]:
    """GOLA-HRC with one worker until it converges (or gives up); returns the session and the
    cost (ns) of each iteration's own work: propose + CAP from the joints + observe."""
    s = GolaSession(params, cap_params, log=log, worker=worker.label)
    cost_ns: list[int] = []
    missed = 0
    try:
        while not s.done and missed < MAX_MISSED_CYCLES:
            t0 = time.perf_counter_ns()
            prop = s.propose()
            t1 = time.perf_counter_ns()
            answer = _move(arm, worker, prop.height_m, prop.pitch_deg)
            if answer != "ok":
                prop = s.refused(answer)
                _move(arm, worker, prop.height_m, prop.pitch_deg)
            seen = task_cycle(worker, prop.height_m, prop.pitch_deg, rng, vision)
            t2 = time.perf_counter_ns()
            state = s.observe_joints(seen)
            cost_ns.append((t1 - t0) + (time.perf_counter_ns() - t2))
            missed = missed + 1 if state == "paused" else 0
    finally:
        s.close()
    return s, cost_ns


def run_participant(worker: Worker, arm, rng: np.random.Generator, params: GolaParams = GolaParams(),
                    cap_params: CapParams = CapParams(), log=None, vision=None) -> ParticipantResult:
    """The whole protocol for one participant."""
    session, cost = run_gola(worker, arm, rng, params, cap_params, log, vision)
    positions = {"Fixed": FIXED_POSE, "ElbowHeight": (measured_elbow_height_m(worker, rng, vision), 0.0),
                 "Learnt": session.learnt,
                 "WorkerSelected": worker.selected_position((params.height_min_m, params.height_max_m),
                                                            (params.pitch_min_deg, params.pitch_max_deg))}
    order = [CONDITIONS[i] for i in rng.permutation(len(CONDITIONS))]
    caps: dict[str, list[float]] = {}
    parts: dict[str, dict[str, float]] = {}
    for cond in order:
        h, a, _ = params.clamp(*positions[cond])
        positions[cond] = (h, a)
        if _move(arm, worker, h, a) != "ok":
            raise RuntimeError(f"{worker.label}: the arm cannot reach the {cond} position ({h:.3f} m, {a:.1f} deg)")
        res: list[CapResult] = []
        for _ in range(REPETITIONS + MAX_MISSED_CYCLES):       # a repetition nobody saw is repeated
            r = _cap(task_cycle(worker, h, a, rng, vision), cap_params)
            if r.valid:
                res.append(r)
            if len(res) == REPETITIONS:
                break
        if not res:
            raise RuntimeError(f"{worker.label}: no valid pose in {REPETITIONS + MAX_MISSED_CYCLES} cycles at {cond}")
        caps[cond] = [r.cap for r in res]
        parts[cond] = {p: float(np.mean([r.parts[p] for r in res])) for p in res[0].parts}
    return ParticipantResult(worker, session, cost, positions, {c: caps[c] for c in CONDITIONS},
                             {c: parts[c] for c in CONDITIONS}, order)


# -- statistics ---------------------------------------------------------------------------------
def statistics(results: list[ParticipantResult]) -> dict:
    """Kruskal-Wallis over the four positions, Steel-Dwass pairs, and the dissertation's ordering."""
    import scikit_posthocs as sp
    from scipy.stats import kruskal

    groups = {c: np.array([x for r in results for x in r.caps[c]]) for c in CONDITIONS}
    out: dict = {"cap": {c: {"mean": float(g.mean()), "sd": float(g.std(ddof=1)) if len(g) > 1 else 0.0,
                             "median": float(np.median(g)), "n": int(len(g))} for c, g in groups.items()}}
    out["parts"] = {c: {p: float(np.mean([r.parts[c][p] for r in results])) for p in results[0].parts[c]}
                    for c in CONDITIONS}
    values = [groups[c] for c in CONDITIONS]
    if all(len(np.unique(v)) == 1 for v in values) and len(np.unique(np.concatenate(values))) == 1:
        kw_p = 1.0
    else:
        kw_p = float(kruskal(*values).pvalue)
    sd = sp.posthoc_dscf(values).to_numpy()
    pairs = {f"{CONDITIONS[i]}-{CONDITIONS[j]}": float(sd[i, j])
             for i in range(len(CONDITIONS)) for j in range(i + 1, len(CONDITIONS))}
    out["p_values"] = {"kruskal_wallis": kw_p, "steel_dwass": pairs}
    m = {c: out["cap"][c]["mean"] for c in CONDITIONS}
    checks = {
        "Learnt<ElbowHeight": m["Learnt"] < m["ElbowHeight"],
        "WorkerSelected<ElbowHeight": m["WorkerSelected"] < m["ElbowHeight"],
        "ElbowHeight<Fixed": m["ElbowHeight"] < m["Fixed"],
        "Learnt~WorkerSelected (Steel-Dwass p >= 0.05)": pairs["Learnt-WorkerSelected"] >= 0.05,
    }
    # the dissertation: every pair differs (Steel-Dwass p < 0.05) except Learnt - WorkerSelected
    significance = {k: {"expected_different": k != "Learnt-WorkerSelected", "different": v < 0.05}
                    for k, v in pairs.items()}
    out["ordering"] = {"expected": "Learnt ~ WorkerSelected < ElbowHeight < Fixed", "checks": checks,
                       "observed": " < ".join(sorted(CONDITIONS, key=m.get)), "significance": significance,
                       "significance_matches": all(v["expected_different"] == v["different"]
                                                   for v in significance.values())}
    out["ordering_holds"] = all(checks.values())
    return out


def run_experiment(cohort: int, seed: int, link: str = "none", log_dir: Path | None = None,
                   params: GolaParams = GolaParams(), cap_params: CapParams = CapParams(),
                   progress: bool = False, vision: VisionPath | None = None) -> tuple[dict, list[ParticipantResult]]:
    """The experiment on ``cohort`` simulated participants; returns (the JSON summary, the raw results).
    ``vision``: measure CAP through the camera and the lifter instead of from the true joints."""
    workers = [replace(w, workpiece_xz_m=params.workpiece_xz_m) for w in make_cohort(cohort, seed)]
    arm = open_arm(link)
    results: list[ParticipantResult] = []
    it = workers
    if progress:
        from tqdm import tqdm

        it = tqdm(workers, desc="gola", unit="participant", leave=False)
    try:
        for w in it:
            rng = np.random.default_rng([seed, w.pid])
            log = (log_dir / f"{w.label}.jsonl") if log_dir is not None else None
            results.append(run_participant(w, arm, rng, params, cap_params, log, vision))
        moves = arm.moves
    finally:
        arm.close()
    cost = np.array([c for r in results for c in r.iteration_cost_ns], dtype=float) / 1000.0
    iters = np.array([r.session.iteration for r in results])
    summary = {
        "participants": len(results),
        "seed": seed,
        "link": link,
        "robot_moves": moves,
        "cap_from": "camera keypoints -> lifter" if vision is not None else "true joints",
        "mean_iterations": float(iters.mean()),
        "sd_iterations": float(iters.std(ddof=1)) if len(iters) > 1 else 0.0,
        "converged": int(sum(r.session.state == "converged" for r in results)),
        **statistics(results),
        "gola_iteration_us": {"median": float(np.median(cost)), "p99": float(np.percentile(cost, 99)),
                              "mean": float(cost.mean()), "n": int(len(cost)),
                              "what": "propose + CAP from 17 joints + observe; excludes the robot move and the task"},
        "gola_params": {k: v for k, v in vars(params).items()},
        "cap_params": {k: v for k, v in vars(cap_params).items()},
        "per_participant": [r.as_dict() for r in results],
    }
    return summary, results


# -- figures ------------------------------------------------------------------------------------
def plot_boxes(summary: dict, results: list[ParticipantResult], path: Path) -> None:
    """Fig. 4.7(a): CAP per position, boxes at the 10/25/50/75/90 % quantiles, means marked."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    data = [[x for r in results for x in r.caps[c]] for c in CONDITIONS]
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    ax.boxplot(data, whis=(10, 90), showmeans=True, showfliers=False)
    ax.set_xticks(range(1, len(CONDITIONS) + 1), ["Fixed", "Elbow Height", "Learnt", "Worker-selected"])
    ax.set_ylabel("CAP score")
    p = summary["p_values"]
    ax.set_title(f"CAP by end-effector position (n = {summary['participants']}, "
                 f"Kruskal-Wallis p = {p['kruskal_wallis']:.2g})", fontsize=10)
    top = max(max(d) for d in data)
    for k, (i, j) in enumerate(((3, 4), (2, 3), (1, 2))):
        pv = p["steel_dwass"][f"{CONDITIONS[i - 1]}-{CONDITIONS[j - 1]}"]
        y = top + 0.25 + 0.35 * k
        ax.plot([i, j], [y, y], color="k", lw=0.8)
        ax.text((i + j) / 2, y + 0.05, "*" if pv < 0.05 else "ns", ha="center", fontsize=9)
    ax.set_ylim(top=top + 1.4)
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def plot_iterations(result: ParticipantResult, path: Path) -> None:
    """Fig. 4.6: CAP, height and pitch per GOLA iteration for one participant."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    hist = result.session.history
    it = [h["iteration"] for h in hist]
    fig, axes = plt.subplots(3, 1, figsize=(6.4, 6.0), sharex=True)
    for ax, key, label in zip(axes, ("cap", "height_m", "pitch_deg"), ("CAP", "height above floor (m)", "pitch (deg)")):
        ax.plot(it, [h[key] for h in hist], marker="o")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].set_title(f"GOLA-HRC, {result.worker.label} ({result.worker.body.height_m * 100:.0f} cm, "
                      f"{result.worker.style.kind}): {result.session.state} after "
                      f"{result.session.iteration} iterations",
                      fontsize=10)
    axes[-1].set_xlabel("iteration (task cycle)")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


# -- command line -------------------------------------------------------------------------------
def _nonneg_float(s: str) -> float:
    import argparse

    try:
        v = float(s)
    except ValueError:
        raise argparse.ArgumentTypeError(f"not a number: {s!r}") from None
    if not (math.isfinite(v) and v >= 0):
        raise argparse.ArgumentTypeError(f"must be a finite number >= 0, got {s}")
    return v


def add_arguments(parser) -> None:
    parser.add_argument("--cohort", type=positive_int, default=20, help="participants (default 20: 10 F, 10 M)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", required=True, metavar="OUT.json",
                        help="results: CAP per position, p values, iterations")
    parser.add_argument("--plot", metavar="OUT.png",
                        help="box plot like Fig. 4.7; also OUT_iterations.png (Fig. 4.6) for the first participant")
    parser.add_argument("--link", choices=("none", "can", "mavlink"), default="none",
                        help="how GOLA reaches the simulated Sawyer (default: in process)")
    parser.add_argument("--log", metavar="DIR", help="one JSON-lines session log per participant (DIR/P01.jsonl ...)")
    parser.add_argument("--neck-weight", type=_nonneg_float, default=None,
                        help="personalise CAP: the neck's weight (default 1; Fig. 4.11 doubles it)")
    parser.add_argument("--vision", action="store_true",
                        help="measure CAP through the simulated camera and the shipped pose lifter "
                             "(default: from the true joints)")
    parser.add_argument("--quiet", action="store_true", help="no progress bar")


def _writable_file(path: str, what: str) -> Path:
    p = Path(path)
    if p.parent and not p.parent.exists():
        try:
            p.parent.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise CliError(f"{what} {path}: cannot create its directory ({e.strerror or e})") from None
    if p.is_dir():
        raise CliError(f"{what} {path}: is a directory")
    try:
        with open(p, "a"):                      # fail now, not after the whole experiment
            pass
    except OSError as e:
        raise CliError(f"{what} {path}: cannot write ({e.strerror or e})") from None
    return p


def cmd(args) -> int:
    if args.plot and Path(args.plot).suffix.lower() != ".png":
        raise CliError(f"--plot {args.plot}: must end in .png")
    cap_params = CapParams() if args.neck_weight is None else CapParams(neck_weight=args.neck_weight)
    vision = None
    if args.vision:
        try:
            vision = VisionPath.shipped()
        except LookupError as e:
            raise CliError(f"--vision: {e}") from None
    out = _writable_file(args.json, "--json")
    plot = _writable_file(args.plot, "--plot") if args.plot else None
    log_dir = None
    if args.log:
        log_dir = Path(args.log)
        try:
            log_dir.mkdir(parents=True, exist_ok=True)
        except OSError as e:
            raise CliError(f"--log {args.log}: cannot create the directory ({e.strerror or e})") from None
    summary, results = run_experiment(args.cohort, args.seed, args.link, log_dir, cap_params=cap_params,
                                      progress=not args.quiet, vision=vision)
    try:
        out.write_text(json.dumps(summary, indent=1))
        if plot is not None:
            plot_boxes(summary, results, plot)
            plot_iterations(results[0], plot.with_name(plot.stem + "_iterations.png"))
    except OSError as e:
        raise CliError(f"cannot write results: {e.strerror or e} ({e.filename})") from None
    c = summary["cap"]
    n = summary["participants"]
    print(f"gola: {n} participant{'s' if n != 1 else ''}, {summary['converged']} converged, "
          f"mean {summary['mean_iterations']:.1f} iterations; CAP "
          + ", ".join(f"{k} {c[k]['mean']:.2f} +/- {c[k]['sd']:.2f}" for k in CONDITIONS)
          + f"; Kruskal-Wallis p = {summary['p_values']['kruskal_wallis']:.2g}; ordering "
          + ("holds" if summary["ordering_holds"] else f"does not hold ({summary['ordering']['observed']})")
          + f"; one GOLA iteration {summary['gola_iteration_us']['median']:.0f} us (median) -> {out}")
    return 0
