"""``python -m firmware_sim hrc``: the closed-loop collision-avoidance proof (dissertation chapter 3).

    python -m firmware_sim hrc --scenario NAME|dissertation|random:N --link can|mavlink --seed S
                               --json OUT.json [--plot OUT.png] [--max-speed M] [--camera-hz HZ]
                               [--perception auto|truth|lifter] [--no-runtime] [--with-baseline]
                               [--config BOX.toml] [--retract-time S] [--zone KEY=VALUE ...]
                               [--loop KEY=VALUE ...] [--validated FILE] [--jobs N] [--only NAME]
                               [--protection head|stop_only|speed_scaled]

Runs the robot-side runtime (``edge_runtime.robot.loop.RobotLoop``) against the simulated
Sawyer on a real link (CAN or signed MAVLink), a simulated worker and a simulated camera,
in simulated time (:mod:`firmware_sim.scenarios.hrc_world` describes the world, what counts as a
collision, a false alarm and the reaction time). Scenarios:

* ``left_to_right``, ``right_to_left``, ``front``: the dissertation's three validation walks
  (``dissertation`` runs all three);
* ``hard:N``: N scenarios of the hard suite (1-3 workers, curves, stop-and-go, running bursts,
  reaching toward the tool, occlusion, a real detector's noise: :mod:`firmware_sim.scenarios.hrc_hard`);
* ``random:N``: N random approaches from the work side (speed 0.5..``--max-speed`` m/s, start
  3-6 m out, camera 3-8 m away and 1-3 m high, detector noise x0.5-2, a worker who walks past
  or stops short); paths closer than 1.1 m to the base's axis are redrawn: nothing can avoid a
  worker who walks through the robot's base, and the folded arm still fills 0.69 m around its
  axis (``hrc_world.RandomParams.min_base_distance_m``).

``--no-runtime`` is the baseline: the same scenarios with an arm that never sees the worker
(the loop is fed empty frames), which shows the collisions the runtime has to prevent.

The JSON: ``scenarios`` (count), ``collisions`` (scenarios with at least one),
``min_separation_m`` (smallest clearance of all), ``stops``, ``retracts``, ``false_alarms``
(totals), ``reaction_ms`` ``{"median", "p99", "n"}`` (wall clock, keypoints handed to the
runtime -> command written on the link), ``command_delay_s`` (simulated time from the true
head entering a zone to the runtime's command), ``head_error_m`` (``{"median", "p95"}``: the head
the runtime was given against the true head, robot frame), ``runtime_cpu_share``, the settings
(with every ZoneParams and LoopParams value used), ``config`` (the whole effective box
configuration the runtime ran), ``config_sha256`` (its hash), ``lifter_model`` (the manifest entry
of the lifter the box runs: name and sha256) and ``safety_sha256`` (the hash of the sections the
cell's safety depends on, :data:`SAFETY_SECTIONS`, and of ``lifter_model``: a new lifter voids a
validation as a changed default does), and ``details``: one object per scenario.

One source of truth: the runtime runs the box configuration, the shipped defaults
(``edge_runtime/box.example.toml``) unless ``--config BOX.toml`` names a box file; ``--zone``,
``--loop`` and ``--retract-time`` override single fields on top of it to measure other settings.
The scenario's task replaces ``[robot_loop] task_waypoints_m``. ``--validated FILE`` adds the
run's figures to a validation record (``reports/hrc/validated.json``) kept per ``safety_sha256``:
``tests/sim/test_hrc.py`` fails when the shipped safety defaults are not the validated ones.
Python callers: :func:`run`, :func:`run_dissertation` (what ``make demo`` shows) and
:func:`format_table`.
"""
from __future__ import annotations

import argparse
import hashlib
import json
import sys
from collections import Counter
from dataclasses import asdict, fields, replace
from pathlib import Path

import numpy as np

from edge_runtime import config
from edge_runtime.cli import CliError, positive_float, positive_int
from firmware_sim.scenarios.hrc_world import (
    DISSERTATION,
    RunResult,
    WorldParams,
    box_config,
    dissertation_scenarios,
    hard_scenarios,
    lifter_available,
    percentiles,
    random_scenarios,
    run_scenario,
)

LINKS = ("can", "mavlink")
PERCEPTIONS = ("auto", "truth", "lifter")
SPEED_LIMITS_MPS = (0.5, 2.0)

PROTECTIONS = {"head": {"separation": "head"},
               "stop_only": {"separation": "whole_body", "speed_scaling": False},
               "speed_scaled": {"separation": "whole_body", "speed_scaling": True}}
"""``--protection``: the [zones] fields each way of protecting the worker sets."""

SAFETY_SECTIONS = ("zones", "tracker", "robot_loop", "calibration", "lifter")
"""The box sections the closed loop's collision figures depend on; their hash (``safety_sha256``)
is what a validation holds for. The other sections (the wearable's, posture, link addresses) do
not change what the cell does, so editing them does not void a validation."""


NOT_SAFETY_KEYS = {"lifter": ("manifest_public_key",)}
"""Keys of the safety sections that do not change what the cell does, left out of the sections'
hash: which builder's signed manifest the box trusts (issue 16) decides whether the shipped
models load at all, not how the loop behaves with them."""


def lifter_model(box, assets_dir=None) -> dict:
    """The identity of the lifter the box runs: the name and sha256 of the manifest entry its
    ``[lifter] precision`` selects (``assets_dir``: the shipped assets by default). The cell's
    perception is that model, so it is part of what a validation holds for; a manifest without
    the entry gives its error instead of a hash (nothing validated runs without a lifter)."""
    from edge_runtime.core.manifest import ASSETS_DIR, ManifestError, load_manifest, select_model
    from edge_runtime.robot.lifter import LIFTER_ARCH

    try:
        entry = select_model(load_manifest(assets_dir or ASSETS_DIR), box.lifter.precision, arch=LIFTER_ARCH)
    except ManifestError as e:
        return {"name": None, "sha256": None, "error": str(e)}
    return {"name": entry["name"], "sha256": entry["sha256"]}


def safety_config(box, assets_dir=None) -> dict:
    """What a validation holds for: the :data:`SAFETY_SECTIONS` of the configuration (without
    :data:`NOT_SAFETY_KEYS`) and ``lifter_model``, the shipped lifter's identity."""
    return {**config_dict(box, SAFETY_SECTIONS), "lifter_model": lifter_model(box, assets_dir)}


def _json_sha256(value) -> str:
    """sha256 of ``value``'s canonical JSON (sorted keys, no spaces): equal values, equal hash."""
    return hashlib.sha256(json.dumps(value, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def safety_sha256(box, assets_dir=None) -> str:
    """sha256 of :func:`safety_config` (canonical JSON, sorted keys)."""
    return _json_sha256(safety_config(box, assets_dir))


def config_dict(box, sections=None) -> dict:
    """The configuration as plain JSON values (tuples as lists), all sections or ``sections``
    (without :data:`NOT_SAFETY_KEYS`)."""
    whole = config._as_lists(asdict(box))
    if sections is None:
        return whole
    return {k: {f: v for f, v in whole[k].items() if f not in NOT_SAFETY_KEYS.get(k, ())} for k in sections}


def config_sha256(box, sections=None) -> str:
    """sha256 of the configuration's canonical JSON (sorted keys): equal values, equal hash."""
    return _json_sha256(config_dict(box, sections))


def load_box(path: str | None = None):
    """The box configuration from ``path`` (TOML), or the shipped defaults."""
    return box_config() if path is None else replace(box_config(), **{
        name: getattr(config.load(path), name) for name in config.registered()})


def parse_scenario(text: str) -> tuple[str, int | None]:
    """``NAME``, ``dissertation`` or ``random:N`` -> (kind, N)."""
    if text in DISSERTATION or text == "dissertation":
        return text, None
    kind = text.split(":", 1)[0]
    if kind in ("random", "hard") and ":" in text:
        try:
            n = int(text.split(":", 1)[1])
        except ValueError:
            n = 0
        if n < 1:
            raise CliError(f"--scenario {text!r}: {kind}:N needs a whole number N >= 1")
        return kind, n
    raise CliError(f"--scenario {text!r}: expected one of {', '.join(DISSERTATION)}, dissertation, random:N "
                   "or hard:N")


def scenarios_for(text: str, seed: int, max_speed_mps: float = 2.0, only: str | None = None):
    scs = _scenario_set(text, seed, max_speed_mps)
    if only is None:
        return scs
    picked = [s for s in scs if s.name == only]
    if not picked:
        raise CliError(f"--only {only!r}: no such scenario in {text} (names: {scs[0].name} .. {scs[-1].name})")
    return picked


def _scenario_set(text: str, seed: int, max_speed_mps: float):
    kind, n = parse_scenario(text)
    if kind == "random":
        return random_scenarios(n, seed, max_speed_mps)
    if kind == "hard":
        return hard_scenarios(n, seed)
    all3 = dissertation_scenarios(seed)
    return all3 if kind == "dissertation" else [s for s in all3 if s.name == kind]


def resolve_perception(perception: str) -> str:
    if perception == "auto":
        return "lifter" if lifter_available() else "truth"
    if perception == "lifter" and not lifter_available():
        raise CliError("--perception lifter: edge_runtime/assets/manifest.json lists no lifter (arch 'lifter')")
    return perception


def protection_name(zones) -> str:
    """The PROTECTIONS name of a [zones] configuration."""
    if zones.separation == "head":
        return "head"
    return "speed_scaled" if zones.speed_scaling else "stop_only"


def _run_one(job) -> RunResult:
    sc, link, runtime, perception, world, box = job
    return run_scenario(sc, link, runtime, perception, world, box)


def overrides(base, items: list[str], flag: str):
    """``base`` (a frozen config dataclass) with ``KEY=VALUE`` overrides of its number fields."""
    kinds = {f.name: type(getattr(base, f.name)) for f in fields(base)}
    changes = {}
    for item in items or ():
        key, sep, value = item.partition("=")
        if not sep or key not in kinds or kinds[key] not in (int, float):
            numeric = ", ".join(k for k, t in kinds.items() if t in (int, float))
            raise CliError(f"{flag} {item!r}: expected KEY=NUMBER with KEY one of {numeric}")
        try:
            changes[key] = kinds[key](value)
        except ValueError:
            raise CliError(f"{flag} {item!r}: {value!r} is not a {kinds[key].__name__}") from None
    try:
        return replace(base, **changes)
    except ValueError as e:
        raise CliError(f"{flag}: {e}") from None


def _map(jobs: list, n_jobs: int, progress: bool):
    """Run the jobs (in ``n_jobs`` processes when > 1), in order, with a progress bar."""
    from tqdm import tqdm

    bar = dict(total=len(jobs), disable=not progress, unit="scenario", file=sys.stderr, leave=False)
    if n_jobs <= 1:
        return [_run_one(j) for j in tqdm(jobs, **bar)]
    from concurrent.futures import ProcessPoolExecutor

    with ProcessPoolExecutor(n_jobs) as ex:
        return list(tqdm(ex.map(_run_one, jobs, chunksize=1), **bar))


def _stats(values) -> dict:
    v = [x for x in values if x is not None]
    if not v:
        return {"median": None, "p99": None, "n": 0}
    return {"median": round(float(np.median(v)), 4), "p99": round(float(np.percentile(v, 99)), 4), "n": len(v)}


STILL_BEFORE_CONTACT_S = 0.5
"""A collision counts as "into a standing arm" only if the arm had stood still for at least this long (s)
when a worker's body first came within ``collision_m`` of it AND did not move at any step while he was that
close (``arm_moved_in_contact``: a retract that resumes into him, or an arm that swings its links toward him,
is an arm moving); every other collision counts in ``collisions_arm_moving``. ISO/TS 15066's speed and
separation monitoring asks that the robot be at standstill when a person reaches it; a worker reaching into
an arm that stopped seconds before and stays stopped is that case. 0.5 s, a fixed figure rather than the box's
``predict_s``: the measure must not move with the configuration it judges. Both counts are reported; the
issue's must-hold counts every collision."""


def arm_was_moving(d: dict) -> bool:
    """Whether a collided scenario's arm moved into the worker (see :data:`STILL_BEFORE_CONTACT_S`)."""
    still = d.get("arm_still_at_contact_s")
    return bool(d.get("arm_moved_in_contact", True) or still is None or still < STILL_BEFORE_CONTACT_S)


def summarize(results: list[RunResult], settings: dict) -> dict:
    """The contract JSON from per-scenario results."""
    ran = [r.summary for r in results if "not_run" not in r.summary]
    det = [r.summary for r in results]
    reaction = [1000.0 * s for r in results for s in r.reaction_s]
    states: dict[str, int] = {}
    for d in det:
        states[d["max_state"]] = states.get(d["max_state"], 0) + 1
    by_kind = {}
    for kind in sorted({d["kind"] for d in det}):
        sub = [d for d in det if d["kind"] == kind]
        by_kind[kind] = {"scenarios": len(sub), "collisions": sum(d["collision"] for d in sub),
                         "min_separation_m": min((d["min_separation_m"] for d in sub if d["min_separation_m"]
                                                  is not None), default=None)}
    return {
        **settings,
        "scenarios": len(det),
        "collisions": sum(d["collision"] for d in det),
        "collided": [d["name"] for d in det if d["collision"]],
        "arm_still_at_contact_s": {d["name"]: d.get("arm_still_at_contact_s") for d in det if d["collision"]},
        "arm_moved_in_contact": {d["name"]: d.get("arm_moved_in_contact") for d in det if d["collision"]},
        "collisions_arm_moving": sum(d["collision"] and arm_was_moving(d) for d in det),
        "not_run": {d["name"]: d["not_run"] for d in det if "not_run" in d},
        "min_separation_m": min((d["min_separation_m"] for d in ran), default=None),
        "stops": sum(d["stops"] for d in det),
        "retracts": sum(d["retracts"] for d in det),
        "unreachable_retracts": sum(d["unreachable"] for d in det),
        "false_alarms": sum(d["false_alarms"] for d in det),
        "zone_entries": sum(len(d["zone_entries"]) for d in det),
        "reaction_ms": _stats(reaction),
        "command_delay_s": {lvl: _stats([d["command_delay_s"][lvl] for d in det]) for lvl in ("LEVEL1", "LEVEL2")},
        "max_state": states,
        "by_kind": by_kind,
        "invalid_frames": sum(d["invalid"] for d in det),
        "runtime_cpu_share": _stats([d.get("runtime_cpu_share") for d in det]),
        "head_error_m": percentiles([e for r in results for e in r.head_error_m], 1.0, (50, 95)),
        "frames": sum(d["frames"] for d in det),
        **productivity(ran),
        "details": det,
    }


def productivity(ran: list[dict]) -> dict:
    """The cell's work and its false stops over the scenarios that ran: ``productive_time_share``
    (time the arm did its task, at full or reduced speed, over scenario time), ``false_stops``
    (stops and retractions with nobody within the protective distance plus the false-alarm margin,
    hrc_world's rule), and ``false_stops_per_worker_hour`` over walk-by traffic: the scenarios in
    which no worker ever came within the protective distance at full speed, per hour of workers
    in view there (``walkby_worker_h``): there every halt of the task (a stop, a retraction, or a
    fault stop: an invalid or stale pose) is a stop with nobody within the protective distance;
    ``walkby_stops_by_reason``: those halts by the runtime's reason code (``person_unseen``,
    ``person_lost``, ``level2_retract``, ...)."""
    scenario_s = sum(d["scenario_s"] for d in ran)
    walkby = [d for d in ran if not d["came_within_protective"]]
    walkby_h = sum(d["worker_s"] for d in walkby) / 3600.0
    walkby_stops = sum(d["halts"] for d in walkby)
    kinds: dict[str, int] = {}
    walkby_reasons: dict[str, int] = {}
    for d in walkby:
        for why, n in d.get("halt_reasons", {}).items():
            walkby_reasons[why] = walkby_reasons.get(why, 0) + n
    state_s, halt_s = Counter(), Counter()  # seconds per monitor state, and halted seconds by reason
    for d in ran:
        state_s.update(d.get("state_s", {}))
        halt_s.update(d.get("halt_s", {}))
        for w in d.get("worker_specs") or [{"kind": d["kind"]}]:
            kinds[w["kind"]] = kinds.get(w["kind"], 0) + 1
    return {
        "productive_time_share": round(sum(d["productive_s"] for d in ran) / scenario_s, 4) if scenario_s else None,
        "false_stops": sum(d["false_alarms"] for d in ran),
        "halts": sum(d["halts"] for d in ran), "walkby_scenarios": len(walkby), "walkby_worker_h": round(walkby_h, 4), "walkby_stops": walkby_stops,
        "walkby_stops_by_reason": walkby_reasons,
        "false_stops_per_worker_hour": round(walkby_stops / walkby_h, 2) if walkby_h else None,
        "worker_kinds": kinds, "speed_changes": sum(d.get("speed_changes", 0) for d in ran),
        "state_share": {name: round(t_s / scenario_s, 4) for name, t_s in sorted(state_s.items())} if scenario_s else {},
        "halt_share": {name: round(t_s / scenario_s, 4) for name, t_s in sorted(halt_s.items())} if scenario_s else {},
    }


def run(scenario: str = "dissertation", link: str = "can", seed: int = 0, runtime: bool = True,
        perception: str = "auto", camera_hz: float = 30.0, max_speed_mps: float = 2.0,
        latency_ms: float | None = None, box=None, jobs: int = 1, progress: bool = False,
        keep_results: bool = False, only: str | None = None, labelled_calibration: bool = True):
    """Run scenarios with the box configuration ``box`` (default: the shipped one) and return the
    contract JSON (and the per-scenario results with ``keep_results``, for plots)."""
    box = box or box_config()
    zones = box.zones
    if link not in LINKS:
        raise CliError(f"--link {link!r}: expected can or mavlink")
    if not SPEED_LIMITS_MPS[0] <= max_speed_mps <= SPEED_LIMITS_MPS[1]:
        raise CliError(f"--max-speed {max_speed_mps:g}: walking speeds of {SPEED_LIMITS_MPS[0]}-"
                       f"{SPEED_LIMITS_MPS[1]} m/s only")
    percept = resolve_perception(perception) if runtime else "none"
    world = WorldParams(camera_hz=camera_hz, latency_s=None if latency_ms is None else latency_ms / 1000.0,
                        labelled_calibration=labelled_calibration)
    scs = scenarios_for(scenario, seed, max_speed_mps, only)
    results = _map([(sc, link, runtime, percept, world, box) for sc in scs], jobs, progress)
    settings = {
        "scenario": scenario, "only": only, "labelled_calibration": labelled_calibration, "link": link, "seed": seed, "runtime": runtime, "perception": percept,
        "camera_hz": camera_hz, "latency_ms": round(1000 * world.frame_latency_s, 1), "max_speed_mps": max_speed_mps,
        "collision_m": world.collision_m,
        "protection": protection_name(zones),
        "zones": {"r1_m": round(zones.r1_m, 3), "r2_m": round(zones.r2_m, 3), "sizing": zones.sizing,
                  "separation": zones.separation, "speed_scaling": zones.speed_scaling,
                  "retract_time_s": zones.retract_time_s, "predict_s": zones.predict_s,
                  "worker_speed_mps": zones.worker_speed_mps},
        "zone_params": asdict(zones), "loop_params": {k: v for k, v in asdict(box.robot_loop).items()
                                                       if k != "task_waypoints_m"},
        "config": config_dict(box), "config_sha256": config_sha256(box),
        "lifter_model": lifter_model(box), "safety_sha256": safety_sha256(box),
    }
    out = summarize(results, settings)
    return (out, results) if keep_results else out


VALIDATED_KEYS = ("scenario", "link", "seed", "perception", "camera_hz", "max_speed_mps", "scenarios",
                  "collisions", "not_run", "min_separation_m", "stops", "retracts", "false_alarms", "reaction_ms",
                  "protection", "productive_time_share", "false_stops_per_worker_hour")


def record_validation(out: dict, path: str | Path, command: str) -> dict:
    """Add this run's figures to the validation record at ``path``: one entry per (scenario, link,
    max speed, perception, camera rate), under the run's ``safety_sha256``. A record made for other
    safety settings is replaced, not mixed: its figures do not validate these. ``must_hold_met``: no
    run in the record collided."""
    p = Path(path)
    try:
        rec = json.loads(p.read_text())
    except (OSError, ValueError):
        rec = {}
    if rec.get("safety_sha256") != out["safety_sha256"]:
        rec = {"safety_sha256": out["safety_sha256"],
               "safety_config": {**{k: {f: v for f, v in out["config"][k].items() if f not in NOT_SAFETY_KEYS.get(k, ())}
                                    for k in SAFETY_SECTIONS}, "lifter_model": out["lifter_model"]},
               "runs": {}}
    key = (f"{out['scenario']} {out['link']} {out['max_speed_mps']:g}mps {out['perception']} {out['camera_hz']:g}hz"
           f" {out['protection']}")
    rec["runs"][key] = {**{k: out[k] for k in VALIDATED_KEYS}, "command": command}
    # the record says whether the must-hold held in every run it holds (tests/sim/test_hrc.py checks the flag)
    rec["must_hold_met"] = all(r["collisions"] == 0 for r in rec["runs"].values())
    p.write_text(json.dumps(rec, indent=1, sort_keys=True) + "\n")
    return rec


def run_dissertation(link: str, seed: int) -> dict:
    """The three dissertation scenarios with the runtime, and the same without it (``baseline``)."""
    out = run("dissertation", link, seed)
    base = run("dissertation", link, seed, runtime=False)
    out["baseline"] = {k: base[k] for k in ("collisions", "collided", "min_separation_m", "details")}
    return out


def format_table(result: dict) -> str:
    """A fixed-width table of a run (one row per scenario), for ``make demo``."""
    base = {d["name"]: d for d in result.get("baseline", {}).get("details", [])}
    head = (f"{'scenario':<14} {'speed':>5} {'max state':<9} {'stops':>5} {'retr':>4} {'false':>5} "
            f"{'min sep m':>9} {'collision':>9}")
    if base:
        head += f" | {'no runtime: min sep m':>21} {'collision':>9}"
    z = result["zones"]
    sizing = (f"whole-body separation ({result.get('protection')})" if z.get("separation") == "whole_body"
              else f"R1 {z['r1_m']:.1f} m, R2 {z['r2_m']:.1f} m")
    lines = [f"hrc: {result['link']} link, camera {result['camera_hz']:g} Hz, perception {result['perception']}, "
             f"{sizing}", head, "-" * len(head)]
    for d in result["details"]:
        sep = "not run" if d["min_separation_m"] is None else f"{d['min_separation_m']:.3f}"
        row = (f"{d['name']:<14} {d['speed_mps']:>5.2f} {d['max_state']:<9} {d['stops']:>5} {d['retracts']:>4} "
               f"{d['false_alarms']:>5} {sep:>9} {'YES' if d['collision'] else 'no':>9}")
        b = base.get(d["name"])
        if b:
            row += f" | {b['min_separation_m']:>21.3f} {'YES' if b['collision'] else 'no':>9}"
        lines.append(row)
    r = result["reaction_ms"]
    react = "n/a" if r["median"] is None else f"median {r['median']:.3f} ms, p99 {r['p99']:.3f} ms"
    for name, why in result.get("not_run", {}).items():
        lines.append(f"{name}: {why}")
    if "protection" in result:
        lines.append(f"protection {result['protection']}: productive time share {result['productive_time_share']}, "
                     f"false stops {result['false_stops']}, per walk-by worker-hour "
                     f"{result['false_stops_per_worker_hour']}")
    moving = result.get("collisions_arm_moving")
    lines.append(f"collisions {result['collisions']}/{result['scenarios']}"
                 + ("" if moving is None else f" ({moving} with the arm moving)")
                 + (f" (without the runtime {result['baseline']['collisions']}/{result['scenarios']})" if base else "")
                 + f"; reaction (keypoints in -> command on the link) {react}")
    return "\n".join(lines)


# ----------------------------------------------------------------------------------------------
# command line

def _speed(s: str) -> float:
    v = positive_float(s)
    if not SPEED_LIMITS_MPS[0] <= v <= SPEED_LIMITS_MPS[1]:
        raise argparse.ArgumentTypeError(f"must be {SPEED_LIMITS_MPS[0]}-{SPEED_LIMITS_MPS[1]} m/s, got {s}")
    return v


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--scenario", default="dissertation",
                   help=f"{', '.join(DISSERTATION)}, dissertation (all three) or random:N (default dissertation)")
    p.add_argument("--link", choices=LINKS, default="can", help="robot link (default can)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--json", default=None, metavar="OUT.json", help="write the results here")
    p.add_argument("--plot", default=None, metavar="OUT.png", help="Fig. 3.8: top-down worker and end-effector paths")
    p.add_argument("--max-speed", type=_speed, default=2.0, metavar="M",
                   help="fastest random walking speed (m/s, 0.5-2.0; default 2.0)")
    p.add_argument("--camera-hz", type=positive_float, default=30.0, help="camera rate (Hz; 30, or 5.8 as in ch. 3)")
    p.add_argument("--latency-ms", type=positive_float, default=None,
                   help="capture -> runtime latency of a frame (ms; default one camera period)")
    p.add_argument("--perception", choices=PERCEPTIONS, default="auto",
                   help="truth: detector keypoints at the true depth; lifter: the shipped lifter + calibration; "
                        "auto: lifter when the manifest has one (default)")
    p.add_argument("--no-runtime", action="store_true", help="baseline: the arm never sees the worker")
    p.add_argument("--with-baseline", action="store_true", help="also run the baseline and add it to the JSON")
    p.add_argument("--config", default=None, metavar="BOX.toml",
                   help="the box configuration the runtime runs (default: the shipped one, edge_runtime/box.example.toml)")
    p.add_argument("--retract-time", type=positive_float, default=None, metavar="S",
                   help="override [zones] retract_time_s, T_retract of Eq. 4 (s; the dissertation's 1.0 gives "
                        "R2 = 1 m, R1 = 3 m)")
    p.add_argument("--unlabelled-calibration", action="store_true",
                   help="lifter perception: calibrate through the runtime's own stand detection, without the "
                        "simulator's marker labels")
    p.add_argument("--only", default=None, metavar="NAME",
                   help="run only this scenario of the set (e.g. --scenario hard:10 --only hard_002)")
    p.add_argument("--protection", choices=tuple(PROTECTIONS), default=None,
                   help="override [zones] separation / speed_scaling: head (the dissertation's head-to-effector "
                        "zones), stop_only or speed_scaled (whole-body separation; default: the box's)")
    p.add_argument("--zone", action="append", metavar="KEY=VALUE",
                   help="override a ZoneParams number field of the runtime (repeatable), e.g. --zone predict_s=0.7")
    p.add_argument("--loop", action="append", metavar="KEY=VALUE",
                   help="override a LoopParams number field of the runtime (repeatable), e.g. --loop re_retract_m=100")
    p.add_argument("--validated", default=None, metavar="FILE",
                   help="add the run's figures to this validation record (reports/hrc/validated.json)")
    p.add_argument("--jobs", type=positive_int, default=1, help="worker processes (default 1)")
    p.add_argument("--quiet", action="store_true", help="no progress bar")


def _check_writable(path: str | None, flag: str) -> None:
    if path is None:
        return
    parent = Path(path).resolve().parent
    if not parent.is_dir():
        raise CliError(f"{flag} {path}: directory {str(parent)!r} does not exist")


def cmd(args) -> int:
    parse_scenario(args.scenario)
    _check_writable(args.json, "--json")
    _check_writable(args.plot, "--plot")
    _check_writable(args.validated, "--validated")
    box = load_box(args.config)
    zones = box.zones if args.retract_time is None else replace(box.zones, retract_time_s=args.retract_time)
    if args.protection is not None:
        zones = replace(zones, **PROTECTIONS[args.protection])
    box = replace(box, zones=overrides(zones, args.zone, "--zone"),
                  robot_loop=overrides(box.robot_loop, args.loop, "--loop"))
    common = dict(link=args.link, seed=args.seed, camera_hz=args.camera_hz, max_speed_mps=args.max_speed,
                  latency_ms=args.latency_ms, box=box, jobs=args.jobs, progress=not args.quiet, only=args.only,
                  labelled_calibration=not args.unlabelled_calibration)
    out, results = run(args.scenario, runtime=not args.no_runtime, perception=args.perception, keep_results=True,
                       **common)
    if args.with_baseline and not args.no_runtime:
        base = run(args.scenario, runtime=False, **common)
        out["baseline"] = {k: base[k] for k in ("collisions", "collided", "min_separation_m", "details")}
    if args.json:
        Path(args.json).write_text(json.dumps(out, indent=1) + "\n")
    if args.validated:
        record_validation(out, args.validated, "python -m firmware_sim " + " ".join(sys.argv[1:]))
    if args.plot:
        from firmware_sim.scenarios.hrc_plots import plot_runs

        plot_runs(results, out, args.plot)
    print(format_table(out) if len(out["details"]) <= 12 else _one_line(out))
    return 0


def _one_line(out: dict) -> str:
    r = out["reaction_ms"]
    return (f"hrc: {out['scenarios']} scenarios ({out['scenario']}), {out['link']} link, camera {out['camera_hz']:g} Hz, "
            f"perception {out['perception']}, runtime {'on' if out['runtime'] else 'OFF'}: collisions "
            f"{out['collisions']} ({out['collisions_arm_moving']} with the arm moving), not run {len(out['not_run'])}, min separation {out['min_separation_m']} m, "
            f"stops {out['stops']}, "
            f"retracts {out['retracts']}, false alarms {out['false_alarms']}, reaction median {r['median']} ms "
            f"p99 {r['p99']} ms; protection {out['protection']}: productive share {out['productive_time_share']}, "
            f"false stops per walk-by worker-hour {out['false_stops_per_worker_hour']}")


BAD_INPUT = (CliError, config.ConfigError)
