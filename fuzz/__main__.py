"""``python -m fuzz [--target NAME ...] [--inputs N] [--seed S] [--json OUT] [--md OUT] [--timeout-s T]``

(``python -m fuzz merge SHARD.json ...``: one report from shard runs, :mod:`fuzz.merge`.)

Drives every target of fuzz/targets (or the named ones) with N inputs each and prints
one line per target: inputs, refused (the documented error), crashes, silent
acceptances, hangs, rate; then the first distinct tracebacks of each finding. Exit 1
when any target has a crash, a silent acceptance or a hang.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from fuzz.harness import TargetReport, discover, run_target

HEADER = ("target", "inputs", "refused", "crashes", "silent acceptances", "hangs", "inputs/s")


def _row(r: TargetReport) -> tuple:
    return (r.name, r.inputs, r.refused, r.crashes, r.silent_acceptances, r.hangs, f"{r.rate_per_s:,.0f}")


def markdown(reports: list[TargetReport], commands: str | list[str], commit: str | None = None,
             missing: list[str] | None = None) -> str:
    """The table (and a total row for several targets), the command lines, the tracebacks; a
    ``code`` column when the targets ran on different commits, and the targets ``missing``."""
    commands = [commands] if isinstance(commands, str) else commands
    lines = ["# Fuzz run\n", *(f"`{c}`\n" for c in commands)]
    per_target = len({r.commit for r in reports}) > 1
    if commit and not per_target:
        lines.append(f"Code: commit `{commit}`.\n")
    if missing:
        lines.append(f"**Not in this report** (no run of theirs was given): {', '.join(missing)}.\n")
    header = HEADER + (("code",) if per_target else ())
    lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(map(str, _row(r) + ((f"`{r.commit}`",) if per_target else ()))) + " |"
              for r in reports]
    if len(reports) > 1:
        total = TargetReport("**all**", *(sum(getattr(r, k) for r in reports)
                                          for k in ("inputs", "refused", "crashes", "silent_acceptances", "hangs")))
        lines.append("| " + " | ".join(map(str, _row(total)[:-1])) + " |" + " |" * (1 + per_target))
    for r in reports:
        for f in r.findings:
            lines += [f"\n## {r.name}: {f.key} ({f.count} inputs)\n", "```", f.traceback.rstrip(),
                      f"first input: {f.example}", "```"]
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    argv = sys.argv[1:] if argv is None else argv
    if argv[:1] == ["merge"]:
        from fuzz.merge import main as merge_main

        return merge_main(argv[1:])
    ap = argparse.ArgumentParser(prog="python -m fuzz", description=__doc__.splitlines()[0])
    ap.add_argument("--target", action="append", metavar="NAME", help="only this target (repeatable)")
    ap.add_argument("--inputs", type=int, default=100_000, metavar="N", help="inputs per target (default 100000)")
    ap.add_argument("--seed", type=int, default=0, metavar="S")
    ap.add_argument("--timeout-s", type=float, default=5.0, metavar="T", help="an input longer than this is a hang")
    ap.add_argument("--json", metavar="OUT", help="write the reports as JSON")
    ap.add_argument("--md", metavar="OUT", help="write the table and tracebacks as Markdown")
    ap.add_argument("--list", action="store_true", help="list the targets and exit")
    a = ap.parse_args(argv)
    targets = discover()
    if a.list:
        print("\n".join(targets))
        return 0
    unknown = sorted(set(a.target or ()) - set(targets))
    if unknown:
        print(f"python -m fuzz: unknown target(s) {', '.join(unknown)} (known: {', '.join(targets)})", file=sys.stderr)
        return 2
    reports = []
    print("  ".join(HEADER), flush=True)
    for name in a.target or targets:
        r = run_target(targets[name], a.inputs, a.seed, a.timeout_s)
        reports.append(r)
        print("  ".join(map(str, _row(r))), flush=True)
    for r in reports:
        for f in r.findings:
            print(f"\n{r.name}: {f.key} ({f.count} inputs)\n{f.traceback.rstrip()}\nfirst input: {f.example}")
    command = "python -m fuzz " + " ".join(argv)
    if a.json:
        Path(a.json).parent.mkdir(parents=True, exist_ok=True)
        Path(a.json).write_text(json.dumps({"command": command, "seed": a.seed, "inputs_per_target": a.inputs,
                                            "targets": [r.to_json() for r in reports]}, indent=1) + "\n")
    if a.md:
        Path(a.md).parent.mkdir(parents=True, exist_ok=True)
        Path(a.md).write_text(markdown(reports, command))
    return 0 if all(r.clean for r in reports) else 1


if __name__ == "__main__":
    sys.exit(main())
