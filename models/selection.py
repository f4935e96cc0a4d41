"""Honest selection (issue 12, item 4): every training choice is made on a separate simulated cohort.

    python -m models select --out reports/wearable/selection --seed 0 [--subjects 12] [--minutes 10]
                            [--epochs 24] [--jobs 2]

The selection cohort is simulated with seed ``SELECTION_SEED_OFFSET + seed``: other people (body,
style, strategies) than the reported cohort's, which is simulated with ``seed``. Its first
``n_train`` subjects train candidate recipes; the others are the validation subjects, scored on
their detector captures (every capture: onsets, repeats and false alarms), never on the reported
cohort. What it chooses, written to OUT/selection.json and read by ``python -m models report`` and
``python -m export assets``:

* whether the training subjects' detector captures (labelled as the test set is: the truth event
  their trigger falls in, else Other) join the ground-truth windows in training;
* how far forward the time-shift augmentation reaches (``shift_fwd``, resampled frames);
* the number of epochs, with the cosine schedule of the ``epochs`` candidate run kept
  (``schedule_epochs``).

The criterion is the validation subjects' macro-F1 over every capture after all 6 sub-windows
(the full-window decision; the early steps are reported but do not choose), ties to fewer epochs.
Temperatures and preliminary-alert thresholds are fitted later, per shipped or per fold model,
on this cohort's captures too (:func:`calibrate_steps`).
"""
from __future__ import annotations

import json
import time
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

import numpy as np

from models.calibration import (
    ALERT_PRECISION_TARGET,
    alert_precision,
    expected_calibration_error,
    fit_temperature,
    min_confidence_for_precision,
    temper,
)
from models.dataset import WindowSet, build_cohort_datasets, load_npz
from models.evaluate import compute_metrics

SELECTION_SEED_OFFSET = 1000
N_STEPS = 6
EVAL_EVERY = 3
CANDIDATES = (
    {"captures": False, "shift_fwd": 50},  # the recipe before issue 12
    {"captures": True, "shift_fwd": 50},
    {"captures": True, "shift_fwd": 10},
    {"captures": False, "shift_fwd": 10},
)
DEFAULT_RECIPE = {"captures": True, "shift_fwd": 50, "epochs": 25, "schedule_epochs": 25,
                  "chosen_on": "not chosen: no selection.json (run python -m models select)"}
SELECTION_JSON = Path(__file__).resolve().parent.parent / "reports" / "wearable" / "selection" / "selection.json"


def training_arrays(gt: WindowSet, captures: WindowSet | None, subjects) -> tuple[np.ndarray, np.ndarray]:
    """(X (N, 700, 3), y) of ``subjects``: their ground-truth windows, plus their detector captures
    when ``captures`` is given."""
    m = np.isin(gt.subject, list(subjects))
    X, y = [gt.X[m]], [gt.y[m]]
    if captures is not None:
        c = np.isin(captures.subject, list(subjects))
        X.append(captures.X[c])
        y.append(captures.y[c])
    return np.concatenate(X), np.concatenate(y)


def step_metrics(step_probs: np.ndarray, y: np.ndarray, classes) -> list[dict]:
    """Per step (1..6): accuracy and macro-F1 of the decision after that many sub-windows."""
    rows = []
    for s, p in enumerate(step_probs, start=1):
        m = compute_metrics(y, p.argmax(1), classes)
        rows.append({"steps": s, "accuracy": m["accuracy"], "macro_f1": m["macro_f1"]})
    return rows


def _candidate(job: dict) -> dict:
    """Train one recipe on the selection cohort's training subjects; validate every EVAL_EVERY epochs."""
    import torch

    from models.evaluate import predict_steps
    from models.train import fit

    torch.set_num_threads(1)
    gt, cap = load_npz(job["train"]), load_npz(job["test"])
    X, y = training_arrays(gt, cap if job["recipe"]["captures"] else None, job["train_subjects"])
    val = cap.subset(np.isin(cap.subject, job["val_subjects"]))
    history = []

    def on_epoch(epoch: int, model) -> None:
        if (epoch + 1) % EVAL_EVERY == 0 or epoch + 1 == job["epochs"]:
            rows = step_metrics(predict_steps(model, val.X), val.y, gt.classes)
            history.append({"epochs": epoch + 1, "steps": rows})

    fit("convlstm", X, y, len(gt.classes), epochs=job["epochs"], seed=job["seed"], progress=False,
        shift_fwd=job["recipe"]["shift_fwd"], on_epoch=on_epoch)
    return {"recipe": job["recipe"], "n_train": int(len(y)), "history": history}


def run_selection(out: str | Path, *, seed: int = 0, subjects: int = 12, minutes: float = 10.0, epochs: int = 24,
                  n_train: int = 8, jobs: int = 2, log=print) -> dict:
    """Simulate (or reuse) the selection cohort under OUT/data, train every candidate, write
    OUT/selection.json and OUT/selection.md; returns the selection."""
    out = Path(out)
    t0 = time.time()
    data = out / "data"
    sel_seed = SELECTION_SEED_OFFSET + seed
    if not ((data / "train.npz").exists() and (data / "test.npz").exists()):
        log(f"simulating the selection cohort: {subjects} subjects, seed {sel_seed}, {minutes:g} min per trial")
        build_cohort_datasets(subjects, sel_seed, minutes, data, progress=False)
    ids = sorted(int(s) for s in np.unique(load_npz(data / "train.npz").subject))
    train_subjects, val_subjects = ids[:n_train], ids[n_train:]
    job_list = [{"recipe": r, "epochs": epochs, "seed": seed, "train": str(data / "train.npz"),
                 "test": str(data / "test.npz"), "train_subjects": train_subjects, "val_subjects": val_subjects}
                for r in CANDIDATES]
    if jobs > 1:
        with ProcessPoolExecutor(max_workers=jobs, mp_context=get_context("spawn")) as ex:
            results = list(ex.map(_candidate, job_list))
    else:
        results = [_candidate(j) for j in job_list]
    best = max(((r, h) for r in results for h in r["history"]),
               key=lambda rh: (round(rh[1]["steps"][-1]["macro_f1"], 3), -rh[1]["epochs"]))
    chosen_on = (f"selection cohort (python -m models select, seed {sel_seed}): trained on subjects "
                 f"{train_subjects[0]}-{train_subjects[-1]}, validated on the detector captures of subjects "
                 f"{val_subjects[0]}-{val_subjects[-1]}")
    recipe = {**best[0]["recipe"], "epochs": best[1]["epochs"], "schedule_epochs": epochs,
              "validation_macro_f1_every_capture": best[1]["steps"][-1]["macro_f1"], "chosen_on": chosen_on}
    sel = {"command": f"python -m models select --out {out} --seed {seed} --subjects {subjects} --minutes {minutes:g} "
                      f"--epochs {epochs}",
           "selection_seed": sel_seed, "subjects": subjects, "minutes_per_trial": minutes,
           "train_subjects": train_subjects, "validation_subjects": val_subjects,
           "criterion": "validation macro-F1 over every detector capture after 6 sub-windows; ties -> fewer epochs",
           "recipe": recipe, "candidates": results, "wall_s": round(time.time() - t0, 1)}
    out.mkdir(parents=True, exist_ok=True)
    (out / "selection.json").write_text(json.dumps(sel, indent=2))
    (out / "selection.md").write_text("\n".join(_markdown(sel)) + "\n")
    log(f"chose {recipe} in {time.time() - t0:.0f} s")
    return sel


def _markdown(sel: dict) -> list[str]:
    lines = ["# Training recipe chosen on the selection cohort", "", f"Command: `{sel['command']}`", "",
             f"Criterion: {sel['criterion']}. {sel['recipe']['chosen_on']}.", "",
             "| captures in training | shift forward (frames) | epochs | " +
             " | ".join(f"macro-F1 S={s}" for s in range(1, N_STEPS + 1)) + " |",
             "|---|---:|---:|" + "---:|" * N_STEPS]
    for c in sel["candidates"]:
        for h in c["history"]:
            lines.append(f"| {'yes' if c['recipe']['captures'] else 'no'} | {c['recipe']['shift_fwd']} | {h['epochs']} | "
                         + " | ".join(f"{r['macro_f1']:.3f}" for r in h["steps"]) + " |")
    r = sel["recipe"]
    lines += ["", f"**Chosen:** captures in training {'yes' if r['captures'] else 'no'}, shift forward "
                  f"{r['shift_fwd']} frames, {r['epochs']} epochs (cosine schedule over {r['schedule_epochs']})."]
    return lines


def load_recipe(path: str | Path | None = None) -> dict:
    """The chosen recipe (``DEFAULT_RECIPE`` when no selection was run)."""
    p = Path(path) if path else SELECTION_JSON
    if not p.exists():
        return dict(DEFAULT_RECIPE)
    return json.loads(p.read_text())["recipe"]


def selection_captures(path: str | Path | None = None) -> WindowSet | None:
    """Every detector capture of the selection cohort (none of its subjects is in the reported cohort):
    the data temperatures and thresholds are fitted on."""
    p = (Path(path) if path else SELECTION_JSON).parent / "data" / "test.npz"
    return load_npz(p) if p.exists() else None


def ensure_selection_captures(seed: int = 0, path: str | Path | None = None, log=print) -> tuple[WindowSet, str]:
    """(every detector capture of the selection cohort, what to call it): read from beside
    selection.json, or simulated again from the cohort parameters it records (same seed, same arrays)."""
    p = Path(path) if path else SELECTION_JSON
    sel = json.loads(p.read_text()) if p.exists() else {"selection_seed": SELECTION_SEED_OFFSET + seed,
                                                         "subjects": 12, "minutes_per_trial": 10.0}
    data = p.parent / "data"
    if not (data / "test.npz").exists():
        log(f"simulating the selection cohort again (seed {sel['selection_seed']}) -> {data}")
        build_cohort_datasets(sel["subjects"], sel["selection_seed"], sel["minutes_per_trial"], data, progress=False)
    what = (f"every detector capture of the selection cohort (python -m models select: seed {sel['selection_seed']}, "
            f"{sel['subjects']} simulated subjects none of whom is in training, {sel['minutes_per_trial']:g} min per trial)")
    return load_npz(data / "test.npz"), what


def calibrate_steps(val_step_probs: np.ndarray, y_val: np.ndarray, other: int) -> dict:
    """Per step: the NLL temperature and the preliminary-alert threshold fitted on validation
    probabilities (S, N, K), with the validation figures that justify them."""
    temps, thresholds, rows = {}, {}, []
    for s, p in enumerate(val_step_probs, start=1):
        t = fit_temperature(p, y_val)
        pc = temper(p, t)
        thr = min_confidence_for_precision(pc, y_val, other)
        prec, n = alert_precision(pc, y_val, other, thr)
        temps[str(s)], thresholds[str(s)] = round(t, 4), thr
        rows.append({"steps": s, "temperature": round(t, 4), "min_confidence": thr,
                     "ece_raw": expected_calibration_error(p, y_val), "ece": expected_calibration_error(pc, y_val),
                     "alert_precision": prec if n else None, "alerts": n,  # JSON has no NaN
                     "alert_recall": float(np.mean((pc.argmax(1) != other) & (pc.max(1) >= thr) & (y_val != other))
                                           / max(np.mean(y_val != other), 1e-12))})
    return {"steps": list(range(1, len(val_step_probs) + 1)), "temperature_by_steps": temps,
            "min_confidence_by_steps": thresholds, "alert_precision_target": ALERT_PRECISION_TARGET,
            "validation": rows}
