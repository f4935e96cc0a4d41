"""Chapter-2 style report: Tables 2.1-2.3 for every architecture on the simulated cohort.

    python -m models report --out reports/wearable --seed 0 [--subjects 20] [--epochs N]
                            [--archs convlstm,cnn,lstm,lda] [--data TRAIN.npz --test TEST.npz]

Writes under OUT:
  data/train.npz, data/test.npz, data/detector.json   simulated cohort (unless --data)
  <arch>/loso/metrics.json, confusion.png, predictions.npz, model.pt|pkl, folds/s<K>/
  <arch>/within/metrics.json, confusion.png             (unless --no-within)
  report.md, report.json                                the tables and the command that made them
"""
from __future__ import annotations

import json
import shlex
import sys
import time
from pathlib import Path

import numpy as np

from models.dataset import build_cohort_datasets, load_npz
from models.experiments import run_loso, run_within
from models.train import DEFAULT_EPOCHS

ARCH_ORDER = ("convlstm", "cnn", "lstm", "lda")
NAMES = {"convlstm": "ConvLSTM", "cnn": "CNN", "lstm": "LSTM", "lda": "LDA"}


def _f(x) -> str:
    return "–" if x is None or (isinstance(x, float) and np.isnan(x)) else f"{x:.2f}"


def subject_table(results: dict[str, dict], title: str) -> list[str]:
    archs = list(results)
    subs = sorted({s for m in results.values() for s in m.get("per_subject", {})}, key=int)
    head = "| Subject | " + " | ".join(f"{NAMES[a]} R | {NAMES[a]} P | {NAMES[a]} F1" for a in archs) + " |"
    lines = [f"### {title}", "", head, "|---|" + "---:|" * (3 * len(archs))]
    for s in subs:
        cells = []
        for a in archs:
            row = results[a].get("per_subject", {}).get(s)
            cells += [_f(row["recall"]), _f(row["precision"]), _f(row["f1"])] if row else ["–"] * 3
        lines.append(f"| {s} | " + " | ".join(cells) + " |")
    cells = []
    for a in archs:
        mean = results[a].get("per_subject_mean", {})
        cells += [_f(mean.get("recall")), _f(mean.get("precision")), _f(mean.get("f1"))]
    lines.append("| **Average** | " + " | ".join(f"**{c}**" for c in cells) + " |")
    return lines + [""]


def class_table(results: dict[str, dict], title: str) -> list[str]:
    lines = [f"### {title}", ""]
    for a, m in results.items():
        classes = m["classes"]
        lines += [f"| {NAMES[a]} | " + " | ".join(classes) + " |", "|---|" + "---:|" * len(classes)]
        for key, name in (("precision", "Precision"), ("recall", "Recall"), ("f1", "F1-score")):
            lines.append(f"| {name} | " + " | ".join(_f(m["per_class"][c][key]) for c in classes) + " |")
        lines.append("| Support | " + " | ".join(str(m["per_class"][c]["support"]) for c in classes) + " |")
        lines.append("")
    return lines


def summary_table(loso: dict[str, dict], within: dict[str, dict]) -> list[str]:
    lines = ["| Architecture | LOSO macro-F1 | LOSO macro-F1, onset captures | LOSO macro-F1 (5 distractions) | "
             "LOSO accuracy | LOSO mean per-subject F1 | within-subject macro-F1 | epochs |",
             "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for a, m in loso.items():
        w = within.get(a, {})
        lines.append(f"| {NAMES[a]} | {_f(m['macro_f1'])} | {_f(m.get('onset_only', {}).get('macro_f1'))} | "
                     f"{_f(m.get('macro_f1_distractions'))} | "
                     f"{_f(m['accuracy'])} | {_f(m.get('per_subject_mean', {}).get('f1'))} | "
                     f"{_f(w.get('macro_f1'))} | {m.get('epochs')} |")
    return lines + [""]


def _cached(run_dir: Path, reuse: bool) -> dict | None:
    f = run_dir / "metrics.json"
    return json.loads(f.read_text()) if reuse and f.exists() else None


def run_report(out: str, *, seed: int = 0, subjects: int = 20, epochs: int | None = None,
               archs=ARCH_ORDER, data: str | None = None, test: str | None = None, minutes: float = 15.0,
               jobs: int = 2, within: bool = True, progress: bool = True, command: str | None = None,
               reuse: bool = False) -> dict:
    """LOSO (and within-subject) for every arch; with ``reuse``, an arch whose
    metrics.json is already under ``out`` is read back instead of retrained
    (delete its directory to retrain just that one)."""
    out_p = Path(out)
    out_p.mkdir(parents=True, exist_ok=True)
    t_start = time.time()
    data, test, detector = _cohort(out_p, data, test, seed=seed, subjects=subjects, minutes=minutes,
                                   progress=progress)
    train = load_npz(data)
    test_ws = load_npz(test) if test else None
    loso, wit, timing = _run_archs(archs, train, test_ws, out_p, epochs=epochs, seed=seed, jobs=jobs, within=within,
                                   progress=progress, reuse=reuse, t_start=t_start)
    command = command or "python -m models " + " ".join(shlex.quote(x) for x in sys.argv[1:])
    md = _markdown(loso, wit, detector, command=command, seed=seed, data=data, test=test, train=train,
                   test_ws=test_ws, wall_s=time.time() - t_start)
    (out_p / "report.md").write_text("\n".join(md))
    summary = {"command": command, "seed": seed, "train": data, "test": test, "detector": detector,
               "timing_s": timing, "wall_s": round(time.time() - t_start, 1),
               "loso": {a: {k: m.get(k) for k in ("accuracy", "macro_f1", "macro_f1_distractions", "per_class",
                                                  "onset_only",
                                                  "confusion", "per_subject", "per_subject_mean", "epochs")}
                        for a, m in loso.items()},
               "within": {a: {k: m.get(k) for k in ("accuracy", "macro_f1", "macro_f1_distractions", "per_class",
                                                    "per_subject", "per_subject_mean", "protocol")}
                          for a, m in wit.items()}}
    (out_p / "report.json").write_text(json.dumps(summary, indent=2))
    return summary


def _cohort(out_p: Path, data: str | None, test: str | None, *, seed: int, subjects: int, minutes: float,
            progress: bool) -> tuple[str, str | None, dict | None]:
    """(training NPZ, test NPZ, detector statistics): the given files (the detector's from the
    detector.json beside them, if any), else a cohort simulated into ``out_p/data``."""
    if data is None:
        built = build_cohort_datasets(subjects, seed, minutes, out_p / "data", progress=progress)
        return built["train"], built["test"], built["detector"]
    detector_json = Path(data).with_name("detector.json")
    return data, test, json.loads(detector_json.read_text()) if detector_json.exists() else None


def _run_archs(archs, train, test_ws, out_p: Path, *, epochs: int | None, seed: int, jobs: int, within: bool,
               progress: bool, reuse: bool, t_start: float) -> tuple[dict, dict, dict]:
    """(LOSO metrics, within-subject metrics, seconds) per arch, each run (or read back) in turn."""
    loso, wit, timing = {}, {}, {}
    for a in archs:
        t0 = time.time()
        ep = DEFAULT_EPOCHS[a] if epochs is None else (0 if a == "lda" else epochs)
        loso[a] = _cached(out_p / a / "loso", reuse) or run_loso(
            a, train, test_ws, out_p / a / "loso", epochs=ep, seed=seed, jobs=jobs, progress=progress)
        timing[a] = {"loso_s": round(time.time() - t0, 1)}
        if within:
            t0 = time.time()
            wit[a] = _cached(out_p / a / "within", reuse) or run_within(
                a, train, test_ws, out_p / a / "within", epochs=ep, seed=seed, jobs=jobs, progress=progress)
            timing[a]["within_s"] = round(time.time() - t0, 1)
        if progress:
            print(f"{NAMES[a]:>8}: LOSO macro-F1 {loso[a]['macro_f1']:.3f} (acc {loso[a]['accuracy']:.3f})"
                  + (f", within {wit[a]['macro_f1']:.3f}" if a in wit else "")
                  + f"  [{time.time() - t_start:.0f} s]", file=sys.stderr)
    return loso, wit, timing


def _markdown(loso: dict, wit: dict, detector: dict | None, *, command: str, seed: int, data: str, test: str | None,
              train, test_ws, wall_s: float) -> list[str]:
    """report.md's lines: data, detector, summary, the chapter's tables, confusion matrices."""
    md = ["# Wearable distraction classifiers: chapter-2 style report", "",
          f"Command: `{command}`", "",
          f"Data: train `{data}` ({len(train)} ground-truth windows, {len(np.unique(train.subject))} subjects), "
          f"test `{test}` ({len(test_ws) if test_ws is not None else 0} detector captures). "
          "Train on ground-truth segments, test on detector captures (false alarms labelled Other). "
          f"Seed {seed}; wall time {wall_s:.0f} s.", ""]
    if detector:
        md += ["## Detector (section 2.3.1)", "",
               f"Recall {_f(detector['recall'])} ({detector['detected']}/{detector['distractions']} distractions "
               f"detected), precision {_f(detector['precision'])} ({detector['captures_distraction']}/"
               f"{detector['captures']} captures are distractions; {detector['false_alarms']} false alarms "
               f"incl. Other motions); counted per event as in the dissertation (detected / (detected + false alarms)) "
               f"precision is {_f(detector.get('precision_per_event'))}; {detector.get('repeat_captures')} repeat "
               f"captures. Dissertation: recall 0.97, precision 0.86.", ""]
    md += ["## Summary", "", *summary_table(loso, wit),
           "Dissertation (between-participant F1): ConvLSTM 0.87, LSTM 0.85, CNN 0.76, LDA 0.38.", "",
           "macro-F1 pools every fold's predictions and averages F1 over the classes (Other included); "
           "per-subject rows average over the classes present for that subject. 'Onset captures' leaves out "
           "the repeat captures (a second trigger inside a truth event that an earlier capture already "
           "caught, e.g. the return to the wheel after a long phone call): one capture per detected "
           "distraction plus the false alarms, the dissertation's count.", "",
           "## Between-participant (leave-one-subject-out)", "",
           *subject_table(loso, "Table 2.2: per subject (recall, precision, F1)"),
           *class_table(loso, "Table 2.3: per class")]
    if wit:
        md += ["## Within-participant", "", f"Protocol: {next(iter(wit.values()))['protocol']}.", "",
               *subject_table(wit, "Table 2.1: per subject (recall, precision, F1)"),
               *class_table(wit, "Per class (within-participant)")]
    md += ["## Confusion matrices (LOSO, rows = truth)", ""]
    md += [f"![{NAMES[a]}]({a}/loso/confusion.png)" for a in loso] + [""]
    return md
