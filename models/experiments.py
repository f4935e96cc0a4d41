"""Evaluation protocols: train/test, leave-one-subject-out, within-subject.

``run_train_test`` trains on a TRAIN set and scores a TEST set.

``run_loso`` (between-participant, Table 2.2): one fold per subject of the
TRAIN set. The fold trains on every other subject's training windows and is
scored on the held-out subject's detector captures from the TEST set when one
is given (the dissertation's protocol), else on the held-out subject's own
training windows. Each fold's checkpoint and its result (result.npz: the held-out
subject's predictions, per-step probabilities; result.json: its calibration and
what it was made from) go to DIR/folds/s<K>/ as soon as the fold completes; with
``resume`` a re-run reads back every fold whose result was made from the same data
(content hashes of TRAIN, TEST and the calibration set), architecture, epochs, seed
and recipe, and trains only the others, so a killed run loses only the folds under
way. The key does not cover the training code: delete DIR/folds/ after changing it.
Pooled predictions go to DIR/predictions.npz; a final model trained on all
subjects to DIR/model.pt (its ``metrics`` are the LOSO figures).

``run_within`` (within-participant, Table 2.1): per subject, leave-one-trial-out
when the NPZ carries ``trial`` (train on the subject's other trials, score the
held-out trial's captures from TEST when given, else its training windows);
without ``trial``, stratified 5-fold cross-validation of the subject's
training windows. The dissertation used leave-one-out within each participant;
with a ~6-trial session, leaving out one trial is the cheaper analogue.

Folds run in ``jobs`` worker processes (one thread each); results do not
depend on ``jobs``: every fold is seeded with the same ``seed``.
"""
from __future__ import annotations

import hashlib
import json
import os
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context
from pathlib import Path

import numpy as np

from models.calibration import expected_calibration_error, temper
from models.dataset import DataError, WindowSet, load_npz
from models.evaluate import compute_metrics, predict, predict_steps, save_confusion_png
from models.train import (
    DEFAULT_EPOCHS,
    LDA_FEATURES,
    fit,
    is_main_process,
    preprocess_all,
    recipe_fit_kwargs,
    save_checkpoint,
)


def _json(path: Path, obj) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(obj, indent=2, allow_nan=True))


def _check_compatible(train: WindowSet, test: WindowSet | None) -> None:
    if test is not None and list(test.classes) != list(train.classes):
        raise DataError(f"{test.source}: field 'classes': {list(test.classes)} differs from the training "
                        f"set's {list(train.classes)} ({train.source})")


def _finish(out: Path, arch: str, classes, y_true, y_pred, probs, subject, extra: dict, title: str,
            repeat=None, step_probs=None) -> dict:
    """Metrics (every capture; onset captures; per step when ``step_probs`` (S, N, K) holds the
    early decisions, raw and temperature-scaled), metrics.json, confusion.png, predictions.npz."""
    m = compute_metrics(y_true, y_pred, classes, subject)
    m.update(arch=arch, **extra)
    y_true = np.asarray(y_true)
    if len(y_true) and np.asarray(probs).shape[1:] == (len(classes),):
        m["ece"] = expected_calibration_error(probs, y_true)
    on = None
    if repeat is not None and np.any(repeat):
        on = np.asarray(repeat) == 0  # one capture per truth event (+ false alarms): the dissertation's count
        m["onset_only"] = compute_metrics(y_true[on], np.asarray(y_pred)[on], classes, np.asarray(subject)[on])
        m["repeat_captures"] = int((~on).sum())
    if step_probs is not None:
        m["steps"] = _step_rows(step_probs, y_true, classes, on)
    if is_main_process():
        _json(out / "metrics.json", m)
        save_confusion_png(m["confusion"], classes, out / "confusion.png",
                           title=f"{title}: macro-F1 {m['macro_f1']:.3f}, acc {m['accuracy']:.3f}")
        extra_arrays = {} if step_probs is None else {
            "step_probs_raw": np.asarray(step_probs["raw"], np.float32),
            "step_probs": np.asarray(step_probs["calibrated"], np.float32)}
        np.savez_compressed(out / "predictions.npz", y_true=y_true, y_pred=np.asarray(y_pred),
                            probs=np.asarray(probs, dtype=np.float32), subject=np.asarray(subject),
                            classes=np.asarray(classes, dtype=str), **extra_arrays)
    return m


def _step_rows(step_probs: dict, y_true: np.ndarray, classes, onset: np.ndarray | None) -> list[dict]:
    """Per step S = 1..6: accuracy, macro-F1 and ECE over every capture (raw and with the fold's
    temperatures), and macro-F1 over onset captures."""
    rows = []
    for s, (raw, cal) in enumerate(zip(step_probs["raw"], step_probs["calibrated"]), start=1):
        mm = compute_metrics(y_true, cal.argmax(1), classes)
        row = {"steps": s, "accuracy": mm["accuracy"], "macro_f1": mm["macro_f1"],
               "ece_raw": expected_calibration_error(raw, y_true), "ece": expected_calibration_error(cal, y_true)}
        if onset is not None:
            row["onset_macro_f1"] = compute_metrics(y_true[onset], cal.argmax(1)[onset], classes)["macro_f1"]
        rows.append(row)
    return rows


def run_train_test(arch: str, train: WindowSet, test: WindowSet | None, out_dir, *, epochs: int | None = None,
                   seed: int = 0, progress: bool = True, threads: int | None = 1) -> dict:
    """Train on ``train``; score ``test`` (or the training set itself when no test set is given)."""
    _check_compatible(train, test)
    epochs = DEFAULT_EPOCHS[arch] if epochs is None else epochs
    out = Path(out_dir)
    k = len(train.classes)
    model = fit(arch, train.X, train.y, k, epochs=epochs, seed=seed, progress=progress, threads=threads)
    ev = test if test is not None else train
    probs = predict(model, ev.X)
    m = _finish(out, arch, train.classes, ev.y, probs.argmax(1), probs, ev.subject, repeat=ev.repeat,
                extra=
                {"protocol": "train/test" if test is not None else "training set (no --test)",
                 "epochs": epochs, "seed": seed, "n_train": len(train),
                 **({"ddp": model.ddp_info} if hasattr(model, "ddp_info") else {})},
                title=f"{arch} {'test' if test is not None else 'train'}")
    if is_main_process():
        save_checkpoint(out, model, arch=arch, classes=train.classes, seed=seed, epochs=epochs, metrics=_summary(m),
                        data={"train": train.source, "test": test.source if test is not None else None})
    return m


def _summary(m: dict) -> dict:
    keys = ("accuracy", "macro_f1", "macro_f1_distractions", "macro_precision", "macro_recall", "n", "protocol")
    return {k: m[k] for k in keys if k in m}


# --------------------------------------------------------------------------- fold workers

_CACHE: dict = {}
_TEST_CACHE: dict = {}


def _cached(ws_or_path):
    """(WindowSet, its preprocessed inputs or None): each process loads and preprocesses a set once."""
    key = ws_or_path if isinstance(ws_or_path, str) else id(ws_or_path)
    if key not in _CACHE:
        ws = ws_or_path if isinstance(ws_or_path, WindowSet) else load_npz(ws_or_path)
        _CACHE.clear()
        _CACHE[key] = (ws, None)
    return _CACHE[key]


def _inputs(key, arch):
    ws, pre = _CACHE[key]
    if pre is None and arch not in LDA_FEATURES:
        pre = preprocess_all(ws.X).numpy()
        _CACHE[key] = (ws, pre)
    return ws.X if arch in LDA_FEATURES else pre


def _load_test(test):
    """A test WindowSet (loaded once per worker when given as a path) and its preprocessed inputs."""
    if not isinstance(test, str):
        return test
    if _TEST_CACHE.get("path") != test:
        _TEST_CACHE.clear()
        _TEST_CACHE.update(path=test, ws=load_npz(test))
    return _TEST_CACHE["ws"]


_PRE_CACHE: dict = {}


def _model_inputs(ws: WindowSet, arch: str) -> np.ndarray:
    """What ``arch`` reads of every window of ``ws``: the raw windows for the LDAs, else the
    preprocessed inputs (N, 6, 33, 3), computed once per process and set (the test captures and
    the calibration cohort were preprocessed again in every fold). Preprocessing works window by
    window, so a row is the same whether it is computed alone or with the whole set."""
    if arch in LDA_FEATURES:
        return ws.X
    held = _PRE_CACHE.get(id(ws))
    if held is None or held[0] is not ws:  # an id can be reused once its set is freed
        held = _PRE_CACHE[id(ws)] = (ws, preprocess_all(ws.X).numpy())
    return held[1]


def _training_set(job: dict, train: WindowSet, key, test: WindowSet | None) -> tuple[np.ndarray, np.ndarray]:
    """The fold's training inputs: the other subjects' ground-truth windows, plus their detector
    captures when the recipe says so (``job["recipe"]["captures"]``)."""
    X, y = _inputs(key, job["arch"])[job["train_idx"]], train.y[job["train_idx"]]
    if not (job["recipe"].get("captures") and test is not None):
        return X, y
    c = np.flatnonzero(np.isin(test.subject, np.unique(train.subject[job["train_idx"]])))
    return np.concatenate([X, _model_inputs(test, job["arch"])[c]]), np.concatenate([y, test.y[c]])


def _calibrated_steps(model, ev_inputs: np.ndarray, calib) -> dict:
    """The ConvLSTM's decisions after 1..6 sub-windows on ``ev_inputs`` (S, N, K), raw and scaled by
    temperatures fitted on ``calib`` (the selection cohort's captures, never the held-out subject)."""
    from models.selection import calibrate_steps

    raw = predict_steps(model, ev_inputs)
    if calib is None:
        return {"raw": raw, "calibrated": raw, "calibration": None}
    cal_ws = _load_calib(calib)
    other = list(cal_ws.classes).index("Other")
    c = calibrate_steps(predict_steps(model, _model_inputs(cal_ws, "convlstm")), cal_ws.y, other)
    scaled = np.stack([temper(p, c["temperature_by_steps"][str(s)]) for s, p in enumerate(raw, start=1)])
    return {"raw": raw, "calibrated": scaled, "calibration": c}


_CALIB_CACHE: dict = {}


def _load_calib(calib):
    if isinstance(calib, WindowSet):
        return calib
    if _CALIB_CACHE.get("path") != calib:
        _CALIB_CACHE.update(path=calib, ws=load_npz(calib))
    return _CALIB_CACHE["ws"]


def _fold(job: dict) -> dict:
    """Train one fold and score it (runs in a worker process or inline); with a ``ckpt_dir``, its
    checkpoint and result are written there before it returns."""
    test = _load_test(job.get("test"))
    train, _ = _cached(job["train"])
    key = job["train"] if isinstance(job["train"], str) else id(job["train"])
    src = test if job["eval_from"] == "test" else train
    ev = src.subset(job["eval_idx"])
    job.setdefault("recipe", {})
    X, y = _training_set(job, train, key, test)
    model = fit(job["arch"], X, y, len(train.classes), epochs=job["epochs"], seed=job["seed"],
                progress=job["progress"], threads=job["threads"], desc=job["desc"],
                **recipe_fit_kwargs(job["recipe"]))
    ev_inputs = _model_inputs(src, job["arch"])[job["eval_idx"]]
    probs = predict(model, ev_inputs) if len(ev) else np.zeros((0, len(train.classes)))
    res = {"name": job["name"], "y_true": ev.y, "y_pred": probs.argmax(1) if len(ev) else ev.y[:0],
           "probs": probs, "subject": ev.subject,
           "repeat": ev.repeat if ev.repeat is not None else np.zeros(len(ev), np.int8)}
    if job["arch"] == "convlstm" and len(ev):
        res["steps"] = _calibrated_steps(model, ev_inputs, job.get("calib"))
    if job.get("ckpt_dir") and is_main_process():
        fm = compute_metrics(ev.y, res["y_pred"], train.classes) if len(ev) else {}
        save_checkpoint(job["ckpt_dir"], model, arch=job["arch"], classes=train.classes, seed=job["seed"],
                        epochs=job["epochs"], metrics={**_summary(fm), "fold": job["name"]},
                        data={"train": f"{train.source} minus {job['name']}",
                              "test": f"{(test or train).source} {job['name']}"})
        if job.get("key"):
            _save_fold(Path(job["ckpt_dir"]), res, job["key"])
    return res


# --------------------------------------------------------------------------- fold results on disk

_ARRAYS = ("y_true", "y_pred", "probs", "subject", "repeat")


def fingerprint(ws: WindowSet | None) -> str | None:
    """A content hash of a window set (windows, labels, subjects, repeat flags): a saved fold is
    reused only for the very data it was made from, whatever the file is called."""
    if ws is None:
        return None
    h = hashlib.sha256()
    for a in (ws.X, ws.y, ws.subject, ws.repeat):
        if a is not None:
            h.update(np.ascontiguousarray(a).tobytes())
    h.update(json.dumps(list(ws.classes)).encode())
    return h.hexdigest()[:16]


def _save_fold(d: Path, res: dict, key: dict) -> None:
    """folds/s<K>/result.npz + result.json; the JSON is written last (and both by rename), so a
    fold killed while writing is not taken for a completed one."""
    d.mkdir(parents=True, exist_ok=True)
    arrays = {k: np.asarray(res[k]) for k in _ARRAYS}
    if "steps" in res:
        arrays.update(step_raw=res["steps"]["raw"], step_calibrated=res["steps"]["calibrated"])
    tmp = d / "result.tmp.npz"
    np.savez_compressed(tmp, **arrays)
    os.replace(tmp, d / "result.npz")
    meta = {"name": res["name"], "key": key,
            "calibration": res["steps"]["calibration"] if "steps" in res else None}
    (d / "result.tmp.json").write_text(json.dumps(meta, indent=1, allow_nan=True))
    os.replace(d / "result.tmp.json", d / "result.json")


def _load_fold(d: Path, key: dict) -> dict | None:
    """The saved result of the fold in ``d`` when it was made with ``key``, else None."""
    try:
        meta = json.loads((d / "result.json").read_text())
    except (OSError, ValueError):
        return None
    if meta.get("key") != key:
        return None
    with np.load(d / "result.npz") as z:
        res = {k: z[k] for k in _ARRAYS}
        if "step_raw" in z.files:
            res["steps"] = {"raw": z["step_raw"], "calibrated": z["step_calibrated"],
                            "calibration": meta["calibration"]}
    res["name"] = meta["name"]
    return res


def _run_jobs(jobs: list[dict], n_workers: int) -> list[dict]:
    from tqdm import tqdm

    if n_workers <= 1 or len(jobs) <= 1:
        return [_fold(j) for j in jobs]
    with ProcessPoolExecutor(max_workers=n_workers, mp_context=get_context("spawn")) as ex:
        futs = [ex.submit(_fold, j) for j in jobs]
        out = []
        for f in tqdm(futs, desc=jobs[0]["arch"] + " folds", unit="fold", leave=False,
                      disable=not jobs[0]["progress_folds"]):
            out.append(f.result())
        return out


def _job_data(ws: WindowSet | None, n_workers: int):
    """Workers re-load the NPZ from disk (cheap) instead of receiving pickled arrays."""
    if ws is None:
        return None
    return ws.source if n_workers > 1 and ws.source and os.path.exists(ws.source) else ws


# --------------------------------------------------------------------------- LOSO

def run_loso(arch: str, train: WindowSet, test: WindowSet | None, out_dir, *, epochs: int | None = None,
             seed: int = 0, jobs: int = 1, progress: bool = True, final_model: bool = True,
             recipe: dict | None = None, calib: WindowSet | None = None, folds: int | None = None,
             resume: bool = False, train_missing: bool = True) -> dict:
    """One fold per subject (the first ``folds`` subjects only, when given). ``recipe``: the
    selection's choices (``captures``: the training subjects' detector captures join the training
    set; ``shift_fwd``; ``schedule_epochs``). ``calib``: validation captures (the selection cohort's)
    on which each ConvLSTM fold fits its per-step temperatures. ``resume``: read back the folds
    saved by an earlier run with the same data and recipe (see the module docstring);
    ``train_missing=False``: train none, pool only the saved folds (the metrics say which)."""
    _check_compatible(train, test)
    recipe = dict(recipe or {})
    epochs = DEFAULT_EPOCHS[arch] if epochs is None else epochs
    out = Path(out_dir)
    subjects = np.unique(train.subject)
    if len(subjects) < 2:
        raise DataError(f"{train.source}: field 'subject': leave-one-subject-out needs at least 2 subjects, "
                        f"got {len(subjects)}")
    from models.train import dist_info
    distributed = dist_info()[0]
    n_workers = 1 if distributed else max(1, jobs)
    # what a saved fold must have been made from to be reused (JSON round trip: as read back)
    key = json.loads(json.dumps({"arch": arch, "epochs": epochs, "seed": seed, "recipe": recipe,
                                 "train": fingerprint(train), "test": fingerprint(test),
                                 "calib": fingerprint(calib) if arch == "convlstm" else None}))
    job_list = []
    for s in subjects[:folds]:
        ev_idx = (np.flatnonzero(test.subject == s) if test is not None else np.flatnonzero(train.subject == s))
        job_list.append(dict(
            name=f"s{int(s)}", arch=arch, epochs=epochs, seed=seed, threads=1,
            train=_job_data(train, n_workers), test=_job_data(test, n_workers),
            train_idx=np.flatnonzero(train.subject != s), eval_idx=ev_idx,
            eval_from="test" if test is not None else "train",
            ckpt_dir=str(out / "folds" / f"s{int(s)}"), desc=f"{arch} LOSO s{int(s)}",
            progress=progress and n_workers == 1, progress_folds=progress, recipe=recipe,
            calib=_job_data(calib, n_workers), key={**key, "fold": f"s{int(s)}"}))
    saved = {j["name"]: _load_fold(Path(j["ckpt_dir"]), j["key"]) for j in job_list} if resume else {}
    reused = [n for n, r in saved.items() if r is not None]
    todo = [j for j in job_list if saved.get(j["name"]) is None] if train_missing else []
    trained = {r["name"]: r for r in _run_jobs(todo, n_workers)} if todo else {}
    results = [saved.get(j["name"]) or trained[j["name"]] for j in job_list
               if saved.get(j["name"]) is not None or j["name"] in trained]
    if not results:
        raise DataError(f"{out / 'folds'}: no saved {arch} fold matches this data and recipe (nothing to report)")
    cat = lambda key: np.concatenate([r[key] for r in results])  # noqa: E731
    with_steps = all("steps" in r for r in results) and results
    steps = None if not with_steps else {
        k: np.concatenate([r["steps"][k] for r in results], axis=1) for k in ("raw", "calibrated")}
    m = _finish(out, arch, train.classes, cat("y_true"), cat("y_pred"), cat("probs"), cat("subject"),
                {"protocol": "leave-one-subject-out", "evaluated_on": "test captures" if test is not None
                 else "held-out training windows", "folds": [r["name"] for r in results],
                 "all_folds": len(results) == len(subjects), "subjects_total": int(len(subjects)),
                 "folds_reused": reused,
                 "epochs": epochs, "seed": seed, "train": train.source,
                 "test": test.source if test is not None else None,
                 "recipe": recipe, **({"calibration_per_fold": {r["name"]: r["steps"]["calibration"]
                                                                for r in results}} if with_steps else {})},
                f"{arch} LOSO", repeat=cat("repeat"), step_probs=steps)
    if final_model:
        _cached(train)
        job = {"arch": arch, "train_idx": np.arange(len(train)), "recipe": recipe}
        X, y = _training_set(job, train, id(train), test)
        model = fit(arch, X, y, len(train.classes), epochs=epochs, seed=seed, progress=progress,
                    desc=f"{arch} final", **recipe_fit_kwargs(recipe))
        if is_main_process():
            save_checkpoint(out, model, arch=arch, classes=train.classes, seed=seed, epochs=epochs,
                            metrics=_summary(m) | {"per_subject_mean": m.get("per_subject_mean")},
                            data={"train": train.source, "test": test.source if test is not None else None,
                                  "protocol": "final model on all subjects; metrics = LOSO"})
    return m


# --------------------------------------------------------------------------- within-subject

def run_within(arch: str, train: WindowSet, test: WindowSet | None, out_dir, *, epochs: int | None = None,
               seed: int = 0, jobs: int = 1, progress: bool = True, min_train: int = 5) -> dict:
    _check_compatible(train, test)
    from sklearn.model_selection import StratifiedKFold

    epochs = DEFAULT_EPOCHS[arch] if epochs is None else epochs
    out = Path(out_dir)
    n_workers = max(1, jobs)
    by_trial = train.trial is not None and (test is None or test.trial is not None)
    job_list = []
    for s in np.unique(train.subject):
        own = np.flatnonzero(train.subject == s)
        if by_trial:
            for t in np.unique(train.trial[own]):
                tr_idx = own[train.trial[own] != t]
                if test is not None:
                    ev_idx = np.flatnonzero((test.subject == s) & (test.trial == t))
                else:
                    ev_idx = own[train.trial[own] == t]
                if len(tr_idx) >= min_train and len(ev_idx):
                    job_list.append((f"s{int(s)}-{t}", tr_idx, ev_idx, "test" if test is not None else "train"))
        else:
            counts = np.bincount(train.y[own])
            k = int(min(5, counts[counts > 0].min())) if len(own) else 0
            if k < 2:
                continue
            skf = StratifiedKFold(n_splits=k, shuffle=True, random_state=seed)
            for f, (a, b) in enumerate(skf.split(own, train.y[own])):
                job_list.append((f"s{int(s)}-f{f}", own[a], own[b], "train"))
    if not job_list:
        raise DataError(f"{train.source}: field 'subject': no subject has enough windows for within-subject folds")
    jobs_ = [dict(name=name, arch=arch, epochs=epochs, seed=seed, threads=1,
                  train=_job_data(train, n_workers), test=_job_data(test, n_workers),
                  train_idx=tr, eval_idx=ev, eval_from=src, ckpt_dir=None, desc=f"{arch} within {name}",
                  progress=False, progress_folds=progress)
             for name, tr, ev, src in job_list]
    results = _run_jobs(jobs_, n_workers)
    cat = lambda key: np.concatenate([r[key] for r in results])  # noqa: E731
    return _finish(out, arch, train.classes, cat("y_true"), cat("y_pred"), cat("probs"), cat("subject"),
                   {"protocol": "within-subject " + ("leave-one-trial-out" if by_trial else "stratified 5-fold"),
                    "folds": len(results), "epochs": epochs, "seed": seed, "train": train.source,
                    "test": test.source if test is not None else None},
                   f"{arch} within-subject", repeat=cat("repeat"))
