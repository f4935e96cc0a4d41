"""People crossing in front of the camera: does the runtime's tracker keep who is who?

    python -m firmware_sim crossings --n 100 --seed 0 [--json OUT.json]

Each crossing: a random camera (:func:`firmware_sim.scenarios.recording.random_camera`: 3-8 m,
1-3 m high, wide-angle lens), two or three people (1.45-2.0 m) walking across its view on
straight lines through one floor point 3-8 m away, at 0.7-1.8 m/s, in opposite directions or
(a quarter of the walkers) the same one, so that one overtakes another, timed to pass that point within 0.6 s of each other, at depths up to 1.5 m
apart. COCO keypoints at a real detector's scale (:data:`firmware_sim.devices.camera.REAL_DETECTOR`),
the nearer person hiding the farther one (:func:`firmware_sim.devices.camera.occlude`), people
in random order in each frame and WITHOUT exporter ids, go through
:class:`edge_runtime.robot.keypoints.PersonTracker` (the box's [people] defaults).

Scored per person over the crossing (``CROSSING_HALF_S`` either side of the meeting time): the right id is kept (``right_id_kept``) when the tracker id he has in his last
detected frame is the one he had in his first, and nobody else ends with it; ``never_mixed``: he
also had that id in every frame he was detected and nobody else ever had it (no momentary swap
either). ``id_switches``: frames in which a person's id differs from his id in the frame before.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from edge_runtime.cli import positive_int
from edge_runtime.core.skeleton import HIP
from edge_runtime.robot.keypoints import PeopleTrackParams, Person, PersonTracker
from firmware_sim.devices.camera import REAL_DETECTOR, detect, occlude
from firmware_sim.people import motions
from firmware_sim.scenarios.head_error import stop_points
from firmware_sim.scenarios.recording import RATE_HZ, random_body, random_camera

BAD_INPUT = (OSError,)
CROSSING_HALF_S = 1.5
"""Ids are scored from this long before the people meet to this long after (s): the crossing,
not a walker leaving the image at the end of his path."""


def add_arguments(parser) -> None:
    parser.add_argument("--n", type=positive_int, default=100, help="crossings (default 100)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", metavar="OUT.json", help="write the figures here")


def crossing(rng: np.random.Generator, params: PeopleTrackParams = PeopleTrackParams()) -> dict:
    """One crossing: per person his (T,) tracker ids (-1: not detected) and the people count."""
    camera = random_camera(rng)
    centre = stop_points(camera, rng, 1)[0]
    right = camera.R[0, [0, 2]] / np.linalg.norm(camera.R[0, [0, 2]])
    forward = camera.R[2, [0, 2]] / np.linalg.norm(camera.R[2, [0, 2]])
    n_people = int(rng.choice([2, 3]))
    meet_s = 3.0
    walks, signs = [], []
    for k in range(n_people):
        a = math.radians(rng.uniform(-40, 40))
        signs.append((1 if k % 2 == 0 else -1) * int(rng.choice([1, 1, 1, -1])))
        d = (math.cos(a) * right + math.sin(a) * forward) * signs[-1]
        speed = rng.uniform(0.7, 1.8)
        through = centre + forward * rng.uniform(-0.75, 0.75)
        arrive = meet_s + rng.uniform(-0.3, 0.3)
        start = through - d * speed * arrive
        m = motions.walk(random_body(rng), [start, through + d * speed * (6.0 - arrive)], speed, RATE_HZ,
                         accel_mps2=10.0, stop_at_end=False, rng=rng)
        walks.append(m.joints_m)
    n = min(len(w) for w in walks)
    kps = [detect(camera, w[:n], rng, REAL_DETECTOR, fmt="coco") for w in walks]
    kps = occlude(kps, [camera.to_camera(w[:n, HIP])[:, 2] for w in walks], rng)
    tracker = PersonTracker(params)
    ids = np.full((n_people, n), -1)
    for t in range(n):
        dets = [(i, Person(kp[t])) for i, kp in enumerate(kps) if np.isfinite(kp[t, :, :2]).all(axis=1).any()]
        order = rng.permutation(len(dets))
        people = [dets[i][1] for i in order]
        for who, tracked in zip([dets[i][0] for i in order], _aligned(people, tracker.update(t / RATE_HZ, people))):
            if tracked is not None:
                ids[who, t] = tracked.id
    window = slice(int((meet_s - CROSSING_HALF_S) * RATE_HZ), int((meet_s + CROSSING_HALF_S) * RATE_HZ))
    return {"ids": ids[:, window], "people": n_people, "overtaking": len(set(signs)) < len(signs)}


def _aligned(people, tracked):
    """The tracker's output (people that are people, in order) lined up with its input (None: dropped)."""
    out, it = [], iter(tracked)
    nxt = next(it, None)
    for p in people:
        if nxt is not None and nxt.keypoints is p.keypoints:
            out.append(nxt)
            nxt = next(it, None)
        else:
            out.append(None)
    return out


def score(results: list[dict]) -> dict:
    """The figures over all crossings, and apart for those where some walk the same way (one
    overtakes another: long overlaps at the same image speed, the hard case without appearance)."""
    return {**_score(results), "opposite_only": _score([r for r in results if not r["overtaking"]]),
            "with_overtaking": _score([r for r in results if r["overtaking"]])}


def _score(results: list[dict]) -> dict:
    kept = persons = all_kept = switches = never_mixed = 0
    for r in results:
        ids = r["ids"]
        ok_all = True
        for who, row in enumerate(ids):
            seen = row[row >= 0]
            if not len(seen):
                continue
            persons += 1
            others = np.concatenate([ids[o][ids[o] >= 0] for o in range(len(ids)) if o != who] or [np.zeros(0, int)])
            last_others = {int(ids[o][ids[o] >= 0][-1]) for o in range(len(ids)) if o != who and (ids[o] >= 0).any()}
            ok = seen[0] == seen[-1] and int(seen[-1]) not in last_others
            kept += int(ok)
            never_mixed += int(bool(ok and seen[0] not in others and (seen == seen[0]).all()))
            ok_all &= bool(ok)
            switches += int((np.diff(seen) != 0).sum())
        all_kept += int(ok_all)
    return {"crossings": len(results), "people": persons, "right_id_kept": kept,
            "right_id_kept_fraction": round(kept / max(persons, 1), 4),
            "never_mixed_fraction": round(never_mixed / max(persons, 1), 4),
            "crossings_all_ids_kept_fraction": round(all_kept / max(len(results), 1), 4),
            "id_switches": int(switches), "two_people": int(sum(r["people"] == 2 for r in results)),
            "three_people": int(sum(r["people"] == 3 for r in results))}


def cmd(args) -> int:
    rng = np.random.default_rng(args.seed)
    results = [crossing(np.random.default_rng(int(s))) for s in rng.integers(0, 2**31, args.n)]
    res = {"command": f"python -m firmware_sim crossings --n {args.n} --seed {args.seed}"
                      + (f" --json {args.json}" if args.json else ""), **score(results)}
    if args.json:
        Path(args.json).write_text(json.dumps(res, indent=1) + "\n")
    print(f"crossings: {res['crossings']} ({res['two_people']} of two people, {res['three_people']} of three): "
          f"right id kept for {res['right_id_kept']} of {res['people']} people "
          f"({100 * res['right_id_kept_fraction']:.1f} %; never mixed up {100 * res['never_mixed_fraction']:.1f} %), "
          f"all ids kept in "
          f"{100 * res['crossings_all_ids_kept_fraction']:.1f} % of crossings, {res['id_switches']} id switches")
    for kind in ("opposite_only", "with_overtaking"):
        r = res[kind]
        print(f"  {kind}: {r['crossings']} crossings, right id kept {r['right_id_kept']} of {r['people']} "
              f"({100 * r['right_id_kept_fraction']:.1f} %), never mixed up {100 * r['never_mixed_fraction']:.1f} %")
    return 0
