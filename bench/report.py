"""What a bench run reports: per-model profiles, the text and Markdown tables, and ``--compare``.

The report (``--json``) is::

    {"machine": {...}, "method": {...},
     "results":  [{"model", "precision", "runtime", "threads", "p50_us", "p99_us", "mean_us", "n",
                   "file_bytes", "peak_rss_mb", ...}, ...],
     "skipped":  [{"model", "precision", "runtime", "threads", "note"}, ...],
     "loops":    [{"name", ...}, ...],
     "profiles": [{"model", "threads", "fp32": {...}, "int8": {...}, "int8_over_fp32": {...}}, ...]}
"""
from __future__ import annotations

ROW_KEY = ("model", "precision", "runtime", "threads")
PROFILE_FIGURES = ("file_bytes", "peak_rss_mb", "model_rss_mb", "p50_us", "p99_us")
COMPARED = ("p50_us", "p99_us", "mean_us", "peak_rss_mb", "cpu_share_pct")
"""Figures ``--compare`` divides, where both runs have them (lower is better for all)."""


def row_key(r: dict) -> tuple:
    return tuple(r.get(k) for k in ROW_KEY)


def _find(results: list[dict], **match) -> dict | None:
    return next((r for r in results if all(r.get(k) == v for k, v in match.items())), None)


def _ratio(a, b) -> float | None:
    return round(a / b, 3) if isinstance(a, (int, float)) and isinstance(b, (int, float)) and b else None


def profiles(results: list[dict]) -> list[dict]:
    """Per model and thread count: int8 against fp32 on onnxruntime (file size, peak memory,
    latency and their ratios), and the speed-ups of int8 over fp32 and over torch eager."""
    out = []
    for model in dict.fromkeys(r["model"] for r in results):
        for t in sorted({r["threads"] for r in results if r["model"] == model}):
            f32 = _find(results, model=model, precision="fp32", runtime="onnxruntime", threads=t)
            i8 = _find(results, model=model, precision="int8", runtime="onnxruntime", threads=t)
            if not (f32 and i8):
                continue
            te = _find(results, model=model, precision="fp32", runtime="torch-eager", threads=t)
            p = {"model": model, "threads": t, "runtime": "onnxruntime",
                 "fp32": {k: f32.get(k) for k in PROFILE_FIGURES}, "int8": {k: i8.get(k) for k in PROFILE_FIGURES},
                 "int8_over_fp32": {k: _ratio(i8.get(k), f32.get(k)) for k in PROFILE_FIGURES},
                 "int8_speedup_vs_fp32": _ratio(f32["p50_us"], i8["p50_us"]),
                 "int8_speedup_vs_torch_eager": _ratio(te["p50_us"], i8["p50_us"]) if te else None}
            out.append(p)
    return out


def _fmt(v, spec: str = ",.1f") -> str:
    return "-" if v is None else format(v, spec)


def _kib(n) -> str:
    return "-" if n is None else f"{n / 1024:,.1f}"


def format_profiles(profs: list[dict]) -> str:
    """An embedded toolchain's memory/latency summary, one block per model and thread count."""
    units = {"file_bytes": ("file", ",.0f", "B"), "peak_rss_mb": ("peak RSS", ",.1f", "MiB"),
             "model_rss_mb": ("RSS of the model", ",.1f", "MiB"), "p50_us": ("p50", ",.1f", "us"),
             "p99_us": ("p99", ",.1f", "us")}
    lines = []
    for p in profs:
        lines.append(f"profile {p['model']} on {p['runtime']}, {p['threads']} thread(s)"
                     f"{'':<4}{'fp32':>14}{'int8':>14}{'int8/fp32':>11}")
        for k, (label, spec, unit) in units.items():
            lines.append(f"  {label + ' (' + unit + ')':<44}{_fmt(p['fp32'][k], spec):>14}"
                         f"{_fmt(p['int8'][k], spec):>14}{_fmt(p['int8_over_fp32'][k], '.2f'):>11}")
        s = f"  int8 is {_fmt(p['int8_speedup_vs_fp32'], '.2f')}x faster than fp32 (p50)"
        if p["int8_speedup_vs_torch_eager"] is not None:
            s += f", {_fmt(p['int8_speedup_vs_torch_eager'], '.2f')}x faster than torch eager"
        lines.append(s)
    return "\n".join(lines)


def _loop_figure(lp: dict) -> str:
    if lp.get("available") is False:
        return f"not available ({lp['note']})"
    if not lp.get("n"):
        return "no samples"
    s = f"p50 {lp['p50_us']:,.1f} us, p99 {lp['p99_us']:,.1f} us, mean {lp['mean_us']:,.1f} us (n {lp['n']:,})"
    if "cpu_share_pct" in lp:
        blocks = f" in blocks of {lp['block_samples']}" if lp.get("block_samples", 1) > 1 else ""
        s += (f"; CPU {lp['cpu_share_pct']:.2f} % of one core at {lp['rate_hz']:g} Hz{blocks} over {lp['seconds']:g} s, "
              f"{lp['deadline_misses']} deadline misses")
    if "captures" in lp:
        s += f", {lp['captures']} capture(s)"
    if "hops" in lp:
        s += f", {lp['hops']} stream decision(s)"
    if "peak_rss_mb" in lp:
        s += f"; peak RSS {lp['peak_rss_mb']:.1f} MiB"
    if "escapes" in lp:
        s += (f"; {lp['commands']:,} commands: {lp['speed_changes']} speed overrides, {lp['stops']} stops, "
              f"{lp['retracts']} retractions ({lp['escapes']} escape turns), {lp['unacked']} unacknowledged")
    if lp.get("p99_note"):
        s += f" [{lp['p99_note']}]"
    if (lp.get("from_due") or {}).get("n"):
        f = lp["from_due"]
        s += (f"; from when the keypoints were due (the frame's schedule time, waits for ticks and late starts "
              f"included) p50 {f['p50_us']:,.1f} us, p99 {f['p99_us']:,.1f} us, max {f['max_us']:,.1f} us"
              + (" (the figure the 5 ms is judged on)" if lp.get("judged_on") == "from_due" else ""))
    if (lp.get("from_feed") or {}).get("n"):
        f = lp["from_feed"]
        s += f"; from feed_people's own t_in (after tracking) p50 {f['p50_us']:,.1f} us, p99 {f['p99_us']:,.1f} us"
    if (lp.get("frame_cpu") or {}).get("n"):
        f = lp["frame_cpu"]
        s += f"; the frames' CPU time p50 {f['p50_us']:,.1f} us, p99 {f['p99_us']:,.1f} us"
    if lp.get("by_kind"):
        s += "; by kind: " + ", ".join(
            f"{k} n {v['n']} p50 {v['p50_us']:,.1f} p99 {v['p99_us']:,.1f} max {v['max_us']:,.1f} us"
            + (" (p99 of < 100)" if v["n"] < 100 else "") for k, v in lp["by_kind"].items())
    return s


WHAT_A_RUN_IS = {
    "convlstm": "convlstm: the whole capture (S = 6 sub-windows) in one run (the one-shot model: the comparison)",
    "convlstm_step": "convlstm_step: per decision: one step, what the box runs when a sub-window of a capture "
                     "completes (the sub-window and the LSTM state in, the decision and the next state out); "
                     "on onnxruntime timed as the box calls it (StepModel.step_stream: inputs and outputs bound once, "
                     "the state kept in the bound buffers from step to step; captures of 6 steps from the zero state)",
}
"""What one timed call of a model is, where that needs saying (a row's ``model``)."""


def _what_a_run_is(report: dict) -> list[str]:
    shown = dict.fromkeys(r["model"] for r in report["results"])
    return [WHAT_A_RUN_IS[m] for m in shown if m in WHAT_A_RUN_IS] if "convlstm_step" in shown else []


def format_table(report: dict) -> str:
    """The plain-text table printed by ``python -m bench``."""
    m = report["machine"]
    lines = [f"{m['cpu']} ({m['cores']} cores, using {m['cpus_used']}), load {m['load_avg_1_5_15']}, "
             f"python {m['python']}, onnxruntime {m['onnxruntime']}, openvino {m.get('openvino') or 'absent'}, "
             f"torch {m['torch'] or 'absent'}",
             f"{'model':<10} {'precision':<9} {'runtime':<12} {'threads':>7} {'p50 us':>9} {'p99 us':>9} "
             f"{'mean us':>9} {'n':>6} {'file KiB':>9} {'peak RSS MiB':>12}"]
    for r in report["results"]:
        lines.append(f"{r['model']:<10} {r['precision']:<9} {r['runtime']:<12} {r['threads']:>7} "
                     f"{r['p50_us']:>9.1f} {r['p99_us']:>9.1f} {r['mean_us']:>9.1f} {r['n']:>6} "
                     f"{_kib(r['file_bytes']):>9} {r['peak_rss_mb']:>12.1f}")
    for s in report.get("skipped", []):
        lines.append(f"{s['model']:<10} {s['precision']:<9} {s['runtime']:<12} {s['threads']:>7} skipped: {s['note']}")
    lines += _what_a_run_is(report)
    if report.get("loops"):
        lines.append("loops:")
        lines += [f"  {lp['name']:<17} {_loop_figure(lp)}" for lp in report["loops"]]
    if report.get("profiles"):
        lines.append(format_profiles(report["profiles"]))
    return "\n".join(lines)


def format_markdown(report: dict) -> str:
    """The README's tables: per-inference latency, then loop costs."""
    m = report["machine"]
    lines = [f"Measured with `{report['method']['command']}` on {m['cpu']} ({m['cores']} cores, CPUs "
             f"{m['cpus_used']}, load average {m['load_avg_1_5_15']} at the start), python {m['python']}, "
             f"onnxruntime {m['onnxruntime']}, openvino {m.get('openvino') or 'absent'}, torch "
             f"{m['torch'] or 'absent'}; batch 1, {report['method']['n']} timed calls per row after "
             f"{report['method']['warmup']} warm-up calls. A shared machine: expect noise."
             + (f" A busy-loop process ran on CPU(s) {report['load_generator_cpus']} throughout (the other core busy)."
                if report.get("load_generator_cpus") else ""), "",
             "| model | precision | runtime | threads | p50 µs | p99 µs | mean µs | file KiB | peak RSS MiB |",
             "|---|---|---|---:|---:|---:|---:|---:|---:|"]
    for r in report["results"]:
        lines.append(f"| {r['model']} | {r['precision']} | {r['runtime']} | {r['threads']} | {r['p50_us']:,.1f} | "
                     f"{r['p99_us']:,.1f} | {r['mean_us']:,.1f} | {_kib(r['file_bytes'])} | "
                     f"{r['peak_rss_mb']:,.1f} |")
    for s in report.get("skipped", []):
        lines.append(f"| {s['model']} | {s['precision']} | {s['runtime']} | {s['threads']} | "
                     f"skipped: {s['note']} | | | | |")
    lines += [""] + _what_a_run_is(report) if _what_a_run_is(report) else []
    if report.get("loops"):
        lines += ["", "| loop | cost |", "|---|---|"]
        lines += [f"| {lp['name']} | {_loop_figure(lp)} |" for lp in report["loops"]]
    return "\n".join(lines) + "\n"


def compare(new: dict, old: dict, tolerance: float = 0.10) -> tuple[list[str], int]:
    """Lines of new/old ratios per result row and loop, and the number of regressions
    (a ratio above 1 + ``tolerance``: slower, or more memory or CPU)."""
    lines, regressions = [], 0

    def one(label: str, a: dict | None, b: dict | None) -> None:
        nonlocal regressions
        if a is None or b is None:
            lines.append(f"{label:<48} {'only in new' if b is None else 'only in old'}")
            return
        if a.get("scenario") != b.get("scenario"):  # same name, another measurement (bench/robot_cycle.py SCENARIO)
            lines.append(f"{label:<48} not comparable (scenario {b.get('scenario') or 'untagged'} -> "
                         f"{a.get('scenario') or 'untagged'})")
            return
        parts = []
        for k in COMPARED:
            r = _ratio(a.get(k), b.get(k))
            if r is None:
                continue
            bad = r > 1 + tolerance
            regressions += bad
            parts.append(f"{k} {r:.2f}" + (" REGRESSION" if bad else ""))
        lines.append(f"{label:<48} " + (", ".join(parts) or "nothing to compare"))

    old_rows = {row_key(r): r for r in old.get("results", [])}
    for r in new.get("results", []):
        one(" ".join(str(x) for x in row_key(r)), r, old_rows.pop(row_key(r), None))
    for k, r in old_rows.items():
        one(" ".join(str(x) for x in k), None, r)
    old_loops = {lp["name"]: lp for lp in old.get("loops", [])}
    for lp in new.get("loops", []):
        one(f"loop {lp['name']}", lp, old_loops.pop(lp["name"], None))
    for name, lp in old_loops.items():
        one(f"loop {name}", None, lp)
    lines.insert(0, f"new/old ratios (above {1 + tolerance:.2f} = regression): {regressions} regression(s)")
    return lines, regressions
