"""models/: parameter counts, learning, determinism, metrics, datasets, LOSO folds."""
from __future__ import annotations

import numpy as np
import pytest
import torch

from edge_runtime.wearable.labels import CLASSES
from models.dataset import DataError, WindowSet, load_npz, save_npz, windows_from_recording
from models.evaluate import compute_metrics, predict, save_confusion_png
from models.experiments import run_loso, run_within
from models.lda import LDAClassifier, window_features
from models.nets import build, keras_param_count, torch_param_count
from models.toy import toy_stream, toy_windows
from models.train import fit, load_checkpoint, save_checkpoint

# --------------------------------------------------------------------------- networks

def test_convlstm_parameter_counts():
    m = build("convlstm", 6)
    assert keras_param_count(m) == 79_598  # the dissertation's figure
    assert torch_param_count(m) == 79_998  # nn.LSTM's two bias vectors


@pytest.mark.parametrize("arch", ["convlstm", "cnn", "lstm"])
def test_forward_shapes_any_class_count(arch):
    for k in (2, 6, 9):
        out = build(arch, k)(torch.zeros(4, 6, 33, 3))
        assert out.shape == (4, k)


def test_convlstm_step_decisions_are_the_prefix_decisions():
    """Step s of all_steps is the decision on the first s sub-windows (the runtime's early path)."""
    torch.manual_seed(0)
    m = build("convlstm", 6).eval()
    x = torch.randn(5, 6, 33, 3) * 3.0
    with torch.no_grad():
        steps = m(x, all_steps=True)
        assert steps.shape == (5, 6, 6)
        for s in range(1, 7):
            torch.testing.assert_close(steps[:, s - 1], m(x[:, :s]), rtol=1e-5, atol=1e-5)
        torch.testing.assert_close(steps[:, -1], m(x))


def test_convlstm_peeks_are_the_truncated_sub_window_decisions():
    """A peek after k frames of sub-window s is one LSTM step from the state after the s - 1 complete
    sub-windows on the conv features of those k frames alone; k = 33 is the committed decision."""
    torch.manual_seed(0)
    m = build("convlstm", 6).eval()
    x = torch.randn(4, 6, 33, 3) * 3.0
    with torch.no_grad():
        peeks = m.peeks(x, (5, 11, 33))
        assert peeks.shape == (4, 6, 3, 6)
        torch.testing.assert_close(peeks[:, :, 2], m(x, all_steps=True))
        for s in (1, 4):
            for j, k in enumerate((5, 11)):
                f = m.features(x[:, :s, :k]).amax(dim=3)  # sub-windows 1..s, each truncated to k frames ...
                full = m.features(x[:, :s - 1]).amax(dim=3)  # ... of which only the last stays truncated
                _, (h, _) = m.lstm(torch.cat([full, f[:, -1:]], dim=1))
                torch.testing.assert_close(peeks[:, s - 1, j], m.head(h[-1]), rtol=1e-5, atol=1e-5)
        with pytest.raises(ValueError, match="5..33"):
            m.peeks(x, (4,))


# --------------------------------------------------------------------------- training

@pytest.fixture(scope="module")
def toy():
    return toy_windows(n_per_class=24, n_classes=4, n_subjects=3, seed=1)


def test_convlstm_learns_separable_toy(toy):
    test = toy_windows(n_per_class=10, n_classes=4, n_subjects=1, seed=2)
    model = fit("convlstm", toy.X, toy.y, 4, epochs=30, seed=0, progress=False, batch_size=32, lr=3e-3)
    acc = np.mean(predict(model, test.X).argmax(1) == test.y)
    assert acc >= 0.8, acc  # chance is 0.25


def test_lda_learns_separable_toy(toy):
    test = toy_windows(n_per_class=10, n_classes=4, n_subjects=1, seed=2)
    lda = fit("lda", toy.X, toy.y, 4, epochs=0, seed=0)
    assert np.mean(lda.predict(test.X) == test.y) >= 0.9
    assert window_features(test.X[:3]).shape == (3, 594)  # the networks' input, flattened
    assert window_features(test.X[:3], "summary").shape == (3, 12)
    summary = LDAClassifier(4, features="summary").fit(toy.X, toy.y)
    assert np.mean(summary.predict(test.X) == test.y) >= 0.5
    assert predict(lda, test.X).shape == (len(test.y), 4)


def test_deep_supervision_teaches_early_steps(toy):
    """Trained with a loss on every step, the decision after 3 of 6 sub-windows already separates the
    toy classes (their waveforms start in the first second)."""
    from models.evaluate import predict_steps

    test = toy_windows(n_per_class=10, n_classes=4, n_subjects=1, seed=2)
    model = fit("convlstm", toy.X, toy.y, 4, epochs=30, seed=0, progress=False, batch_size=32, lr=3e-3)
    steps = predict_steps(model, test.X)
    assert steps.shape == (6, len(test.y), 4)
    np.testing.assert_allclose(steps[-1], predict(model, test.X), atol=1e-6)
    assert np.mean(steps[2].argmax(1) == test.y) >= 0.8


def test_peek_supervision_changes_training_only_when_asked(toy):
    """fit's peek_frames adds the partial sub-windows' losses; without it the recipe's weights are today's."""
    kw = dict(epochs=2, seed=0, progress=False, batch_size=32)
    plain = fit("convlstm", toy.X, toy.y, 4, **kw)
    again = fit("convlstm", toy.X, toy.y, 4, peek_frames=(), **kw)
    peeked = fit("convlstm", toy.X, toy.y, 4, peek_frames=(11, 22), **kw)
    for a, b in zip(plain.parameters(), again.parameters()):
        assert torch.equal(a, b)
    assert any(not torch.equal(a, c) for a, c in zip(plain.parameters(), peeked.parameters()))


def test_loso_with_captures_recipe_and_calibration(tmp_path, toy):
    """A recipe that adds the training subjects' captures, and per-step temperatures fitted on a
    separate calibration set: the per-step rows and the per-fold calibration are reported."""
    calib = toy_windows(n_per_class=8, n_classes=4, n_subjects=2, seed=5, classes=["A", "B", "C", "Other"])
    data = WindowSet(toy.X, toy.y, toy.subject, ["A", "B", "C", "Other"])
    m = run_loso("convlstm", data, data, tmp_path, epochs=2, seed=0, progress=False, final_model=False,
                 recipe={"captures": True, "shift_fwd": 10, "schedule_epochs": 4}, calib=calib, folds=2)
    assert m["folds"] == ["s0", "s1"] and m["all_folds"] is False and m["recipe"]["captures"] is True
    assert [r["steps"] for r in m["steps"]] == [1, 2, 3, 4, 5, 6]
    assert all(0.0 <= r["ece"] <= 1.0 for r in m["steps"])
    cal = m["calibration_per_fold"]["s0"]
    assert set(cal["temperature_by_steps"]) == {"1", "2", "3", "4", "5", "6"}
    z = np.load(tmp_path / "predictions.npz")
    assert z["step_probs"].shape == (6, m["n"], 4)


def test_lda_unseen_class_gets_zero_probability(toy):
    m = toy.y < 3
    lda = LDAClassifier(4).fit(toy.X[m], toy.y[m])
    p = lda.predict_proba(toy.X)
    assert p.shape == (len(toy.y), 4) and np.all(p[:, 3] == 0)


def _weights(model):
    return {k: v.clone() for k, v in model.state_dict().items()}


@pytest.mark.parametrize("arch", ["convlstm", "lstm"])
def test_training_is_deterministic(toy, arch):
    sub = toy.subset(np.arange(0, len(toy), 3))
    a = _weights(fit(arch, sub.X, sub.y, 4, epochs=2, seed=7, progress=False, batch_size=16))
    b = _weights(fit(arch, sub.X, sub.y, 4, epochs=2, seed=7, progress=False, batch_size=16))
    c = _weights(fit(arch, sub.X, sub.y, 4, epochs=2, seed=8, progress=False, batch_size=16))
    assert all(torch.equal(a[k], b[k]) for k in a)
    assert not all(torch.equal(a[k], c[k]) for k in a)


def test_checkpoint_roundtrip(tmp_path, toy):
    model = fit("cnn", toy.X[:16], toy.y[:16], 4, epochs=1, seed=0, progress=False)
    path = save_checkpoint(tmp_path, model, arch="cnn", classes=toy.classes, seed=0, epochs=1,
                           metrics={"macro_f1": 0.5}, data={"train": "toy"})
    assert path.name == "model.pt"
    ck = torch.load(path, weights_only=False)
    assert set(ck) == {"arch", "state_dict", "classes", "n_classes", "seed", "epochs", "metrics", "data"}
    m2, meta = load_checkpoint(tmp_path)
    assert not m2.training and meta["classes"] == toy.classes and meta["n_classes"] == 4
    np.testing.assert_allclose(predict(model, toy.X[:5]), predict(m2, toy.X[:5]), atol=1e-6)
    lda = fit("lda", toy.X, toy.y, 4, epochs=0, seed=0)
    p = save_checkpoint(tmp_path / "lda", lda, arch="lda", classes=toy.classes, seed=0, epochs=0, metrics={},
                        data={})
    assert p.name == "model.pkl"
    l2, meta = load_checkpoint(p)
    assert meta["arch"] == "lda" and np.allclose(predict(l2, toy.X[:5]), predict(lda, toy.X[:5]))


# --------------------------------------------------------------------------- metrics

def test_metrics_on_hand_made_confusion(tmp_path):
    # truth A A A A B B C C ; pred A A A B B C C C
    y_true = [0, 0, 0, 0, 1, 1, 2, 2]
    y_pred = [0, 0, 0, 1, 1, 2, 2, 2]
    m = compute_metrics(y_true, y_pred, ["A", "B", "C"], subject=[1, 1, 1, 1, 2, 2, 2, 2])
    assert m["confusion"] == [[3, 1, 0], [0, 1, 1], [0, 0, 2]]
    assert m["accuracy"] == pytest.approx(6 / 8)
    pc = m["per_class"]
    assert pc["A"] == pytest.approx({"precision": 1.0, "recall": 0.75, "f1": 6 / 7, "support": 4})
    assert pc["B"] == pytest.approx({"precision": 0.5, "recall": 0.5, "f1": 0.5, "support": 2})
    assert pc["C"] == pytest.approx({"precision": 2 / 3, "recall": 1.0, "f1": 0.8, "support": 2})
    assert m["macro_f1"] == pytest.approx((6 / 7 + 0.5 + 0.8) / 3)
    # subject 1: truth A A A A, pred A A A B -> labels {A, B}: A f1 6/7, B f1 0
    assert m["per_subject"]["1"]["f1"] == pytest.approx((6 / 7 + 0) / 2)
    assert m["per_subject"]["2"]["accuracy"] == pytest.approx(3 / 4)
    png = save_confusion_png(m["confusion"], ["A", "B", "C"], tmp_path / "cm.png", title="t")
    assert png.stat().st_size > 1000


def test_macro_f1_distractions_excludes_other():
    m = compute_metrics([0, 1, 5, 5], [0, 1, 0, 5], list(CLASSES))
    assert m["macro_f1_distractions"] == pytest.approx((2 / 3 + 1.0) / 2)


# --------------------------------------------------------------------------- datasets

def test_npz_roundtrip_and_validation(tmp_path, toy):
    p = save_npz(tmp_path / "d.npz", toy)
    back = load_npz(p)
    assert back.X.dtype == np.float32 and back.classes == toy.classes
    np.testing.assert_array_equal(back.y, toy.y)
    np.testing.assert_array_equal(back.trial, toy.trial)

    def bad(name, **kw):
        d = dict(X=toy.X, y=toy.y, subject=toy.subject, classes=np.array(toy.classes))
        d.update(kw)
        for k in [k for k, v in d.items() if v is None]:
            del d[k]
        path = tmp_path / f"{name}.npz"
        np.savez(path, **d)
        with pytest.raises(DataError) as e:
            load_npz(path)
        msg = str(e.value)
        assert "\n" not in msg and str(path) in msg
        return msg

    assert "'X'" in bad("shape", X=toy.X[:, :600])
    X = toy.X.copy()
    X[3, 10, 1] = np.nan
    assert "'X'" in bad("nan", X=X) and "window 3" in bad("nan2", X=X)
    assert "'y'" in bad("label", y=np.where(toy.y == 0, 9, toy.y))
    assert "'y'" in bad("ylen", y=toy.y[:-1])
    assert "'subject'" in bad("nosubj", subject=None)
    assert "'classes'" in bad("cls", classes=np.array(["A", "A", "B", "C"]))
    with pytest.raises(DataError, match="not found"):
        load_npz(tmp_path / "missing.npz")
    (tmp_path / "junk.npz").write_text("not a zip")
    with pytest.raises(DataError, match="junk.npz"):
        load_npz(tmp_path / "junk.npz")


def test_windows_from_recording_train_and_test():
    rec = toy_stream([(10, 14, "Phone"), (40, 44, "Drink"), (70, 72, "Other")], seconds=120, false_alarms=[95])
    train, test, stats = windows_from_recording(rec)
    # TRAIN: one window per truth event, from 1 s before its start
    assert list(train.y) == [CLASSES.index("Phone"), CLASSES.index("Drink"), CLASSES.index("Other")]
    np.testing.assert_allclose(train.t_s, [9.0, 39.0, 69.0])
    np.testing.assert_array_equal(train.X[0], rec.acc_mps2[900:1600])
    # TEST: detector captures; onsets at start + 0.3 s; the false alarm at 95 s is Other
    labels = [test.classes[k] for k in test.y]
    assert labels[:2] == ["Phone", "Drink"]
    assert labels[-1] == "Other" and test.t_s[-1] == pytest.approx(94.0, abs=0.05)
    assert stats.distractions == 2 and stats.detected == 2 and stats.recall == 1.0
    assert stats.captures == len(test) and stats.precision == pytest.approx(2 / len(test))
    assert test.X.shape[1:] == (700, 3) and np.all(test.subject == 0)


def test_windows_from_recording_unknown_label():
    rec = toy_stream([(10, 14, "Juggling")], seconds=60)
    with pytest.raises(DataError, match="Juggling"):
        windows_from_recording(rec)


# --------------------------------------------------------------------------- protocols

def test_loso_one_fold_per_subject(tmp_path, toy):
    m = run_loso("cnn", toy, None, tmp_path, epochs=1, seed=0, progress=False)
    assert m["folds"] == ["s0", "s1", "s2"]
    assert set(m["per_subject"]) == {"0", "1", "2"} and m["n"] == len(toy)
    for s in range(3):
        assert (tmp_path / "folds" / f"s{s}" / "model.pt").exists()
    assert (tmp_path / "model.pt").exists() and (tmp_path / "metrics.json").exists()
    assert (tmp_path / "confusion.png").exists()


def test_loso_scores_test_captures_of_held_out_subject(tmp_path, toy):
    test = toy_windows(n_per_class=3, n_classes=4, n_subjects=3, seed=5)
    m = run_loso("lda", toy, test, tmp_path, seed=0, progress=False, final_model=False)
    assert m["n"] == len(test) and m["evaluated_on"] == "test captures"
    assert m["macro_f1"] > 0.8


def test_within_subject_by_trial(tmp_path, toy):
    m = run_within("lda", toy, None, tmp_path, seed=0, progress=False)
    assert m["protocol"].endswith("leave-one-trial-out") and m["folds"] == 6  # 3 subjects x 2 trials
    toy2 = WindowSet(toy.X, toy.y, toy.subject, toy.classes)
    m2 = run_within("lda", toy2, None, tmp_path / "k", seed=0, progress=False)
    assert m2["protocol"].endswith("5-fold") and m2["n"] == len(toy)


def test_cohort_datasets_from_simulator(tmp_path):
    pytest.importorskip("firmware_sim.devices.wrist")
    from models.dataset import build_cohort_datasets

    r = build_cohort_datasets(n_subjects=2, seed=0, minutes_per_trial=1.5, out_dir=tmp_path, progress=False)
    train, test = load_npz(r["train"]), load_npz(r["test"])
    assert train.classes == list(CLASSES) and len(set(train.subject.tolist())) == 2
    assert len(test) == r["detector"]["captures"] and test.repeat is not None
    det = r["detector"]
    assert 0 <= det["recall"] <= 1 and 0 <= det["precision"] <= 1
    assert (tmp_path / "detector.json").exists()


def test_loso_resumes_from_saved_folds(tmp_path, toy, monkeypatch):
    """Each fold's result is saved as it completes; a re-run with ``resume`` reads back the folds made
    from the same data and recipe, trains only the missing ones, and pools the same predictions as a
    run that trained them all. Other epochs (or other data) are not reused."""
    import models.experiments as ex

    test = toy_windows(n_per_class=3, n_classes=4, n_subjects=3, seed=5)
    full = run_loso("cnn", toy, test, tmp_path / "full", epochs=1, seed=0, progress=False, final_model=False)

    out = tmp_path / "run"
    first = run_loso("cnn", toy, test, out, epochs=1, seed=0, progress=False, final_model=False, folds=2)
    assert first["folds"] == ["s0", "s1"] and first["folds_reused"] == []
    assert first["all_folds"] is False and first["subjects_total"] == 3
    assert (out / "folds" / "s1" / "result.json").exists()

    trained = []
    real_fit = ex.fit
    monkeypatch.setattr(ex, "fit", lambda *a, **k: trained.append(1) or real_fit(*a, **k))
    done = run_loso("cnn", toy, test, out, epochs=1, seed=0, progress=False, final_model=False, resume=True)
    assert len(trained) == 1 and done["folds_reused"] == ["s0", "s1"] and done["all_folds"] is True
    with np.load(tmp_path / "full" / "predictions.npz") as a, np.load(out / "predictions.npz") as b:
        for k in ("y_true", "y_pred", "probs", "subject"):
            np.testing.assert_array_equal(a[k], b[k])
    assert done["macro_f1"] == full["macro_f1"]

    trained.clear()
    run_loso("cnn", toy, test, out, epochs=2, seed=0, progress=False, final_model=False, resume=True, folds=1)
    assert len(trained) == 1  # the saved fold was made with 1 epoch: trained again
    trained.clear()
    other = toy_windows(n_per_class=3, n_classes=4, n_subjects=3, seed=6)
    run_loso("cnn", toy, other, tmp_path / "full", epochs=1, seed=0, progress=False, final_model=False,
             resume=True, folds=1)
    assert len(trained) == 1  # other test captures: not the saved fold's data


def test_loso_reuse_only_pools_the_saved_folds_and_says_how_many(tmp_path, toy):
    """``train_missing=False`` trains nothing: the figures pool the saved folds, the metrics name them,
    and a killed fold (result.json not written) counts as missing."""
    run_loso("lda", toy, None, tmp_path, seed=0, progress=False, final_model=False, folds=2)
    (tmp_path / "folds" / "s1" / "result.json").unlink()  # as if killed while writing s1
    m = run_loso("lda", toy, None, tmp_path, seed=0, progress=False, final_model=False, resume=True,
                 train_missing=False)
    assert m["folds"] == ["s0"] and m["subjects_total"] == 3 and m["all_folds"] is False
    assert m["n"] == int(np.sum(toy.subject == 0))
    from models.report import _folds
    assert _folds(m) == "1 of 3"
    with pytest.raises(DataError, match="no saved lda fold"):
        run_loso("lda", toy, None, tmp_path / "empty", seed=0, progress=False, final_model=False, resume=True,
                 train_missing=False)


def test_preprocessed_inputs_predict_like_raw_windows(toy):
    """A LOSO preprocesses each set once and predicts from the cached inputs: the same probabilities,
    bit for bit, as predicting from the raw windows; a row's preprocessing does not depend on its batch."""
    from models.evaluate import predict_steps
    from models.train import preprocess_all

    model = fit("convlstm", toy.X, toy.y, 4, epochs=1, seed=0, progress=False)
    pre = preprocess_all(toy.X).numpy()
    np.testing.assert_array_equal(predict(model, pre), predict(model, toy.X))
    np.testing.assert_array_equal(predict_steps(model, pre), predict_steps(model, toy.X))
    np.testing.assert_array_equal(pre[5:9], preprocess_all(toy.X[5:9]).numpy())


def test_report_compares_partial_runs_on_their_common_subjects(tmp_path):
    """An architecture run on fewer folds is compared with every other on its own subjects: one table
    per partial fold set, holding only the architectures that ran those folds."""
    from models.report import same_folds_table

    classes = ["A", "Other"]
    subject = np.repeat([1, 2, 3], 4)
    test = WindowSet(np.zeros((12, 700, 3), np.float32), np.tile([0, 1, 0, 1], 3), subject, classes,
                     repeat=np.tile([0, 0, 1, 0], 3).astype(np.int8))
    loso = {}
    for arch, folds, wrong in (("convlstm", [1, 2, 3], 0), ("cnn", [1, 2], 1), ("lstm", [1], 2)):
        keep = np.isin(subject, folds)
        y_pred = test.y[keep].copy()
        y_pred[:wrong] = 1 - y_pred[:wrong]  # the first `wrong` captures of subject 1 misclassified
        d = tmp_path / arch / "loso"
        d.mkdir(parents=True)
        np.savez(d / "predictions.npz", y_true=test.y[keep], y_pred=y_pred, subject=subject[keep],
                 classes=np.array(classes))
        loso[arch] = {"folds": [f"s{s}" for s in folds], "all_folds": len(folds) == 3}
    md = "\n".join(same_folds_table(loso, tmp_path, test))
    two, one = md.split("On the same held-out subjects (1):")
    assert "(1, 2):" in two and "| LSTM |" not in two and "| ConvLSTM | 1.000 |" in two and "| CNN |" in two
    assert "| LSTM | 0.500 |" in one and "| ConvLSTM | 1.000 |" in one  # 2 of 4 wrong: F1 0.5 for both classes


def test_time_warp_keeps_the_trigger_and_changes_the_pace():
    from models.train import TRIGGER_FRAME, time_warped

    n = 198
    seq = torch.arange(n, dtype=torch.float32)[None, :, None].expand(2, n, 3).contiguous()
    out = time_warped(seq, np.array([1.0, 1.2]))
    assert torch.allclose(out[0], seq[0])  # factor 1: unchanged
    t = int(TRIGGER_FRAME)
    assert abs(float(out[1, t + 10, 0]) - (TRIGGER_FRAME + (t + 10 - TRIGGER_FRAME) * 1.2)) < 1e-4  # 1.2x as fast
    assert float(out[1, -1, 0]) == n - 1  # past the end: the edge frame


def test_weighted_loss_is_cross_entropy_unless_asked():
    from models.train import WeightedLoss

    logits, y, w = torch.randn(8, 6), torch.randint(0, 6, (8,)), torch.rand(6) + 0.5
    ce = torch.nn.CrossEntropyLoss(weight=w)(logits, y)
    assert torch.allclose(WeightedLoss(w)(logits, y), ce)
    assert torch.allclose(WeightedLoss(w, 0.0, 1e-9)(logits, y), ce, atol=1e-5)  # the focal path at gamma -> 0
    assert WeightedLoss(w, 0.0, 2.0)(logits, y) < ce  # the focal term only lowers each example's loss
