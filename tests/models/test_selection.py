"""models/selection.py: the recipe is chosen on the selection cohort's validation subjects only."""
from __future__ import annotations

import json

import numpy as np

from models.dataset import save_npz
from models.selection import CANDIDATES, DEFAULT_RECIPE, load_recipe, run_selection, training_arrays
from models.toy import toy_windows


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
