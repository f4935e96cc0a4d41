"""Rebuild ``edge_runtime/assets/`` from a seed, and check int8 against fp32 fold by fold.

``build_assets`` (``python -m export assets --seed S``):

1. simulate the cohort (``models.dataset.build_cohort_datasets``: ground-truth
   training windows and detector-captured test windows of every subject);
2. train the ConvLSTM on all subjects' ground-truth windows, plus their detector
   captures when the recipe chosen on the selection cohort says so
   (``reports/wearable/selection/selection.json``, :mod:`models.selection`: captures,
   time shift, epochs), with deep supervision over the 6 sub-windows
   (``models.train.fit``, deterministic for a seed);
3. export fp32 ONNX (parity with torch < 1e-4 checked on the test captures);
4. quantise to int8, calibrated on training windows, variant chosen by
   measured latency under an accuracy gate (``export.quantize.choose``);
5. score fp32 and int8 on the detector-captured test windows and, when a LOSO
   directory is given (``--loso-dir``; by default ``reports/wearable/convlstm/loso``
   when ``python -m models report`` has written it), pooled over its folds
   (``compare_int8``: each fold's checkpoint exported and quantised with the
   chosen recipe, scored on the held-out subject's captures);
6. fit the early decisions' per-step temperatures and preliminary-alert thresholds on
   the selection cohort's detector captures (none of its subjects is in training), per
   model (fp32 and int8 each on its own outputs), check int8 against fp32 after every
   S = 1..6 sub-windows on the test captures, and write the models and ``manifest.json``
   (each ConvLSTM entry with an ``early`` object; entries for other models already in
   the manifest, e.g. a pose lifter, are kept);
7. export the same trained model as the streaming step model (``export.step_model``: one
   sub-window and the LSTM state in, the decision and the next state out), fp32 (parity with
   torch after every S) and int8 (``quantise_step``: gated per step on the selection cohort's
   captures, none of whose subjects is in training; the training cohort's "test" captures are
   training data when the recipe says ``captures``),
   as entries ``convlstm-step-fp32`` / ``convlstm-step-int8`` (arch ``convlstm_step``) that the
   ConvLSTM entries name in ``step_model``: the box decides by them (``python -m export step``
   runs this step alone on the shipped model).

No timestamps go into the files: the same seed on the same commit rebuilds
byte-identical models (training is deterministic with one thread).
"""
from __future__ import annotations

import json
import platform
import shlex
import shutil
import sys
import tempfile
import time
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from edge_runtime.core.manifest import (
    SCHEMA_VERSION,
    ManifestError,
    ModelIntegrityError,
    load_manifest,
    select_model,
    sha256_file,
    verify_all,
    write_manifest,
)
from edge_runtime.wearable.classifier import Engine, preprocess
from export.onnx_export import (
    DEFAULT_OPSET,
    EARLY_INPUT_LAYOUT,
    INPUT_NAME,
    LOGITS,
    PROBS,
    ExportError,
    check_parity,
    git_commit,
    package_version,
    save_onnx,
    to_onnx,
)
from export.quantize import VARIANTS, QuantizeError, build_variant, choose, pick_windows, probs_of

REPO_ROOT = Path(__file__).resolve().parent.parent
DEFAULT_ASSETS = REPO_ROOT / "edge_runtime" / "assets"
ARCH = "convlstm"
N_CALIB = 1000
EARLY_MIN_AGREEMENT = 0.99
"""int8 must give fp32's class after every S in ``ALERT_STEPS`` sub-windows on at least this share of test captures."""
ALERT_STEPS = (2, 3, 4, 5, 6)
"""The steps that may raise a preliminary alert. After 1 sub-window (0.16 s after the trigger) the
decision is near chance (validation macro-F1 about 0.45) and most of them are near ties that int8
flips (agreement 0.986 with every candidate of the first build): S = 1 gets min_confidence 1.0."""
DEFAULT_LOSO = REPO_ROOT / "reports" / "wearable" / ARCH / "loso"  # where `python -m models report` puts it


def versions() -> dict:
    import numpy
    import onnx
    import onnxruntime
    import torch

    return {"python": platform.python_version(), "torch": torch.__version__, "onnx": onnx.__version__,
            "onnxruntime": onnxruntime.__version__, "numpy": numpy.__version__,
            "edge_safety": package_version()}


def _metrics(y_true, probs, classes, subject=None) -> dict:
    from models.evaluate import compute_metrics

    m = compute_metrics(y_true, np.asarray(probs).argmax(1), classes, subject)
    keep = ("n", "accuracy", "macro_f1", "macro_f1_distractions", "macro_precision", "macro_recall",
            "weighted_f1", "per_class", "confusion")
    return {k: m[k] for k in keep if k in m}


def io_spec(k: int) -> tuple[list, list]:
    inputs = [{"name": INPUT_NAME, "shape": ["N", "S", 33, 3], "dtype": "float32", "layout": EARLY_INPUT_LAYOUT,
               "units": "m/s^2", "steps": {"min": 1, "max": 6, "full_capture": 6},
               "preprocess": "edge_runtime.wearable.classifier.preprocess(capture (N, 700, 3) at 100 Hz)[:, :S]"}]
    outputs = [{"name": PROBS, "shape": ["N", k], "dtype": "float32",
                "meaning": "softmax, classes order: the decision after the S sub-windows given (before temperature "
                           "scaling: divide log(probs) by early.temperature_by_steps[S] and re-normalise)"},
               {"name": LOGITS, "shape": ["N", k], "dtype": "float32", "meaning": "pre-softmax scores"}]
    return inputs, outputs


# --------------------------------------------------------------------------- LOSO: fp32 vs int8

def _loso_sources(loso_dir: Path, train_npz: str | None, test_npz: str | None) -> tuple[str, str | None]:
    mpath = loso_dir / "metrics.json"
    meta = {}
    if mpath.exists():
        try:
            meta = json.loads(mpath.read_text())
        except json.JSONDecodeError:
            raise ExportError(f"{mpath}: not valid JSON") from None
    train = train_npz or meta.get("train")
    test = test_npz or meta.get("test")
    if not train:
        raise ExportError(f"{mpath}: field 'train': unknown training NPZ (pass --train)")

    def resolve(p):  # paths in metrics.json are as the trainer saw them (often relative to the repo)
        if p and not Path(p).exists() and (REPO_ROOT / p).exists():
            return str(REPO_ROOT / p)
        return p

    return resolve(train), resolve(test)


def compare_int8(loso_dir: str | Path, *, method: str | None = None, train_npz: str | None = None,
                 test_npz: str | None = None, n_calib: int = N_CALIB, seed: int = 0,
                 log: Callable[[str], None] = lambda s: None) -> dict:
    """For every fold checkpoint DIR/folds/*/model.pt: export, quantise (``method``; default the
    shipped recipe), score fp32 and int8 on the held-out subject's test windows; pooled macro-F1."""
    from models.dataset import load_npz

    loso_dir = Path(loso_dir)
    ckpts = _fold_checkpoints(loso_dir)
    method = method or _shipped_method() or "qdq_conv"
    if method not in VARIANTS:
        raise ExportError(f"--method: unknown quantisation variant {method!r}; choose from {', '.join(VARIANTS)}")
    train_src, test_src = _loso_sources(loso_dir, train_npz, test_npz)
    train = load_npz(train_src)
    test = load_npz(test_src) if test_src else None
    X_train = preprocess(train.X)
    ev_set, ev_x = (test, preprocess(test.X)) if test is not None else (train, X_train)
    y_true, p32, p8, subj, rows = [], [], [], [], []
    max_parity = 0.0
    with tempfile.TemporaryDirectory() as td:
        for ck in ckpts:
            name, ev, a, b, parity = _score_fold(ck, Path(td), train, X_train, ev_set, ev_x, method=method,
                                                 n_calib=n_calib, seed=seed, train_src=train_src)
            max_parity = max(max_parity, parity)
            y_true.append(ev_set.y[ev])
            p32.append(a)
            p8.append(b)
            subj.append(ev_set.subject[ev])
            agree = float(np.mean(a.argmax(1) == b.argmax(1))) if len(ev) else float("nan")
            rows.append({"fold": name, "n": int(len(ev)), "agreement": agree})
            log(f"  fold {name}: n {len(ev)}, int8/fp32 agreement {agree:.3f}")
    y = np.concatenate(y_true)
    P32, P8, S = np.concatenate(p32), np.concatenate(p8), np.concatenate(subj)
    m32 = _metrics(y, P32, train.classes, S)
    m8 = _metrics(y, P8, train.classes, S)
    delta = m8["macro_f1"] - m32["macro_f1"]
    return {
        "protocol": "leave-one-subject-out: per fold, the fold's checkpoint exported (fp32) and quantised "
                    f"({method}, calibrated on the fold's training subjects), scored on the held-out "
                    "subject's " + ("detector-captured test windows" if test is not None else "training windows"),
        "loso_dir": str(loso_dir), "train": train_src, "test": test_src, "method": method,
        "folds": len(ckpts), "n": int(len(y)),
        "fp32_macro_f1": m32["macro_f1"], "int8_macro_f1": m8["macro_f1"], "macro_f1_delta": delta,
        "fp32_accuracy": m32["accuracy"], "int8_accuracy": m8["accuracy"],
        "agreement": float(np.mean(P32.argmax(1) == P8.argmax(1))),
        "max_parity_torch_onnx": max_parity,
        "holds": bool(abs(delta) <= 0.01), "per_fold": rows,
        "fp32": m32, "int8": m8,
    }


def _fold_checkpoints(loso_dir: Path) -> list[Path]:
    """DIR/folds/*/model.pt in fold order (s2 before s10)."""
    if not loso_dir.is_dir():
        raise ExportError(f"{loso_dir}: LOSO directory not found")
    ckpts = sorted((loso_dir / "folds").glob("*/model.pt"), key=lambda p: (len(p.parent.name), p.parent.name))
    if not ckpts:
        raise ExportError(f"{loso_dir}: no fold checkpoints (folds/*/model.pt); run "
                          "`python -m models train --loso ...` first")
    return ckpts


def _score_fold(ck: Path, td: Path, train, X_train: np.ndarray, ev_set, ev_x: np.ndarray, *, method: str,
                n_calib: int, seed: int, train_src: str) -> tuple[str, np.ndarray, np.ndarray, np.ndarray, float]:
    """One fold's checkpoint exported to ``td`` and quantised (calibrated on the other subjects'
    training windows): (fold name, indices of the held-out subject's windows in ``ev_set``, fp32
    and int8 probabilities on them, the largest torch/onnxruntime difference)."""
    from models.train import load_checkpoint

    model, meta = load_checkpoint(ck)
    if list(meta["classes"]) != list(train.classes):
        raise ExportError(f"{ck}: field 'classes': {meta['classes']} differ from {train_src}'s {train.classes}")
    name = str(meta.get("metrics", {}).get("fold") or ck.parent.name)
    try:
        s = int(name.lstrip("s"))
    except ValueError:
        raise ExportError(f"{ck}: cannot tell the held-out subject from fold name {name!r}") from None
    ev = np.flatnonzero(ev_set.subject == s)
    cal = np.flatnonzero(train.subject != s)
    cal = cal[pick_windows(train.y[cal], n_calib, seed)]
    fp = td / f"{name}.onnx"
    q = td / f"{name}.int8.onnx"
    onx = to_onnx(model, meta["classes"], commit="")
    save_onnx(onx, fp)
    par = check_parity(model, onx, ev_x[ev[:64]] if len(ev) else None)
    build_variant(fp, q, method, X_train[cal])
    a = probs_of(fp, ev_x[ev]) if len(ev) else np.zeros((0, len(train.classes)))
    b = probs_of(q, ev_x[ev]) if len(ev) else np.zeros((0, len(train.classes)))
    return name, ev, a, b, max(par["max_abs_logits"], par["max_abs_probs"])


def _shipped_method() -> str | None:
    try:
        m = load_manifest(DEFAULT_ASSETS)
    except ManifestError:
        return None
    for e in m["models"]:
        if e.get("precision") == "int8" and e.get("arch") == ARCH:
            return (e.get("quantization") or {}).get("method")
    return None


# --------------------------------------------------------------------------- the shipped assets

def build_assets(*, seed: int = 0, subjects: int = 20, epochs: int | None = None, minutes: float = 15.0,
                 out: str | Path = DEFAULT_ASSETS, work: str | Path | None = None,
                 train_npz: str | None = None, test_npz: str | None = None, loso_dir: str | None = None,
                 variants: Sequence[str] | None = None, command: str | None = None, auto_loso: bool = True,
                 log: Callable[[str], None] = print, progress: bool = True, selection: str | Path | None = None,
                 early_min_agreement: float = EARLY_MIN_AGREEMENT, checkpoint: str | Path | None = None) -> dict:
    """The module docstring's steps 1-6, one function each; returns the manifest written.
    ``selection``: the selection.json whose recipe trains the model and beside whose cohort the
    early decisions are calibrated (default: reports/wearable/selection/selection.json).
    ``checkpoint``: the model.pt an earlier run of this command wrote (``WORK/convlstm``) instead of
    training again; training is deterministic, so for the same seed, data and training code it holds
    the same weights (the manifest records that it was reused)."""
    from models.selection import load_recipe
    from models.train import STEP_LOSS_WEIGHTS

    t0 = time.time()
    out = Path(out)
    work = Path(work) if work else REPO_ROOT / "runs" / f"assets-seed{seed}"
    recipe = load_recipe(selection)
    epochs = recipe["epochs"] if epochs is None else epochs
    if epochs < 1:
        raise ExportError(f"--epochs: must be at least 1, got {epochs}")
    if subjects < 1:
        raise ExportError(f"--subjects: must be at least 1, got {subjects}")
    command = command or "python -m export " + " ".join(shlex.quote(a) for a in sys.argv[1:])

    train_npz, test_npz, data_info = _cohort(train_npz, test_npz, subjects=subjects, seed=seed, minutes=minutes,
                                             work=work, log=log, progress=progress)
    train, test = _load_cohort(train_npz, test_npz, data_info)
    if checkpoint:
        model, train_s, n_windows = _reuse(checkpoint, train, test, recipe, epochs=epochs, seed=seed, log=log)
    else:
        model, train_s, n_windows = _train(train, test, recipe, epochs=epochs, seed=seed, work=work,
                                           data={"train": str(train_npz), "test": str(test_npz)}, log=log,
                                           progress=progress)
    X_train, X_test = preprocess(train.X), preprocess(test.X)
    version, commit = f"{package_version()}+{ARCH}.seed{seed}", git_commit()
    # models are staged in the work directory and copied next to the manifest only when
    # everything passed: a failed build never leaves half-updated assets
    fp32_path, parity = _export_fp32(model, train, X_test, seed=seed, epochs=epochs, version=version,
                                     commit=commit, stage=work / "stage", log=log)
    int8_path, quant = _quantise(fp32_path, X_train, train.y, X_test, test.y, seed=seed, variants=variants, log=log,
                                 early_min_agreement=early_min_agreement)
    scores = _score(fp32_path, int8_path, X_test, test.y, list(train.classes), method=quant["method"],
                    loso_dir=_loso_dir(loso_dir, auto_loso), log=log)
    early = _early(fp32_path, int8_path, X_test, list(train.classes), seed=seed, selection=selection, log=log,
                   min_agreement=early_min_agreement)

    provenance = {"command": command, "seed": seed, "data": data_info,
                  "training": {"arch": ARCH, "epochs": epochs, "seed": seed, "windows": n_windows,
                               "recipe": recipe,
                               "step_loss_weights": list(recipe.get("step_loss_weights", STEP_LOSS_WEIGHTS)),
                               **({"reused_checkpoint": str(checkpoint)} if checkpoint else {}),
                               "function": "models.train.fit", "threads": 1, "seconds": round(train_s, 1)},
                  "git_commit": commit, "versions": versions(), "opset": DEFAULT_OPSET,
                  "exporter": "torch.onnx.export(dynamo=False) via export.onnx_export.to_onnx"}
    entries = _entries(fp32_path, int8_path, _common(model, list(train.classes), version, provenance),
                       parity, quant, scores)
    for e in entries:
        e["early"] = early[e["precision"]]
    entries[1]["metrics"]["early_agreement_with_fp32_by_steps"] = early["agreement_by_steps"]
    step_paths, step_entries = build_step(model, train, X_train, X_test, seed=seed, version=version,
                                          commit=commit, stage=work / "stage", provenance=provenance, log=log,
                                          min_agreement=early_min_agreement, selection=selection)
    link_steps(entries, step_entries)
    manifest, path = _install(out, entries + step_entries, (fp32_path, int8_path, *step_paths), command)
    check_loads(out)
    log(f"wrote {out / fp32_path.name}, {out / int8_path.name}, "
        f"{', '.join(p.name for p in step_paths)}, {path} in {time.time() - t0:.0f} s")
    return manifest


# --------------------------------------------------------------------------- the step model

STEP_FILE = "convlstm_step.{}.onnx"


def build_step(model, train, X_train: np.ndarray, X_test: np.ndarray, *, seed: int, version: str,
               commit: str | None, stage: Path, provenance: dict, log: Callable[[str], None],
               min_agreement: float = EARLY_MIN_AGREEMENT, selection: str | Path | None = None
               ) -> tuple[list[Path], list[dict]]:
    """7. The streaming step model of the same trained ConvLSTM (``export.step_model``): fp32 (parity with
    torch's decision after every S = 1..6 on the training cohort's captures) and int8 (the candidate chosen by
    ``export.step_model.quantise_step``, calibrated on the training windows the one-shot int8 is, gated
    per step on the selection cohort's captures: ``selection``'s, as step 6 reads them); their files in
    ``stage`` and their manifest entries.

    Why the selection cohort: with the shipped recipe (``captures``) the training cohort's detector captures
    are training data, so a gate on them would choose the recipe on windows the model has seen."""
    from export.step_model import (
        C_IN,
        C_OUT,
        H_IN,
        H_OUT,
        STEP_ARCH,
        STEP_INPUT_LAYOUT,
        check_step_parity,
        quantise_step,
        to_step_onnx,
    )
    from models.nets import keras_param_count, torch_param_count
    from models.selection import ensure_selection_captures

    classes = list(train.classes)
    sel, gated_on = ensure_selection_captures(seed, selection, log=log)
    if list(sel.classes) != classes:
        raise ExportError(f"{sel.source}: field 'classes': {sel.classes} differ from {classes}")
    stage.mkdir(parents=True, exist_ok=True)
    onx = to_step_onnx(model, classes, model_version=version, commit=commit,
                       extra_meta={"training": {"seed": seed, "epochs": provenance["training"]["epochs"],
                                                "windows": len(train)}})
    parity = check_step_parity(model, onx, X_test[:512])
    fp32_path = _save_with_parity(onx, stage / STEP_FILE.format("fp32"), parity, "[7] decisions after S = 1..6,", log)
    int8_path = fp32_path.with_name(STEP_FILE.format("int8"))
    quant = quantise_step(fp32_path, int8_path, calibration_windows(X_train, train.y, seed), preprocess(sel.X), sel.y,
                          gate_steps=ALERT_STEPS, min_agreement=min_agreement, log=log)
    quant["calibration"].update(source="training windows (ground-truth segments), stratified by class", seed=seed)
    quant["selection"]["gated_on"] = gated_on
    log(f"    chose {quant['method']}: int8/fp32 agreement by steps "
        + ", ".join(f"{k}: {v:.4f}" for k, v in quant["agreement_by_steps"].items()))
    hidden = model.lstm.hidden_size
    state = {"dtype": "float32", "units": "LSTM state"}
    common = {"arch": STEP_ARCH, "model_version": version, "classes": classes, "provenance": provenance,
              "parameters": {"torch": torch_param_count(model), "keras": keras_param_count(model)},
              "inputs": [{"name": INPUT_NAME, "shape": ["N", 33, 3], "dtype": "float32", "units": "m/s^2",
                          "layout": STEP_INPUT_LAYOUT,
                          "preprocess": "edge_runtime.wearable.classifier.step_inputs (sub-window s as it arrived)"},
                         {"name": H_IN, "shape": ["N", hidden], **state}, {"name": C_IN, "shape": ["N", hidden], **state}],
              "outputs": [{"name": PROBS, "shape": ["N", len(classes)], "dtype": "float32",
                           "meaning": "softmax, classes order: the decision after this sub-window (temperature: the "
                                      "one-shot entry's early.temperature_by_steps[S])"},
                          {"name": H_OUT, "shape": ["N", hidden], **state}, {"name": C_OUT, "shape": ["N", hidden], **state}]}
    entries = [{"name": f"{ARCH}-step-{p}", "file": path.name, "sha256": sha256_file(path), "precision": p,
                "size_bytes": path.stat().st_size, **common} for p, path in (("fp32", fp32_path), ("int8", int8_path))]
    entries[0]["metrics"] = {"parity_vs_torch": parity}
    entries[1]["metrics"] = {"agreement_with_fp32_by_steps": quant["agreement_by_steps"],
                             "macro_f1_by_steps": quant["macro_f1_by_steps"],
                             "macro_f1_delta_vs_fp32": quant["macro_f1_delta"],
                             "evaluated_on": f"{gated_on}, run step by step (the int8 recipe's gate)"}
    entries[1]["quantization"] = quant
    return [fp32_path, int8_path], entries


def link_steps(entries: list[dict], step_entries: list[dict]) -> None:
    """Each one-shot entry names the step model of its precision (``step_model``), the one the box decides by."""
    by_precision = {e["precision"]: e["name"] for e in step_entries}
    for e in entries:
        e["step_model"] = by_precision[e["precision"]]


def add_step_models(*, checkpoint: str | Path, out: str | Path = DEFAULT_ASSETS, work: str | Path | None = None,
                    train_npz: str | None = None, test_npz: str | None = None, command: str | None = None,
                    selection: str | Path | None = None, log: Callable[[str], None] = print) -> dict:
    """``python -m export step``: step 7 of :func:`build_assets` alone, on the shipped ConvLSTM: its
    checkpoint (checked to give the shipped fp32 model's outputs on the test captures) exported as the
    step model, fp32 and int8, added to ``out`` and linked from the ConvLSTM entries; the one-shot
    files are untouched."""
    from edge_runtime.core.onnx import open_session
    from models.train import load_checkpoint

    out = Path(out)
    manifest = verify_all(out)
    fp32_entry = select_model(manifest, f"{ARCH}-fp32", arch=ARCH)
    train, test = _windows_of(fp32_entry, work, train_npz, test_npz, log)
    model, meta = load_checkpoint(checkpoint)
    X_train, X_test = preprocess(train.X), preprocess(test.X)
    shipped = open_session(out / fp32_entry["file"]).run([PROBS], {INPUT_NAME: X_test[:512]})[0]
    onx = to_onnx(model, list(train.classes), commit="")
    mine = open_session(onx.SerializeToString()).run([PROBS], {INPUT_NAME: X_test[:512]})[0]
    if list(meta.get("classes", [])) != list(fp32_entry["classes"]) or float(np.abs(mine - shipped).max()) > 1e-5:
        raise ExportError(f"{checkpoint}: not the checkpoint {out / fp32_entry['file']} was exported from "
                          f"(its outputs on the test captures differ)")
    seed = int(fp32_entry["provenance"]["seed"])
    provenance = dict(fp32_entry["provenance"],
                      step_model={"command": command or "python -m export " + " ".join(shlex.quote(a) for a in sys.argv[1:]),
                                  "checkpoint": str(checkpoint), "git_commit": git_commit(), "versions": versions()})
    with tempfile.TemporaryDirectory() as td:
        paths, step_entries = build_step(model, train, X_train, X_test, seed=seed,
                                         version=fp32_entry["model_version"], commit=git_commit(), stage=Path(td),
                                         provenance=provenance, log=log, selection=selection)
        for p in paths:
            shutil.copyfile(p, out / p.name)
    names = {e["name"] for e in step_entries}
    kept = [e for e in manifest["models"] if e["name"] not in names]
    link_steps([e for e in kept if e["arch"] == ARCH], step_entries)
    last = max(i for i, e in enumerate(kept) if e["arch"] == ARCH)  # beside the ConvLSTM's entries
    manifest["models"] = kept[:last + 1] + step_entries + kept[last + 1:]
    write_manifest(out, manifest)
    check_loads(out)
    log(f"wrote {', '.join(p.name for p in paths)} and {out / 'manifest.json'}")
    return manifest


def _cohort(train_npz: str | None, test_npz: str | None, *, subjects: int, seed: int, minutes: float, work: Path,
            log: Callable[[str], None], progress: bool) -> tuple[str, str, dict]:
    """1. (training NPZ, test NPZ, data provenance): the given files, else a simulated cohort."""
    from models.dataset import build_cohort_datasets

    if train_npz or test_npz:
        if not (train_npz and test_npz):
            raise ExportError("--train and --test go together")
        return train_npz, test_npz, {"source": "given NPZ files", "train": str(train_npz), "test": str(test_npz)}
    log(f"[1/5] simulating {subjects} subjects (seed {seed}, {minutes:g} min per trial) -> {work / 'data'}")
    d = build_cohort_datasets(subjects, seed, minutes, work / "data", progress=progress)
    detector = d["detector"]
    return d["train"], d["test"], {
        "source": "firmware_sim.devices.wrist.simulate_cohort via models.dataset.build_cohort_datasets",
        "subjects": subjects, "seed": seed, "minutes_per_trial": minutes,
        "detector": {k: detector[k] for k in ("recall", "precision", "distractions", "captures", "false_alarms")}}


def _load_cohort(train_npz: str, test_npz: str, data_info: dict):
    """1. The two window sets (same classes, in the same order); their counts go into ``data_info``."""
    from models.dataset import load_npz

    train, test = load_npz(train_npz), load_npz(test_npz)
    if list(train.classes) != list(test.classes):
        raise ExportError(f"{test_npz}: field 'classes': {test.classes} differ from {train_npz}'s {train.classes}")
    data_info.update(train_windows=len(train), test_windows=len(test), train_counts=train.counts(),
                     test_counts=test.counts(),
                     train_kind="ground-truth segments (1 s before each truth event, 700 frames)",
                     test_kind="detector captures (false alarms labelled Other)")
    return train, test


def _train(train, test, recipe: dict, *, epochs: int, seed: int, work: Path, data: dict,
           log: Callable[[str], None], progress: bool):
    """2. (the ConvLSTM trained on every subject, training seconds, training windows); checkpoint in
    ``work``. The recipe (models.selection) says whether the detector captures join the
    ground-truth windows, how far the time shift reaches, and the schedule's length."""
    from models.selection import training_arrays
    from models.train import fit, recipe_fit_kwargs, save_checkpoint

    subjects = np.unique(train.subject)
    X, y = training_arrays(train, test if recipe["captures"] else None, subjects)
    log(f"[2/5] training {ARCH} on {len(y)} windows of all subjects ({'ground truth + detector captures' if recipe['captures'] else 'ground truth'}; "
        f"{epochs} epochs of a {recipe['schedule_epochs']}-epoch schedule, seed {seed})")
    t = time.time()
    model = fit(ARCH, X, y, len(train.classes), epochs=epochs, seed=seed, progress=progress,
                desc=f"{ARCH} assets", **recipe_fit_kwargs(recipe))
    train_s = time.time() - t
    save_checkpoint(work / ARCH, model, arch=ARCH, classes=list(train.classes), seed=seed, epochs=epochs, metrics={},
                    data=data)
    return model, train_s, int(len(y))


def _reuse(checkpoint, train, test, recipe: dict, *, epochs: int, seed: int, log: Callable[[str], None]):
    """2. The checkpoint an earlier run trained, checked against this run's seed, epochs and classes."""
    from models.selection import training_arrays
    from models.train import load_checkpoint

    model, meta = load_checkpoint(checkpoint)
    if (meta.get("arch"), meta.get("seed"), meta.get("epochs"), list(meta.get("classes", []))) != (
            ARCH, seed, epochs, list(train.classes)):
        raise ExportError(f"{checkpoint}: field 'seed'/'epochs'/'classes': trained with seed {meta.get('seed')}, "
                          f"{meta.get('epochs')} epochs, classes {meta.get('classes')}; this build wants seed {seed}, "
                          f"{epochs} epochs, {list(train.classes)}")
    n = len(training_arrays(train, test if recipe["captures"] else None, np.unique(train.subject))[1])
    log(f"[2/5] reusing {checkpoint} ({ARCH}, seed {seed}, {epochs} epochs) instead of training again")
    return model, 0.0, n


def _export_fp32(model, train, X_test: np.ndarray, *, seed: int, epochs: int, version: str, commit: str | None,
                 stage: Path, log: Callable[[str], None]) -> tuple[Path, dict]:
    """3. ``stage/convlstm.fp32.onnx`` and its parity with torch on the test captures (raises when off)."""
    stage.mkdir(parents=True, exist_ok=True)
    onx = to_onnx(model, list(train.classes), opset=DEFAULT_OPSET, model_version=version, commit=commit,
                  extra_meta={"training": {"seed": seed, "epochs": epochs, "windows": len(train)}})
    parity = check_parity(model, onx, X_test[:512])
    return _save_with_parity(onx, stage / f"{ARCH}.fp32.onnx", parity, "[3/5]", log), parity


def _save_with_parity(onx, path: Path, parity: dict, what: str, log: Callable[[str], None]) -> Path:
    """``onx`` written to ``path`` and its torch/onnxruntime ``parity`` logged (``what``: the build step and
    the outputs compared); raises ExportError when the parity does not hold."""
    path = save_onnx(onx, path)
    log(f"{what} {path.name}: parity with torch, max |d| "
        + ", ".join(f"{k.removeprefix('max_abs_')} {v:.2e}" for k, v in parity.items() if k.startswith("max_abs_")))
    if not parity["ok"]:
        raise ExportError(f"{path}: torch/onnxruntime parity exceeds {parity['tol']:g}")
    return path


def _quantise(fp32_path: Path, X_train: np.ndarray, y_train: np.ndarray, X_test: np.ndarray, y_test: np.ndarray, *,
              seed: int, variants: Sequence[str] | None, log: Callable[[str], None],
              early_min_agreement: float) -> tuple[Path, dict]:
    """4. The int8 model next to the fp32 one, calibrated on training windows, the variant chosen by
    :func:`export.quantize.choose` gated on the test captures; and its quantisation report."""
    log("[4/5] quantising: candidates timed with 1 thread, gated on the test captures")
    int8_path = fp32_path.with_name(f"{ARCH}.int8.onnx")
    quant = choose(fp32_path, int8_path, calibration_windows(X_train, y_train, seed), eval_x=X_test, eval_y=y_test,
                   variants=variants, log=log, early_min_agreement=early_min_agreement,
                   early_steps=[s for s in ALERT_STEPS if s < 6])
    quant["calibration"].update(source="training windows (ground-truth segments), stratified by class",
                                seed=seed)
    log(f"      chose {quant['method']}: int8 operators {quant['int8_operators']}")
    return int8_path, quant


def calibration_windows(X_train: np.ndarray, y_train: np.ndarray, seed: int) -> np.ndarray:
    """The int8 model's calibration inputs: N_CALIB preprocessed training windows, stratified by class."""
    return X_train[pick_windows(y_train, N_CALIB, seed)]


def _loso_dir(loso_dir: str | None, auto_loso: bool) -> str | None:
    """The LOSO directory to compare fp32 and int8 over: the given one, else the report's when
    ``python -m models report`` has written its folds."""
    if loso_dir is None and auto_loso and (DEFAULT_LOSO / "folds").is_dir() and (DEFAULT_LOSO / "metrics.json").exists():
        return str(DEFAULT_LOSO)
    return loso_dir


def _score(fp32_path: Path, int8_path: Path, X_test: np.ndarray, y_test: np.ndarray, classes: list[str], *,
           method: str, loso_dir: str | None, log: Callable[[str], None]) -> dict:
    """5. fp32 and int8 metrics on the test captures (and over the LOSO folds); raises when int8's
    macro-F1 is more than 0.01 from fp32's."""
    p32, p8 = probs_of(fp32_path, X_test), probs_of(int8_path, X_test)
    m32, m8 = _metrics(y_test, p32, classes), _metrics(y_test, p8, classes)
    delta = m8["macro_f1"] - m32["macro_f1"]
    loso = None
    if loso_dir:
        log(f"      LOSO fp32 vs int8 over {loso_dir}")
        loso = compare_int8(loso_dir, method=method, log=log)
        loso = {k: v for k, v in loso.items() if k not in ("fp32", "int8")}
    log(f"[5/5] test captures: fp32 macro-F1 {m32['macro_f1']:.4f}, int8 {m8['macro_f1']:.4f} (d {delta:+.4f})"
        + (f"; LOSO fp32 {loso['fp32_macro_f1']:.4f} int8 {loso['int8_macro_f1']:.4f}" if loso else ""))
    if abs(delta) > 0.01:
        raise QuantizeError(f"{int8_path}: int8 macro-F1 differs from fp32 by {delta:+.4f} (> 0.01)")
    return {"fp32": m32, "int8": m8, "delta": delta, "agreement": float(np.mean(p32.argmax(1) == p8.argmax(1))),
            "loso": loso}


def step_probs_of(model_path: Path, X: np.ndarray) -> np.ndarray:
    """(6, N, K): the ONNX model's decision after the first S = 1..6 sub-windows of inputs (N, 6, 33, 3)."""
    return np.stack([probs_of(model_path, np.ascontiguousarray(X[:, :s])) for s in range(1, 7)])


def _early(fp32_path: Path, int8_path: Path, X_test: np.ndarray, classes: list[str], *, seed: int,
           selection: str | Path | None, log: Callable[[str], None], min_agreement: float) -> dict:
    """6. Per model, the manifest's ``early`` object (per-step temperatures and preliminary-alert
    thresholds fitted on the selection cohort's captures); int8/fp32 agreement per step on the
    test captures (must be >= ``min_agreement``)."""
    from models.selection import calibrate_steps, ensure_selection_captures

    sel, chosen_on = ensure_selection_captures(seed, selection, log=log)
    if list(sel.classes) != classes:
        raise ExportError(f"{sel.source}: field 'classes': {sel.classes} differ from {classes}")
    X_sel = preprocess(sel.X)
    out = {}
    for name, path in (("fp32", fp32_path), ("int8", int8_path)):
        c = calibrate_steps(step_probs_of(path, X_sel), sel.y, classes.index("Other"))
        thresholds = {k: (v if int(k) in ALERT_STEPS else 1.0) for k, v in c["min_confidence_by_steps"].items()}
        out[name] = {"steps": c["steps"], "temperature_by_steps": c["temperature_by_steps"],
                     "min_confidence_by_steps": thresholds, "chosen_on": chosen_on, "alert_steps": list(ALERT_STEPS),
                     "criterion": f"temperature: NLL on the validation captures, per step; min_confidence: the "
                                  f"smallest calibrated confidence at which alerts (a class other than Other) "
                                  f"are a distraction, not Other, in >= {c['alert_precision_target']:.0%} of "
                                  f"validation captures; 1.0 = no preliminary alert at that step (always at "
                                  f"S = 1: near-chance decisions that int8 does not reproduce reliably)",
                     "validation": c["validation"]}
    a32, a8 = step_probs_of(fp32_path, X_test), step_probs_of(int8_path, X_test)
    agree = {str(s): float(np.mean(a32[s - 1].argmax(1) == a8[s - 1].argmax(1))) for s in range(1, 7)}
    out["agreement_by_steps"] = agree
    log(f"      early decisions: int8/fp32 agreement by steps {', '.join(f'{k}: {v:.4f}' for k, v in agree.items())}; "
        f"temperatures {out['int8']['temperature_by_steps']}; min confidence {out['int8']['min_confidence_by_steps']}")
    worst = min(agree[str(s)] for s in ALERT_STEPS)
    if worst < min_agreement:
        raise QuantizeError(f"{int8_path}: int8 agrees with fp32 on only {worst:.4f} of the decisions after "
                            f"{list(ALERT_STEPS)} sub-windows (< {min_agreement})")
    return out


def _common(model, classes: list[str], version: str, provenance: dict) -> dict:
    """6. What both manifest entries say alike: the model contract and its provenance."""
    from models.nets import keras_param_count, torch_param_count

    inputs, outputs = io_spec(len(classes))
    return {"arch": ARCH, "model_version": version,
            "parameters": {"torch": torch_param_count(model), "keras": keras_param_count(model)},
            "inputs": inputs, "outputs": outputs, "classes": classes, "provenance": provenance}


TRAINING_COHORT_NOTE = ("training-cohort captures, seen in training: the detector captures of the training subjects, "
                        "which the recipe (captures) trains on; not a test figure (between-subject figures are "
                        "under 'loso', the selection cohort's under the step model's gate)")
"""What the "test_captures" figures of a ConvLSTM entry are measured on (the key's name is the schema's)."""


def _entries(fp32_path: Path, int8_path: Path, common: dict, parity: dict, quant: dict, scores: dict) -> list[dict]:
    """6. The fp32 and int8 manifest entries."""
    eval_note = TRAINING_COHORT_NOTE
    loso = scores["loso"]
    return [
        {"name": f"{ARCH}-fp32", "file": fp32_path.name, "sha256": sha256_file(fp32_path), "precision": "fp32",
         "size_bytes": fp32_path.stat().st_size, **common,
         "metrics": {"test_captures": scores["fp32"], "evaluated_on": eval_note, "parity_vs_torch": parity,
                     **({"loso": {"macro_f1": loso["fp32_macro_f1"], "accuracy": loso["fp32_accuracy"],
                                  "folds": loso["folds"], "n": loso["n"]}} if loso else {})}},
        {"name": f"{ARCH}-int8", "file": int8_path.name, "sha256": sha256_file(int8_path), "precision": "int8",
         "size_bytes": int8_path.stat().st_size, **common,
         "metrics": {"test_captures": scores["int8"], "evaluated_on": eval_note,
                     "macro_f1_delta_vs_fp32": scores["delta"],
                     "agreement_with_fp32": scores["agreement"],
                     **({"loso": {"macro_f1": loso["int8_macro_f1"], "fp32_macro_f1": loso["fp32_macro_f1"],
                                  "macro_f1_delta_vs_fp32": loso["macro_f1_delta"], "folds": loso["folds"],
                                  "n": loso["n"], "method": loso["method"], "holds": loso["holds"]}}
                        if loso else {})},
         "quantization": quant},
    ]


# --------------------------------------------------------------------------- int8 only

def cohort_of(entry: dict, work: str | Path | None = None, *, log: Callable[[str], None] = print):
    """The training and test window sets a manifest entry was built from: its provenance's
    simulated cohort, simulated again (deterministic for the seed) into ``work``."""
    from models.dataset import load_npz

    data = entry["provenance"]["data"]
    if "subjects" not in data:
        raise ExportError(f"{entry['name']}: field 'provenance.data': built from given NPZ files "
                          f"({data.get('train')}); pass --train and --test")
    work = Path(work) if work else REPO_ROOT / "runs" / f"assets-seed{data['seed']}"
    train_npz, test_npz, _ = _cohort(None, None, subjects=data["subjects"], seed=data["seed"],
                                     minutes=data["minutes_per_trial"], work=work, log=log, progress=False)
    return load_npz(train_npz), load_npz(test_npz)


def _windows_of(fp32_entry: dict, work, train_npz: str | None, test_npz: str | None, log: Callable[[str], None]):
    """The training and test windows of the shipped model: the given NPZ files, else its cohort simulated again."""
    from models.dataset import load_npz

    if train_npz or test_npz:
        if not (train_npz and test_npz):
            raise ExportError("--train and --test go together")
        return load_npz(train_npz), load_npz(test_npz)
    return cohort_of(fp32_entry, work, log=log)


def requantize(*, out: str | Path = DEFAULT_ASSETS, work: str | Path | None = None, train_npz: str | None = None,
               test_npz: str | None = None, variants: Sequence[str] | None = None, loso_dir: str | None = None,
               command: str | None = None, early_min_agreement: float = EARLY_MIN_AGREEMENT,
               log: Callable[[str], None] = print) -> dict:
    """``python -m export int8``: the shipped fp32 ConvLSTM quantised again, without training.

    Calibration and test windows are the fp32 entry's own (its cohort simulated again, or
    ``--train``/``--test``), the recipe is chosen as :func:`build_assets` chooses it (step 4)
    and gated the same way (step 5); the int8 file and its manifest entry (sha256, size,
    quantisation report, test-capture metrics) are replaced, the fp32 file is untouched. The
    LOSO comparison is kept only when it was made with the chosen recipe (or is redone over
    ``loso_dir``)."""

    out = Path(out)
    manifest = verify_all(out)
    fp32_entry = select_model(manifest, f"{ARCH}-fp32", arch=ARCH)
    int8_entry = select_model(manifest, f"{ARCH}-int8", arch=ARCH)
    seed = int(fp32_entry["provenance"]["seed"])
    train, test = _windows_of(fp32_entry, work, train_npz, test_npz, log)
    if list(train.classes) != list(fp32_entry["classes"]):
        raise ExportError(f"{out / fp32_entry['file']}: field 'classes': {fp32_entry['classes']} differ from the "
                          f"windows' {list(train.classes)}")
    X_train, X_test = preprocess(train.X), preprocess(test.X)
    with tempfile.TemporaryDirectory() as td:
        fp32_path = Path(shutil.copyfile(out / fp32_entry["file"], Path(td) / fp32_entry["file"]))
        int8_path, quant = _quantise(fp32_path, X_train, train.y, X_test, test.y, seed=seed, variants=variants,
                                     log=log, early_min_agreement=early_min_agreement)
        scores = _score(fp32_path, int8_path, X_test, test.y, list(train.classes), method=quant["method"],
                        loso_dir=loso_dir, log=log)
        shutil.copyfile(int8_path, out / int8_entry["file"])
    quant["command"] = command or "python -m export " + " ".join(shlex.quote(a) for a in sys.argv[1:])
    old_loso = int8_entry["metrics"].get("loso")
    new = _entries(out / fp32_entry["file"], out / int8_entry["file"],
                   {k: v for k, v in int8_entry.items() if k not in ("name", "file", "sha256", "precision",
                                                                     "size_bytes", "metrics", "quantization")},
                   fp32_entry["metrics"].get("parity_vs_torch", {}), quant, scores)[1]
    if scores["loso"] is None and old_loso and old_loso.get("method") == quant["method"]:
        new["metrics"]["loso"] = old_loso
    manifest["models"] = [new if e is int8_entry else e for e in manifest["models"]]
    write_manifest(out, manifest)
    check_loads(out)
    log(f"wrote {out / int8_entry['file']} ({quant['method']}) and {out / 'manifest.json'}")
    return manifest


def check_loads(out: Path) -> None:
    """The box's own load of what was just written: every ConvLSTM precision through
    ``Engine.from_manifest`` (hashes, the step model's link and its agreement with the one-shot model),
    so that an export never leaves assets the box refuses to start with."""
    for precision in ("fp32", "int8"):
        try:
            Engine.from_manifest(out, precision)
        except (ModelIntegrityError, ManifestError) as e:
            raise ExportError(f"{out}: the box would refuse these assets ({precision}): {e}") from None


def _install(out: Path, entries: list[dict], files: Sequence[Path], command: str) -> tuple[dict, Path]:
    """6. ``files`` copied into ``out`` and ``out/manifest.json`` written: ``entries`` first, then
    the entries of other models already there (e.g. a pose lifter), untouched."""
    names = {e["name"] for e in entries}
    kept = []
    try:
        kept = [e for e in load_manifest(out)["models"] if e["name"] not in names]
    except ManifestError:
        pass
    manifest = {"version": SCHEMA_VERSION, "created_by": f"{command} (edge-safety {package_version()})",
                "models": entries + kept}
    out.mkdir(parents=True, exist_ok=True)
    for p in files:
        shutil.copyfile(p, out / p.name)
    return manifest, write_manifest(out, manifest)
