"""models/selection.py: the recipe is chosen on the selection cohort's validation subjects only."""
from __future__ import annotations

import json

import numpy as np

from models.dataset import save_npz
from models.selection import (
    BASELINE_STEP_WEIGHTS,
    CANDIDATES,
    DEFAULT_RECIPE,
    EARLY_CANDIDATES,
    LOSS_CANDIDATES,
    LOSS_FOLDS,
    choose_early,
    choose_loss,
    load_recipe,
    run_early_selection,
    run_loss_selection,
    run_selection,
    training_arrays,
)
from models.toy import toy_windows
from models.train import recipe_fit_kwargs


def test_training_arrays_add_the_subjects_captures_only():
    gt = toy_windows(n_per_class=4, n_classes=3, n_subjects=3, seed=0)
    cap = toy_windows(n_per_class=2, n_classes=3, n_subjects=3, seed=1)
    X, y = training_arrays(gt, None, [0, 1])
    assert len(y) == np.isin(gt.subject, [0, 1]).sum()
    X2, y2 = training_arrays(gt, cap, [0, 1])
    assert len(y2) == len(y) + np.isin(cap.subject, [0, 1]).sum() and X2.shape[1:] == (700, 3)


def test_selection_scores_only_validation_subjects_and_writes_the_recipe(tmp_path):
    d = tmp_path / "data"
    save_npz(d / "train.npz", toy_windows(n_per_class=6, n_classes=3, n_subjects=3, seed=0))
    # the validation subject's captures are shuffled labels: any recipe scores near chance there,
    # while the training subjects' captures are clean; the chosen figure must be the validation one
    cap = toy_windows(n_per_class=4, n_classes=3, n_subjects=3, seed=1)
    v = cap.subject == 2
    cap.y[v] = np.random.default_rng(0).permutation(cap.y[v])
    save_npz(d / "test.npz", cap)
    sel = run_selection(tmp_path, subjects=3, epochs=3, n_train=2, jobs=1, log=lambda s: None)
    assert sel["train_subjects"] == [0, 1] and sel["validation_subjects"] == [2]
    assert len(sel["candidates"]) == len(CANDIDATES)
    r = sel["recipe"]
    best = max(h["steps"][-1]["macro_f1"] for c in sel["candidates"] for h in c["history"])
    assert r["validation_macro_f1_every_capture"] == best and "validated on" in r["chosen_on"]
    assert load_recipe(tmp_path / "selection.json") == r
    assert json.loads((tmp_path / "selection.json").read_text())["criterion"].startswith("validation macro-F1")
    assert "**Chosen:**" in (tmp_path / "selection.md").read_text()


def test_no_selection_means_the_documented_default(tmp_path):
    assert load_recipe(tmp_path / "missing.json") == DEFAULT_RECIPE


def _checkpoint(epochs: int, s2: float, s3: float, s6: float) -> dict:
    return {"epochs": epochs, "steps": [{"steps": s, "macro_f1": f, "accuracy": f}
                                        for s, f in enumerate((0.4, s2, s3, 0.7, 0.7, s6), start=1)]}


def test_the_early_rule_keeps_the_current_recipe_unless_a_new_one_clearly_wins():
    base = {"recipe": {"step_loss_weights": list(BASELINE_STEP_WEIGHTS)}, "history": [_checkpoint(12, 0.65, 0.75, 0.80)]}
    new = {"recipe": {"step_loss_weights": [1.0] * 6},
           "history": [_checkpoint(12, 0.72, 0.80, 0.78),   # early much better, full window worse: not eligible
                       _checkpoint(15, 0.67, 0.76, 0.80),   # +0.015 early: below the margin
                       _checkpoint(18, 0.70, 0.78, 0.795)]}  # +0.04 early, full window within 0.01: wins
    win, h, b = choose_early([base, new], 12)
    assert win is new and h["epochs"] == 18 and b["epochs"] == 12
    new["history"] = new["history"][:2]
    win, h, _ = choose_early([base, new], 12)
    assert win is base and h["epochs"] == 12


def _toy_stage1(tmp_path) -> None:
    """Stage 1 on a toy cohort of 3 subjects (2 train, 1 validates), for the later stages to build on."""
    d = tmp_path / "data"
    save_npz(d / "train.npz", toy_windows(n_per_class=6, n_classes=3, n_subjects=3, seed=0))
    save_npz(d / "test.npz", toy_windows(n_per_class=4, n_classes=3, n_subjects=3, seed=1))
    run_selection(tmp_path, subjects=3, epochs=3, n_train=2, jobs=1, log=lambda s: None)


def test_the_early_stage_writes_the_step_weights_only_when_they_win(tmp_path):
    _toy_stage1(tmp_path)
    stage1 = load_recipe(tmp_path / "selection.json")
    sel = run_early_selection(tmp_path, jobs=1, log=lambda s: None)
    e = sel["early_stage"]
    assert [c["recipe"]["step_loss_weights"] for c in e["candidates"]] == [list(w) for w in EARLY_CANDIDATES]
    r = load_recipe(tmp_path / "selection.json")
    if e["new_recipe_won"]:
        assert r["step_loss_weights"] == e["chosen"]["step_loss_weights"] != list(BASELINE_STEP_WEIGHTS)
    else:
        assert r == stage1
    assert "Stage 2" in (tmp_path / "selection.md").read_text()


def _cv(epochs_full_early: list[tuple[int, float, float]]) -> list[dict]:
    return [{"epochs": e, "full": f, "early": early} for e, f, early in epochs_full_early]


def test_the_loss_rule_needs_a_clear_full_window_gain_without_losing_the_early_steps():
    base = {"cv": _cv([(12, 0.80, 0.70), (15, 0.805, 0.70)])}  # the current recipe at its best: 15 epochs
    early_worse = {"cv": _cv([(12, 0.85, 0.68)])}                  # +0.045 full, early -0.02: not eligible
    small = {"cv": _cv([(12, 0.812, 0.71)])}                       # +0.007: below the margin
    clear = {"cv": _cv([(9, 0.80, 0.72), (12, 0.82, 0.695)])}     # +0.015 at 12 epochs, early -0.005: wins
    i, h, b = choose_loss([base, early_worse, small, clear])
    assert (i, h["epochs"], b["epochs"]) == (3, 12, 15)
    i, h, _ = choose_loss([base, early_worse, small])
    assert i == 0 and h["epochs"] == 15


def test_the_loss_stage_validates_every_subject_once_and_records_the_folds(tmp_path):
    _toy_stage1(tmp_path)
    before = load_recipe(tmp_path / "selection.json")
    sel = run_loss_selection(tmp_path, jobs=1, log=lambda s: None)
    e = sel["loss_stage"]
    assert sorted(x for f in e["folds"] for x in f) == [0, 1, 2] and len(e["folds"]) == LOSS_FOLDS
    assert [c["change"] for c in e["candidates"]] == [dict(c) for c in LOSS_CANDIDATES]
    r = load_recipe(tmp_path / "selection.json")
    if e["new_recipe_won"]:
        assert all(r[k] == v for k, v in e["chosen"]["change"].items())
    else:
        assert r == before
    assert "Stage 3" in (tmp_path / "selection.md").read_text()


def test_a_recipe_sets_only_fit_arguments_it_names():
    assert recipe_fit_kwargs({"captures": True, "shift_fwd": 10, "label_smoothing": 0.1, "epochs": 12}) == {
        "shift_fwd": 10, "label_smoothing": 0.1}
