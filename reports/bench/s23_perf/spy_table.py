"""Where a frame's (and a tick's) time goes, line by line, from a py-spy sampling profile of prof_frame.py.

py-spy samples the interpreter's stack from outside (no instrumentation: a sample costs the profiled process
nothing), so the share of samples each line holds is the share of the time it takes, numpy's C work included (a
numpy call's time is its calling line's). Only samples inside a frame (``_Frames.__call__``) or a control tick
(``RobotLoop.tick``) are counted.

    py-spy record -r 2000 -f raw -o RAW -- python reports/bench/s23_perf/prof_frame.py --mode plain --out X.json
    python reports/bench/s23_perf/spy_table.py RAW [--frames N --ticks M] [--top 40]

With the frame and tick counts (prof_frame's output) the shares are turned into microseconds per frame or tick.
"""
from __future__ import annotations

import argparse
import re
from collections import Counter

_FRAME = re.compile(r"^(?P<fn>.*?) \((?P<file>[^:()]+):(?P<line>\d+)\)$")


def _parse(path: str):
    for row in open(path):
        stack, _, count = row.rstrip("\n").rpartition(" ")
        yield stack.split(";"), int(count)


def _where(frame: str) -> tuple[str, str, str]:
    m = _FRAME.match(frame)
    if not m:
        return frame, "", ""
    return m["fn"], m["file"].split("/")[-1], m["line"]


def _ours(frame: str) -> bool:
    return "edge_runtime/" in frame or "bench/" in frame


STAGES = ("PersonTracker.update", "_usable_all", "StreamingLifter._prepare", "_lift", "_finish", "PeopleLifter.push",
          "RobotLoop._poll_link", "Calibration.to_robot", "HeadTracker.update", "body_spheres_of",
          "separations_per_shift_m", "HazardMonitor._speed_and_separation", "HazardMonitor.observe",
          "RobotLoop._retract_backfires", "RobotLoop._escape", "RobotLoop._call", "RobotLoop._act",
          "RobotLoop.feed_joints", "RobotLoop.feed_poses", "RobotLoop.feed_people", "_Frames.__call__")
"""A frame's stages, innermost first: a sample counts to the first of them on its stack."""


def stage_table(path: str, frame_us: float) -> str:
    """Each stage's share of the frames' samples (and us of ``frame_us`` when given)."""
    total, counts = 0, Counter()
    for frames, n in _parse(path):
        names = [_where(f)[0] for f in frames]
        if "_Frames.__call__" not in names:
            continue
        total += n
        counts[next(s for s in STAGES if s in names)] += n
    return "\n".join(f"  {s:40s} {counts[s] / total * 100:5.1f} %" + (f" {counts[s] / total * frame_us:8.1f} us"
                                                                        if frame_us else "") for s in STAGES)


def table(path: str, top: int, per: dict[str, int], under: str = "") -> str:
    kinds = {"frame": ("_Frames.__call__", "robot_cycle.py"), "tick": ("RobotLoop.tick", "loop.py")}
    total = Counter()
    own_line: dict[str, Counter] = {k: Counter() for k in kinds}
    own_fn: dict[str, Counter] = {k: Counter() for k in kinds}
    stage: dict[str, Counter] = {k: Counter() for k in kinds}
    below: dict[str, Counter] = {k: Counter() for k in kinds}
    for frames, n in _parse(path):
        where = [_where(f) for f in frames]
        for kind, (fn, file) in kinds.items():
            entry = next((i for i, (f, fl, _) in enumerate(where) if f == fn and fl == file), None)
            if entry is None:
                continue
            total[kind] += n
            # the deepest of the project's own lines (numpy's and the libraries' Python wrappers count to the line
            # that called them)
            f, fl, line = next((w for w, full in zip(reversed(where), reversed(frames)) if _ours(full)), where[-1])
            own_line[kind][f"{fl}:{line} {f}"] += n
            own_fn[kind][f"{fl} {f}"] += n
            if under:
                inside = next((i for i, (g, _, _) in enumerate(where) if g == under), None)
                if inside is None:
                    continue
                below[kind][f"{fl}:{line} {f}"] += n
            inner = where[entry + 1:entry + 4]
            stage[kind][" > ".join(f"{f}" for f, _, _ in inner) or "(itself)"] += n
            break
    out = []
    for kind in kinds:
        t = total[kind]
        if not t:
            continue
        us = per.get(kind)

        def scale(c: int, t: int = t, us: float | None = us) -> str:
            return f"{c / t * 100:5.1f} %" + ("" if us is None else f" {c / t * us:8.1f}")

        unit = "share" if kind not in per else f"share, us per {kind} (of {per[kind]:.0f} us)"
        out.append(f"== {kind}: {t} samples ({unit})")
        out.append("-- by the three calls below the entry point")
        out += [f"  {scale(c)}  {k}" for k, c in stage[kind].most_common(top)]
        out.append("-- by function (own time: its lines, the numpy calls on them included)")
        out += [f"  {scale(c)}  {k}" for k, c in own_fn[kind].most_common(top)]
        out.append("-- by line (the project's own: the numpy and library calls on it included)")
        out += [f"  {scale(c)}  {k}" for k, c in own_line[kind].most_common(top)]
        if under:
            out.append(f"-- by line, inside {under}")
            out += [f"  {scale(c)}  {k}" for k, c in below[kind].most_common(top)]
    return "\n".join(out)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("raw")
    ap.add_argument("--top", type=int, default=40)
    ap.add_argument("--frame-us", type=float, default=0.0, help="mean CPU us per frame (prof_frame), for us figures")
    ap.add_argument("--tick-us", type=float, default=0.0, help="mean CPU us per tick")
    ap.add_argument("--stages", action="store_true", help="only the frame's stage shares")
    ap.add_argument("--under", default="", help="also: the lines inside this function (e.g. HazardMonitor.observe)")
    a = ap.parse_args()
    per = {k: v for k, v in (("frame", a.frame_us), ("tick", a.tick_us)) if v}
    if a.stages:
        print(stage_table(a.raw, a.frame_us))
    else:
        print(table(a.raw, a.top, per, a.under))


if __name__ == "__main__":
    main()
