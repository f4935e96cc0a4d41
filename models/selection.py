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
Stage 2 (``--stage early``, :func:`run_early_selection`) then compares the ConvLSTM's step-loss
weights for early decisions by ``EARLY_RULE`` and keeps the current ones unless a new weighting
clearly wins (2026-11-25: kept).
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
BASELINE_STEP_WEIGHTS = (0.5, 0.5, 0.5, 0.5, 0.5, 1.0)
EARLY_CANDIDATES = (
    BASELINE_STEP_WEIGHTS,  # the current recipe (models.train.STEP_LOSS_WEIGHTS before stage 2)
    (1.0, 1.0, 1.0, 1.0, 1.0, 1.0),  # every step weighted as the full window
    (0.5, 1.0, 1.0, 0.5, 0.5, 1.0),  # S = 2 and 3 (the early alerts' steps) weighted as the full window
)
EARLY_STEPS = (2, 3)
EARLY_FULL_TOLERANCE = 0.01
EARLY_MARGIN = 0.02
EARLY_RULE = ("on the selection cohort's validation subjects (every detector capture), the early figure is "
              "the mean macro-F1 of the decisions after S = 2 and S = 3 sub-windows. The baseline is the current "
              "recipe at stage 1's epochs. A new weighting's checkpoint (any evaluated epoch count) is eligible "
              f"when its full-window (S = 6) macro-F1 is at least the baseline's - {EARLY_FULL_TOLERANCE}; the eligible "
              "one with the highest early figure (rounded to 0.001; ties -> fewer epochs) wins if its early figure "
              f"is at least the baseline's + {EARLY_MARGIN}, else the current recipe stays")
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
        shift_fwd=job["recipe"]["shift_fwd"], on_epoch=on_epoch,
        step_loss_weights=job["recipe"].get("step_loss_weights"))
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
    results = _train_candidates(job_list, jobs)
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


def _train_candidates(job_list: list[dict], jobs: int) -> list[dict]:
    if jobs > 1:
        with ProcessPoolExecutor(max_workers=jobs, mp_context=get_context("spawn")) as ex:
            return list(ex.map(_candidate, job_list))
    return [_candidate(j) for j in job_list]


def early_score(h: dict) -> float:
    """Stage 2's early figure of one validation checkpoint: mean macro-F1 at S = 2 and 3."""
    return float(np.mean([h["steps"][s - 1]["macro_f1"] for s in EARLY_STEPS]))


def choose_early(results: list[dict], baseline_epochs: int) -> tuple[dict, dict, dict]:
    """``EARLY_RULE`` applied to stage 2's candidates: (winning candidate, its checkpoint, the
    baseline's checkpoint). The first candidate is the current recipe (``BASELINE_STEP_WEIGHTS``)."""
    base = results[0]
    base_h = next(h for h in base["history"] if h["epochs"] == baseline_epochs)
    full0, early0 = base_h["steps"][-1]["macro_f1"], early_score(base_h)
    eligible = [(r, h) for r in results[1:] for h in r["history"]
                if h["steps"][-1]["macro_f1"] >= full0 - EARLY_FULL_TOLERANCE]
    if eligible:
        r, h = max(eligible, key=lambda rh: (round(early_score(rh[1]), 3), -rh[1]["epochs"]))
        if early_score(h) >= early0 + EARLY_MARGIN:
            return r, h, base_h
    return base, base_h, base_h


def run_early_selection(out: str | Path, *, jobs: int = 1, log=print) -> dict:
    """Stage 2 (issue 12, early decisions): with stage 1's captures, time shift, seed and schedule,
    train the ConvLSTM under each of ``EARLY_CANDIDATES``' step-loss weights and keep a new one only
    by ``EARLY_RULE``. Rewrites OUT/selection.json (its recipe gains ``step_loss_weights`` only when
    a new weighting wins) and OUT/selection.md."""
    out = Path(out)
    t0 = time.time()
    sel = json.loads((out / "selection.json").read_text())
    stage1 = {k: v for k, v in sel["recipe"].items() if k != "step_loss_weights"}
    data = out / "data"
    if not ((data / "train.npz").exists() and (data / "test.npz").exists()):
        log(f"simulating the selection cohort again (seed {sel['selection_seed']}) -> {data}")
        build_cohort_datasets(sel["subjects"], sel["selection_seed"], sel["minutes_per_trial"], data, progress=False)
    seed = sel["selection_seed"] - SELECTION_SEED_OFFSET
    job_list = [{"recipe": {"captures": stage1["captures"], "shift_fwd": stage1["shift_fwd"], "step_loss_weights": list(w)},
                 "epochs": stage1["schedule_epochs"], "seed": seed, "train": str(data / "train.npz"),
                 "test": str(data / "test.npz"), "train_subjects": sel["train_subjects"],
                 "val_subjects": sel["validation_subjects"]} for w in EARLY_CANDIDATES]
    results = _train_candidates(job_list, jobs)
    win, win_h, base_h = choose_early(results, stage1["epochs"])
    new = win is not results[0]
    recipe = dict(stage1)
    if new:
        recipe.update(epochs=win_h["epochs"], step_loss_weights=win["recipe"]["step_loss_weights"],
                      validation_macro_f1_every_capture=win_h["steps"][-1]["macro_f1"],
                      validation_early_macro_f1_s2_s3=early_score(win_h))
    sel["recipe"] = recipe
    sel["early_stage"] = {"command": f"python -m models select --out {out} --stage early --jobs {jobs}",
                          "rule": EARLY_RULE, "candidates": results, "new_recipe_won": new,
                          "baseline": {"epochs": base_h["epochs"], "steps": base_h["steps"]},
                          "chosen": {"step_loss_weights": win["recipe"]["step_loss_weights"],
                                     "epochs": win_h["epochs"], "steps": win_h["steps"]},
                          "wall_s": round(time.time() - t0, 1)}
    (out / "selection.json").write_text(json.dumps(sel, indent=2))
    (out / "selection.md").write_text("\n".join(_markdown(sel)) + "\n")
    log(f"stage 2: {'new' if new else 'kept'} step-loss weights {win['recipe']['step_loss_weights']}, "
        f"{win_h['epochs']} epochs, in {time.time() - t0:.0f} s")
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
    r = {k: v for k, v in sel["recipe"].items() if k != "step_loss_weights"}
    if "early_stage" in sel:  # stage 1's own pick (stage 2 may have changed the epochs)
        r.update(epochs=sel["early_stage"]["baseline"]["epochs"])
    lines += ["", f"**Chosen:** captures in training {'yes' if r['captures'] else 'no'}, shift forward "
                  f"{r['shift_fwd']} frames, {r['epochs']} epochs (cosine schedule over {r['schedule_epochs']})."]
    return lines + (_early_markdown(sel) if "early_stage" in sel else [])


def _early_markdown(sel: dict) -> list[str]:
    e = sel["early_stage"]
    lines = ["", "## Stage 2: the step-loss weights, for early decisions (issue 12)", "",
             f"Command: `{e['command']}` ({e['wall_s']:.0f} s). Same cohort, subjects, seed, captures, time shift "
             "and schedule as above; only the ConvLSTM's loss weight of the decision after 1..6 sub-windows differs.",
             "", f"**Rule** (stated before the run): {e['rule']}", "",
             "| step-loss weights (S = 1..6) | epochs | " + " | ".join(f"macro-F1 S={s}" for s in range(1, N_STEPS + 1))
             + " | accuracy S=2 | accuracy S=3 | early (mean macro-F1 S=2,3) |",
             "|---|---:|" + "---:|" * (N_STEPS + 3)]
    for c in e["candidates"]:
        w = ", ".join(f"{x:g}" for x in c["recipe"]["step_loss_weights"])
        for h in c["history"]:
            lines.append(f"| ({w}) | {h['epochs']} | " + " | ".join(f"{r['macro_f1']:.3f}" for r in h["steps"])
                         + f" | {h['steps'][1]['accuracy']:.3f} | {h['steps'][2]['accuracy']:.3f} | {early_score(h):.3f} |")
    ch, b = e["chosen"], e["baseline"]
    lines += ["", f"Baseline (the current recipe, {b['epochs']} epochs): early {early_score(b):.3f}, "
                  f"full window {b['steps'][-1]['macro_f1']:.3f}.",
              "", f"**Chosen:** step-loss weights ({', '.join(f'{x:g}' for x in ch['step_loss_weights'])}), "
                  f"{ch['epochs']} epochs: early {early_score(ch):.3f}, full window {ch['steps'][-1]['macro_f1']:.3f} "
                  f"({'a new recipe' if e['new_recipe_won'] else 'the current recipe kept'})."]
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
