"""``python -m fuzz merge SHARD.json|SHARD.log ... [--commit HASH ...] [--command CMD ...] [--json OUT] [--md OUT]``

One report from several shards of one campaign: ``make fuzz`` on a shared 2-core machine is
run as shards (``python -m fuzz --target ... --json a.json`` in two processes), each writing
its own JSON; this joins their targets into one table, keeping each shard's command line and
the code commit they ran on (given, since a shard's JSON does not record it: one for every shard,
or one per shard in order when a campaign's shards ran on different commits; each target then
carries its own). The report names the targets of fuzz/targets that no shard ran. A target named
in two shards is an error: the table would count it twice. A shard still running has no
JSON yet: its log (stdout) gives the targets it has finished (``load_log``).
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from fuzz.harness import Finding, TargetReport

HEADER_WORDS = ("target", "inputs", "refused", "crashes", "silent", "acceptances", "hangs", "inputs/s")
"""The words of the table header ``python -m fuzz`` prints first (fuzz.__main__.HEADER)."""


class MergeError(ValueError):
    """A shard file that is not a ``python -m fuzz --json`` report, or targets run twice."""


def load_shard(path: Path) -> tuple[dict, list[TargetReport]]:
    """A shard's JSON and its targets as TargetReports."""
    try:
        doc = json.loads(path.read_text())
        reports = []
        for t in doc["targets"]:
            fields = {k: v for k, v in t.items() if k != "rate_per_s"}  # a property, recomputed
            fields["findings"] = [Finding(**f) for f in fields.get("findings", [])]
            reports.append(TargetReport(**fields))
    except (OSError, ValueError, KeyError, TypeError) as e:
        raise MergeError(f"{path}: not a python -m fuzz --json report ({type(e).__name__}: {e})") from None
    return doc, reports


def load_log(path: Path) -> tuple[dict, list[TargetReport]]:
    """The targets a shard has finished, from the table rows it prints as it goes (its stdout):
    what there is to report while a shard still runs. No tracebacks (a shard prints them at the
    end); the seconds are recovered from the rate."""
    try:
        lines = path.read_text(errors="replace").splitlines()
    except OSError as e:
        raise MergeError(f"{path}: cannot read ({e.strerror or e})") from None
    if not any(line.split() == list(HEADER_WORDS) for line in lines):
        raise MergeError(f"{path}: not a python -m fuzz log (no table header)")
    reports = []
    for line in lines:
        cells = line.split("  ")
        if len(cells) == 7 and all(c.strip().isdigit() for c in cells[1:6]):
            inputs, refused, crashes, silent, hangs = (int(c) for c in cells[1:6])
            rate = float(cells[6].replace(",", "")) or 1.0
            reports.append(TargetReport(cells[0].strip(), inputs, refused, crashes, silent, hangs, inputs / rate))
    return {"command": f"(finished targets read from {path.name})"}, reports


def merge(paths: list[Path], commit: str | list[str] | None = None, commands: list[str] | None = None) -> dict:
    """The shards' targets in one document: ``commands`` (one per shard: given, else the
    shard's own), ``commit`` (one, or one per shard), ``targets`` (each with its commit),
    ``missing`` (targets of fuzz/targets no shard ran). A ``.log`` path is read with :func:`load_log`."""
    from fuzz.harness import discover

    commits = [commit] if isinstance(commit, str) or commit is None else list(commit)
    if len(commits) not in (1, len(paths)):
        raise MergeError(f"--commit: give one for every shard or one per shard ({len(paths)}), got {len(commits)}")
    given, commands, seeds, targets, seen = list(commands or []), [], set(), [], {}
    for i, path in enumerate(paths):
        doc, reports = load_log(path) if path.suffix == ".log" else load_shard(path)
        commands.append(given[i] if i < len(given) else doc.get("command", "?"))
        if "seed" in doc:  # a log does not say
            seeds.add(doc["seed"])
        for r in reports:
            if r.name in seen:
                raise MergeError(f"{path}: target {r.name} is also in {seen[r.name]}")
            seen[r.name] = path
            r.commit = commits[i if len(commits) > 1 else 0] or ""
            targets.append(r)
    one = sorted({c for c in commits if c})
    return {"commands": commands, "commit": one[0] if len(one) == 1 else one, "seed": sorted(seeds, key=str),
            "targets": sorted(targets, key=lambda r: r.name), "missing": sorted(set(discover()) - set(seen))}


def main(argv: list[str]) -> int:
    from fuzz.__main__ import markdown  # the one table writer

    ap = argparse.ArgumentParser(prog="python -m fuzz merge", description=__doc__.splitlines()[0])
    ap.add_argument("shards", nargs="+", type=Path, metavar="SHARD.json")
    ap.add_argument("--commit", action="append", metavar="HASH",
                    help="the code commit the shards ran on: once for all, or once per shard in order")
    ap.add_argument("--command", action="append", metavar="CMD",
                    help="the command line of each shard, in order (default: the one its JSON records)")
    ap.add_argument("--json", metavar="OUT")
    ap.add_argument("--md", metavar="OUT")
    a = ap.parse_args(argv)
    try:
        merged = merge(a.shards, a.commit if a.commit and len(a.commit) > 1 else (a.commit or [None])[0], a.command)
    except MergeError as e:
        print(f"python -m fuzz merge: {e}", file=sys.stderr)
        return 2
    reports = merged["targets"]
    for r in reports:
        print(f"{r.name}: {r.inputs} inputs, {r.crashes} crashes, {r.silent_acceptances} silent, {r.hangs} hangs")
    if a.json:
        Path(a.json).parent.mkdir(parents=True, exist_ok=True)
        Path(a.json).write_text(json.dumps({**merged, "targets": [r.to_json() for r in reports]}, indent=1) + "\n")
    if a.md:
        Path(a.md).parent.mkdir(parents=True, exist_ok=True)
        commit = merged["commit"] if isinstance(merged["commit"], str) else None
        Path(a.md).write_text(markdown(reports, merged["commands"], commit, merged["missing"]))
    return 0 if all(r.clean for r in reports) else 1
