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
from models.selection import LOSS_KEYS
from models.train import DEFAULT_EPOCHS

SUBWINDOW_S = 33 * 7 / 200
"""One sub-window: 33 resampled frames at 200/7 Hz = 1.155 s of the capture."""
PRE_TRIGGER_S = 1.0
"""A capture starts 1 s before its trigger (frames T-100 ... T+599)."""
ARCH_ORDER = ("convlstm", "cnn", "lstm", "lda", "lda_summary")
NAMES = {"convlstm": "ConvLSTM", "cnn": "CNN", "lstm": "LSTM", "lda": "LDA", "lda_summary": "LDA (12 summary stats)"}


def _f(x, digits: int = 2) -> str:
    return "–" if x is None or (isinstance(x, float) and np.isnan(x)) else f"{x:.{digits}f}"


def _f3(x) -> str:
    """Macro-F1 against the must-hold (>= 0.80): two decimals would show 0.7988 as 0.80."""
    return _f(x, 3)


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


def _folds(m: dict) -> str:
    """How many LOSO folds (held-out subjects) a figure pools: "20", or "6 of 20" when folds are missing."""
    n = len(m.get("folds") or [])
    return f"{n}" if m.get("all_folds", True) else f"{n} of {m.get('subjects_total', '?')}"


def headline_table(loso: dict[str, dict]) -> list[str]:
    """Every capture the box classifies (onsets, repeats, false alarms), all architectures."""
    lines = ["| Architecture | LOSO folds | macro-F1, every capture | accuracy | macro-F1, 5 distractions | "
             "ECE (no temperature) | epochs |", "|---|---:|---:|---:|---:|---:|---:|"]
    for a, m in loso.items():
        lines.append(f"| {NAMES[a]} | {_folds(m)} | **{_f3(m['macro_f1'])}** | {_f(m['accuracy'])} | "
                     f"{_f(m.get('macro_f1_distractions'))} | {_f(m.get('ece'))} | {m.get('epochs')} |")
    return lines + [""]


def steps_table(m: dict) -> list[str]:
    """The ConvLSTM's decision after S = 1..6 sub-windows (every capture; onset captures)."""
    lines = ["| S sub-windows | capture seen (s) | time after the trigger (s) | accuracy | macro-F1, every capture | "
             "ECE raw | ECE, temperature-scaled | macro-F1, onset captures |", "|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for r in m.get("steps", []):
        seen = r["steps"] * SUBWINDOW_S
        lines.append(f"| {r['steps']} | {seen:.2f} | {seen - PRE_TRIGGER_S:+.2f} | {_f(r['accuracy'])} | "
                     f"**{_f3(r['macro_f1'])}** | {_f(r['ece_raw'])} | {_f(r['ece'])} | {_f3(r.get('onset_macro_f1'))} |")
    return lines + [""]


def save_steps_png(m: dict, path: Path) -> Path:
    """Macro-F1 (every capture, onset captures) and ECE of the ConvLSTM's decision after S sub-windows."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = m["steps"]
    t = [r["steps"] * SUBWINDOW_S - PRE_TRIGGER_S for r in rows]
    fig, ax = plt.subplots(figsize=(6.4, 3.6), dpi=110)
    ax.plot(t, [r["macro_f1"] for r in rows], "o-", label="macro-F1, every capture")
    ax.plot(t, [r.get("onset_macro_f1") for r in rows], "s--", label="macro-F1, onset captures")
    ax.plot(t, [r["ece"] for r in rows], "^:", label="ECE (temperature-scaled)")
    ax.plot(t, [r["ece_raw"] for r in rows], "v:", alpha=0.6, label="ECE (raw)")
    for r, x in zip(rows, t):
        ax.annotate(f"S={r['steps']}", (x, r["macro_f1"]), textcoords="offset points", xytext=(0, 6), ha="center",
                    fontsize=7)
    ax.set_xlabel("time after the trigger when the decision can be made (s)")
    ax.set_ylim(0, 1)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="center right")
    ax.set_title(f"ConvLSTM early decisions, LOSO ({len(m.get('folds', []))} folds)", fontsize=10)
    fig.tight_layout()
    fig.savefig(path)
    plt.close(fig)
    return path


def same_folds_table(loso: dict[str, dict], out_p: Path, test_ws) -> list[str]:
    """For every fold set of an architecture that did not run all folds, every architecture that ran
    those folds scored on those subjects only, so that architectures run on different numbers of
    folds compare on the same captures."""
    from models.evaluate import compute_metrics

    if test_ws is None or test_ws.repeat is None:
        return []
    sets = sorted({frozenset(m.get("folds", [])) for m in loso.values() if not m.get("all_folds", True)},
                  key=len, reverse=True)
    lines = []
    for common in (c for c in sets if c):
        subjects = sorted(int(f.lstrip("s")) for f in common)
        lines += [f"On the same held-out subjects ({', '.join(map(str, subjects))}):", "",
                  "| Architecture | macro-F1, every capture | macro-F1, onset captures | accuracy, repeat captures |",
                  "|---|---:|---:|---:|"]
        for a, m in loso.items():
            if not common <= set(m.get("folds", [])):
                continue
            with np.load(out_p / a / "loso" / "predictions.npz") as z:
                y, yp, subj, classes = z["y_true"], z["y_pred"], z["subject"], list(z["classes"])
            rep = np.concatenate([test_ws.repeat[test_ws.subject == int(f.lstrip("s"))] for f in m["folds"]])
            keep = np.isin(subj, subjects)
            on, again = keep & (rep == 0), keep & (rep == 1)
            lines.append(f"| {NAMES[a]} | {_f3(compute_metrics(y[keep], yp[keep], classes)['macro_f1'])} | "
                         f"{_f3(compute_metrics(y[on], yp[on], classes)['macro_f1'])} | "
                         f"{_f(float(np.mean(y[again] == yp[again])) if again.any() else None)} |")
        lines.append("")
    return lines


def onset_table(loso: dict[str, dict]) -> list[str]:
    lines = ["| Architecture | LOSO folds | macro-F1, every capture | macro-F1, onset captures | "
             "accuracy, repeat captures |", "|---|---:|---:|---:|---:|"]
    for a, m in loso.items():
        rep = m.get("repeat_only") or {}
        lines.append(f"| {NAMES[a]} | {_folds(m)} | {_f3(m['macro_f1'])} | "
                     f"{_f3(m.get('onset_only', {}).get('macro_f1'))} | {_f(rep.get('accuracy'))} |")
    return lines + [""]


def summary_table(loso: dict[str, dict], within: dict[str, dict]) -> list[str]:
    lines = ["| Architecture | LOSO macro-F1, onset captures | LOSO macro-F1 (5 distractions) | "
             "LOSO mean per-subject F1 | within-subject macro-F1 |",
             "|---|---:|---:|---:|---:|"]
    for a, m in loso.items():
        w = within.get(a, {})
        lines.append(f"| {NAMES[a]} | {_f(m.get('onset_only', {}).get('macro_f1'))} | "
                     f"{_f(m.get('macro_f1_distractions'))} | {_f(m.get('per_subject_mean', {}).get('f1'))} | "
                     f"{_f(w.get('macro_f1'))} |")
    return lines + [""]


def _selection_lines(loso: dict) -> list[str]:
    recipe = next((m.get("recipe") for m in loso.values() if m.get("recipe")), None) or {}
    extra = "".join(f"; {k.replace('_', ' ')} {recipe[k]:g}" for k in LOSS_KEYS if recipe.get(k) is not None)
    others = [NAMES[a] for a in ("cnn", "lstm") if a in loso]
    return [f"- **Training recipe** (detector captures of the training subjects in training: "
            f"{'yes' if recipe.get('captures') else 'no'}; time shift up to {recipe.get('shift_fwd')} frames forward"
            f"{extra}; ConvLSTM epochs {recipe.get('epochs')} of a {recipe.get('schedule_epochs')}-epoch schedule): "
            f"chosen on {recipe.get('chosen_on', 'nothing (defaults)')} "
            "([selection/selection.md](selection/selection.md))."
            + (f" {' and '.join(others)} take the same recipe, with the epochs in the table above (not selected "
               "for them)." if others else "") + " The LDAs have nothing to choose.",
            "- **Temperatures per step** (ECE rows): per fold, on every capture of the selection cohort.",
            "- **Held-out subjects**: touched once, for the figures above."]


def _add_repeat_only(m: dict, run_dir: Path, test_ws) -> None:
    """``m["repeat_only"]``: accuracy on the repeat captures, from predictions.npz (pooled in fold order:
    each fold's held-out subject's captures in file order)."""
    f = run_dir / "predictions.npz"
    if test_ws is None or test_ws.repeat is None or not f.exists():
        return
    folds = [int(name.lstrip("s")) for name in m.get("folds", [])]
    repeat = np.concatenate([test_ws.repeat[test_ws.subject == s] for s in folds])
    with np.load(f) as z:
        y_true, y_pred = z["y_true"], z["y_pred"]
    if len(repeat) == len(y_true) and repeat.any():
        r = repeat == 1
        m["repeat_only"] = {"n": int(r.sum()), "accuracy": float(np.mean(y_true[r] == y_pred[r]))}


def _cached(run_dir: Path, reuse: bool) -> dict | None:
    f = run_dir / "metrics.json"
    return json.loads(f.read_text()) if reuse and f.exists() else None


def run_report(out: str, *, seed: int = 0, subjects: int = 20, epochs: int | None = None,
               archs=ARCH_ORDER, data: str | None = None, test: str | None = None, minutes: float = 15.0,
               jobs: int = 2, within: bool = True, progress: bool = True, command: str | None = None,
               reuse: bool = False, folds: int | None = None, selection: str | None = None,
               reuse_only: bool = False) -> dict:
    """LOSO (and within-subject) for every arch; with ``reuse``, every LOSO fold saved under
    ``out/<arch>/loso/folds/`` from the same data and recipe is read back and only the missing
    folds are trained (with ``reuse_only`` none: the report covers the saved folds, and says how
    many); a within-subject metrics.json is read back whole (delete a directory to retrain it)."""
    out_p = Path(out)
    out_p.mkdir(parents=True, exist_ok=True)
    t_start = time.time()
    data, test, detector = _cohort(out_p, data, test, seed=seed, subjects=subjects, minutes=minutes,
                                   progress=progress)
    train = load_npz(data)
    test_ws = load_npz(test) if test else None
    from models.selection import load_recipe, selection_captures

    recipe, calib = load_recipe(selection), selection_captures(selection)
    loso, wit, timing = _run_archs(archs, train, test_ws, out_p, epochs=epochs, seed=seed, jobs=jobs, within=within,
                                   progress=progress, reuse=reuse or reuse_only, t_start=t_start, recipe=recipe,
                                   calib=calib, folds=folds, reuse_only=reuse_only)
    command = command or "python -m models " + " ".join(shlex.quote(x) for x in sys.argv[1:])
    md = _markdown(loso, wit, detector, command=command, seed=seed, data=data, test=test, train=train,
                   test_ws=test_ws, wall_s=time.time() - t_start, out_dir=out_p)
    (out_p / "report.md").write_text("\n".join(md))
    summary = {"command": command, "seed": seed, "train": data, "test": test, "detector": detector,
               "timing_s": timing, "wall_s": round(time.time() - t_start, 1),
               "loso": {a: {k: m.get(k) for k in ("accuracy", "macro_f1", "macro_f1_distractions", "per_class",
                                                  "onset_only", "repeat_only", "steps", "ece", "folds", "recipe",
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
               progress: bool, reuse: bool, t_start: float, recipe: dict, calib, folds: int | None,
               reuse_only: bool = False) -> tuple[dict, dict, dict]:
    """(LOSO metrics, within-subject metrics, seconds) per arch, each run (or read back) in turn.
    Every arch trains with the selection's recipe (captures, time shift); the ConvLSTM also with its
    chosen epochs, and its per-step temperatures are fitted on the selection cohort (``calib``)."""
    loso, wit, timing = {}, {}, {}
    for a in archs:
        t0 = time.time()
        if a.startswith("lda"):
            ep = 0
        elif epochs is not None:
            ep = epochs
        else:
            ep = recipe["epochs"] if a == "convlstm" else DEFAULT_EPOCHS[a]
        # per fold: with reuse, the folds saved by earlier runs (same data and recipe) are read back
        # and only the missing ones trained (none with reuse_only), so a LOSO can span sessions
        loso[a] = run_loso(a, train, test_ws, out_p / a / "loso", epochs=ep, seed=seed, jobs=jobs,
                           progress=progress, recipe=recipe, calib=calib if a == "convlstm" else None,
                           folds=folds, final_model=False, resume=reuse, train_missing=not reuse_only)
        _add_repeat_only(loso[a], out_p / a / "loso", test_ws)
        if loso[a].get("steps"):
            save_steps_png(loso[a], out_p / a / "loso" / "steps.png")
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
              train, test_ws, wall_s: float, out_dir: Path) -> list[str]:
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
    conv = loso.get("convlstm")
    md += ["## What the box gets: every capture it classifies (leave-one-subject-out)", "",
           "Every detector capture of the held-out subject: onset captures, repeat captures (the hand returning "
           "during a long distraction) and false alarms (Other motions, driving), each labelled by the truth event "
           "its trigger falls in. No choice was made on these subjects (see 'What chose what').", "",
           *headline_table(loso)]
    if conv and conv.get("steps"):
        md += [f"### Early decisions: the ConvLSTM after S of its 6 sub-windows (LOSO folds: {_folds(conv)})", "",
               "One model (79,598 parameters, deep supervision over prefixes) decides on the first S sub-windows "
               "of the capture's preprocessing. Temperatures per step are fitted per fold on the selection cohort "
               "(NLL), never on the held-out subject; ECE over 15 confidence bins.", "", *steps_table(conv),
               "![ConvLSTM early decisions](convlstm/loso/steps.png)", ""]
    md += ["## Onset captures (one capture per detected event + false alarms)", "", *onset_table(loso),
           *same_folds_table(loso, out_dir, test_ws),
           "The summary-statistics LDA (mean, sd, min, max per axis: 12 numbers) measures how much posture alone "
           "gives away on this simulator; it should stay well below the ConvLSTM.", "",
           "## What chose what", "", *_selection_lines(loso), "",
           "## Comparison with the dissertation (Tables 2.1-2.3; its counts, not the product figure)", "",
           *summary_table(loso, wit),
           "Dissertation (between-participant F1, onset-style counts): ConvLSTM 0.87, LSTM 0.85, CNN 0.76, LDA 0.38.", "",
           *([] if wit else ["Within-subject (Table 2.1): not run in this report (`--no-within`).", ""]),
           "macro-F1 pools every fold's predictions and averages F1 over the classes (Other included); "
           "per-subject rows average over the classes present for that subject. 'Onset captures' leaves out "
           "the repeat captures (a second trigger inside a truth event that an earlier capture already "
           "caught, e.g. the return to the wheel after a long phone call): one capture per detected "
           "distraction plus the false alarms, the dissertation's count.", "",
           "### Between-participant (leave-one-subject-out), every capture", "",
           *subject_table(loso, "Table 2.2: per subject (recall, precision, F1)"),
           *class_table(loso, "Table 2.3: per class")]
    if wit:
        md += ["## Within-participant", "", f"Protocol: {next(iter(wit.values()))['protocol']}.", "",
               *subject_table(wit, "Table 2.1: per subject (recall, precision, F1)"),
               *class_table(wit, "Per class (within-participant)")]
    md += ["## Confusion matrices (LOSO, rows = truth)", ""]
    md += [f"![{NAMES[a]}]({a}/loso/confusion.png)" for a in loso] + [""]
    return md
