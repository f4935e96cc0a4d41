"""python -m models {train,evaluate,import,report} ...

  train     --arch {convlstm,cnn,lstm,lda} --data TRAIN.npz [--test TEST.npz | --loso] [--within]
            --out DIR [--epochs N] [--seed S] [--jobs J]
            -> DIR/metrics.json, DIR/model.pt (model.pkl for lda), DIR/confusion.png
               --loso: one fold per subject (DIR/folds/s<K>/), scored on --test captures when given
               --within: within-subject folds (DIR/within/ when combined with --loso/--test)
            Data parallel: torchrun --nproc_per_node=2 -m models train ...
  stream-train  --out DIR [--width 64] [--epochs 16] [--seed 0] [--subjects 20] [--cohort-seed 0[,1...]] [--minutes 15]
                [--sampling s21|hard|hard2]
            -> DIR/model.pt: the trigger-free streaming classifier (models/stream_train.py), trained on the
               simulated cohort's continuous streams; deterministic for a seed (one thread)
  evaluate  --checkpoint DIR/model.pt --data TEST.npz --out DIR2
  import    --csv REC.csv --events EVENTS.csv|truth.json --subject K --out OUT.npz [--split train|test]
            [--classes A,B,...] [--append]
  select    --out reports/wearable/selection --seed 0 [--subjects 12] [--minutes 10] [--epochs 24] [--jobs 2]
            -> the training recipe chosen on a separate simulated cohort (models/selection.py)
            [--stage early]: then the step-loss weights for early decisions, on top of stage 1's recipe
            [--stage loss]: then label smoothing / focal term / rotation, cross-validated (stage 3)
  report    --out reports/wearable --seed 0 [--subjects 20] [--epochs N] [--archs convlstm,cnn,lstm,lda]
            [--data TRAIN.npz --test TEST.npz] [--minutes 15] [--jobs 2] [--no-within] [--reuse | --reuse-only]

Bad input exits with status 2 and one line on stderr naming the file and field.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from edge_runtime.cli import make_parser, run

ARCH_CHOICES = ("convlstm", "cnn", "lstm", "lda", "lda_summary")


def _parser() -> argparse.ArgumentParser:
    p, sub = make_parser("python -m models", "Train, evaluate and report the wearable classifiers.")

    t = sub.add_parser("train", help="train one architecture; train/test, LOSO or within-subject")
    t.add_argument("--arch", required=True, choices=ARCH_CHOICES)
    t.add_argument("--data", required=True, help="training NPZ (ground-truth windows)")
    t.add_argument("--test", help="test NPZ (detector captures)")
    t.add_argument("--loso", action="store_true", help="leave-one-subject-out (uses --test for the held-out "
                                                       "subject's captures when given)")
    t.add_argument("--within", action="store_true", help="within-subject folds (leave-one-trial-out, or "
                                                         "stratified 5-fold when the NPZ has no 'trial')")
    t.add_argument("--out", required=True)
    t.add_argument("--epochs", type=int, default=None, help="default: 40 (neural), 0 (lda)")
    t.add_argument("--seed", type=int, default=0)
    t.add_argument("--jobs", type=int, default=1, help="fold worker processes for --loso/--within")
    t.add_argument("--threads", type=int, default=1, help="torch intra-op threads (train/test mode)")
    t.add_argument("--no-progress", action="store_true")

    st = sub.add_parser("stream-train", help="train the trigger-free streaming classifier on the cohort's streams")
    st.add_argument("--out", required=True, help="directory for model.pt")
    st.add_argument("--width", type=int, default=64, help="channels of the first conv layer (default 64: m64)")
    st.add_argument("--epochs", type=int, default=16)
    st.add_argument("--seed", type=int, default=0, help="training seed (initialisation, sampling, augmentation)")
    st.add_argument("--subjects", type=int, default=20)
    st.add_argument("--cohort-seed", default="0",
                    help="the simulated cohort (0: what the ConvLSTM trains on); comma-separated: several cohorts")
    st.add_argument("--minutes", type=float, default=15.0, help="minutes per simulated trial")
    st.add_argument("--sampling", default="s21",
                    help="window-end draw: s21 (default), hard or hard2 (models/stream_train.py)")

    e = sub.add_parser("evaluate", help="score a checkpoint on an NPZ")
    e.add_argument("--checkpoint", required=True)
    e.add_argument("--data", required=True)
    e.add_argument("--out", required=True)

    i = sub.add_parser("import", help="recording CSV + event list -> dataset NPZ via the detector")
    i.add_argument("--csv", required=True)
    i.add_argument("--events", required=True)
    i.add_argument("--subject", required=True, type=int)
    i.add_argument("--out", required=True)
    i.add_argument("--split", choices=("train", "test"), default="test")
    i.add_argument("--classes", default=None, help="comma-separated class names (default: the six)")
    i.add_argument("--trial", default="", help="trial name stored per window (default: CSV file stem)")
    i.add_argument("--append", action="store_true", help="add to OUT if it exists")

    c = sub.add_parser("select", help="choose the training recipe on a separate simulated cohort")
    c.add_argument("--out", default="reports/wearable/selection")
    c.add_argument("--seed", type=int, default=0, help="the reported cohort's seed (the selection cohort's is +1000)")
    c.add_argument("--subjects", type=int, default=12)
    c.add_argument("--minutes", type=float, default=10.0)
    c.add_argument("--epochs", type=int, default=24, help="the longest candidate run (checkpoints every 3 epochs)")
    c.add_argument("--train-subjects", type=int, default=8, help="selection subjects that train; the rest validate")
    c.add_argument("--jobs", type=int, default=2)
    c.add_argument("--stage", choices=("recipe", "early", "loss", "loss2"), default="recipe",
                   help="recipe: captures, time shift, epochs (stage 1); early: the step-loss weights on top of "
                        "OUT/selection.json's stage 1 (models/selection.py, EARLY_RULE); loss: label smoothing, focal "
                        "term, rotation, cross-validated over the whole cohort (LOSS_RULE); loss2: its round 2 (time warp)")

    r = sub.add_parser("report", help="simulate the cohort, LOSO + within for every arch, tables")
    r.add_argument("--out", default="reports/wearable")
    r.add_argument("--seed", type=int, default=0)
    r.add_argument("--subjects", type=int, default=20)
    r.add_argument("--minutes", type=float, default=15.0, help="minutes per simulated trial")
    r.add_argument("--epochs", type=int, default=None)
    r.add_argument("--archs", default=",".join(ARCH_CHOICES))
    r.add_argument("--data", default=None)
    r.add_argument("--test", default=None)
    r.add_argument("--jobs", type=int, default=2)
    r.add_argument("--no-within", action="store_true")
    r.add_argument("--folds", type=int, default=None, help="hold out only the first N subjects (default: all)")
    r.add_argument("--selection", default=None, help="selection.json (default: reports/wearable/selection/)")
    r.add_argument("--reuse", action="store_true", help="read back the LOSO folds already saved in --out from the "
                                                        "same data and recipe; train only the missing ones")
    r.add_argument("--reuse-only", action="store_true", help="like --reuse, but train no fold: report the saved "
                                                             "folds (the report says how many each figure covers)")
    r.add_argument("--no-progress", action="store_true")
    return p


def _print_metrics(m: dict, label: str) -> None:
    line = f"{label}: macro-F1 {m['macro_f1']:.3f}, accuracy {m['accuracy']:.3f}, n {m['n']}"
    if "per_subject_mean" in m and m["per_subject_mean"]:
        line += f", mean per-subject F1 {m['per_subject_mean']['f1']:.3f}"
    print(line)


def cmd_train(a) -> int:
    from models.dataset import DataError, load_npz

    train = load_npz(a.data)  # validate the inputs before importing torch: bad input fails fast
    test = load_npz(a.test) if a.test else None
    if a.epochs is not None and a.epochs < 0:
        raise DataError(f"--epochs: must be >= 0, got {a.epochs}")
    if test is not None and list(test.classes) != list(train.classes):
        raise DataError(f"{test.source}: field 'classes': {list(test.classes)} differs from the training "
                        f"set's {list(train.classes)} ({train.source})")
    from models.experiments import run_loso, run_train_test, run_within
    from models.train import init_distributed_from_env, is_main_process
    started = init_distributed_from_env()
    try:
        out = Path(a.out)
        progress = not a.no_progress
        if a.loso:
            m = run_loso(a.arch, train, test, out, epochs=a.epochs, seed=a.seed, jobs=a.jobs, progress=progress)
            if is_main_process():
                _print_metrics(m, f"{a.arch} LOSO")
            if a.within:
                w = run_within(a.arch, train, test, out / "within", epochs=a.epochs, seed=a.seed, jobs=a.jobs,
                               progress=progress)
                if is_main_process():
                    _print_metrics(w, f"{a.arch} within")
        elif a.within:
            m = run_within(a.arch, train, test, out, epochs=a.epochs, seed=a.seed, jobs=a.jobs, progress=progress)
            if is_main_process():
                _print_metrics(m, f"{a.arch} within")
            from models.train import DEFAULT_EPOCHS, fit, save_checkpoint
            ep = DEFAULT_EPOCHS[a.arch] if a.epochs is None else a.epochs
            model = fit(a.arch, train.X, train.y, len(train.classes), epochs=ep, seed=a.seed, progress=progress)
            if is_main_process():
                save_checkpoint(out, model, arch=a.arch, classes=train.classes, seed=a.seed, epochs=ep,
                                metrics={k: m[k] for k in ("accuracy", "macro_f1", "protocol")},
                                data={"train": train.source, "test": test.source if test else None})
        else:
            m = run_train_test(a.arch, train, test, out, epochs=a.epochs, seed=a.seed, progress=progress,
                               threads=a.threads)
            if is_main_process():
                _print_metrics(m, f"{a.arch} {'test' if test else 'train (no --test given)'}")
        if is_main_process():
            print(f"wrote {out / 'metrics.json'}")
    finally:
        if started:
            import torch.distributed as dist
            dist.barrier()
            dist.destroy_process_group()
    return 0


def cmd_stream_train(a) -> int:
    from models.dataset import DataError

    for name, v in (("--width", a.width), ("--epochs", a.epochs), ("--subjects", a.subjects)):
        if v < 1:
            raise DataError(f"{name}: must be >= 1, got {v}")
    if not a.minutes > 0:
        raise DataError(f"--minutes: must be > 0, got {a.minutes}")
    from models.stream_train import SAMPLINGS, train_stream

    if a.sampling not in SAMPLINGS:
        raise DataError(f"--sampling: one of {', '.join(SAMPLINGS)}, got {a.sampling!r}")
    try:
        seeds = tuple(int(v) for v in a.cohort_seed.split(","))
    except ValueError:
        raise DataError(f"--cohort-seed: integers separated by commas, got {a.cohort_seed!r}") from None
    if any(s < 0 for s in seeds) or len(set(seeds)) != len(seeds):
        raise DataError(f"--cohort-seed: distinct seeds >= 0, got {a.cohort_seed!r}")
    path = train_stream(a.out, width=a.width, epochs=a.epochs, seed=a.seed, subjects=a.subjects,
                        cohort_seed=seeds[0] if len(seeds) == 1 else seeds, minutes=a.minutes, sampling=a.sampling,
                        log=lambda line: print(line, flush=True))
    print(f"wrote {path}")
    return 0


def cmd_evaluate(a) -> int:
    from models.dataset import DataError, load_npz

    ws = load_npz(a.data)
    if not Path(a.checkpoint).exists():
        raise DataError(f"{a.checkpoint}: checkpoint not found")
    from models.evaluate import compute_metrics, predict, save_confusion_png
    from models.train import load_checkpoint
    model, meta = load_checkpoint(a.checkpoint)
    if list(meta["classes"]) != list(ws.classes):
        raise DataError(f"{a.data}: field 'classes': {ws.classes} differs from the checkpoint's {meta['classes']}")
    probs = predict(model, ws.X)
    m = compute_metrics(ws.y, probs.argmax(1), ws.classes, ws.subject)
    m.update(checkpoint=str(a.checkpoint), data=a.data, arch=meta["arch"])
    out = Path(a.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "metrics.json").write_text(json.dumps(m, indent=2))
    save_confusion_png(m["confusion"], ws.classes, out / "confusion.png", title=f"{meta['arch']} {a.data}")
    _print_metrics(m, f"{meta['arch']} on {a.data}")
    return 0


def cmd_import(a) -> int:
    from edge_runtime.wearable.labels import CLASSES
    from models.importer import import_to_npz

    classes = [c.strip() for c in a.classes.split(",") if c.strip()] if a.classes else list(CLASSES)
    info = import_to_npz(a.csv, a.events, a.subject, a.out, split=a.split, classes=classes, append=a.append,
                         trial=a.trial)
    note = f" (resampled from {info['rate_hz']:.1f} Hz to 100 Hz)" if info["resampled"] else ""
    det = info["detector"]
    print(f"{a.out}: {info['windows']} {a.split} windows from {a.csv}{note}; {info['total_windows']} in file; "
          f"counts {info['counts']}; detector recall {det['recall']:.2f} precision {det['precision']:.2f}")
    return 0


def cmd_select(a) -> int:
    from models.dataset import DataError
    from models.selection import run_early_selection, run_loss_selection, run_selection

    if a.stage != "recipe":  # a later stage, on top of OUT/selection.json
        if a.stage == "early":
            run_early_selection(a.out, jobs=a.jobs)
        else:
            run_loss_selection(a.out, jobs=a.jobs, stage=a.stage)
        print(f"wrote {Path(a.out) / 'selection.json'}")
        return 0
    if a.subjects < 2 or not (1 <= a.train_subjects < a.subjects):
        raise DataError(f"--train-subjects: must be between 1 and --subjects - 1 ({a.subjects - 1}), got {a.train_subjects}")
    if a.epochs < 1:
        raise DataError(f"--epochs: must be >= 1, got {a.epochs}")
    run_selection(a.out, seed=a.seed, subjects=a.subjects, minutes=a.minutes, epochs=a.epochs,
                  n_train=a.train_subjects, jobs=a.jobs)
    print(f"wrote {Path(a.out) / 'selection.json'}")
    return 0


def cmd_report(a) -> int:
    from models.dataset import DataError
    from models.report import run_report

    archs = [x.strip() for x in a.archs.split(",") if x.strip()]
    bad = [x for x in archs if x not in ARCH_CHOICES]
    if bad or not archs:
        raise DataError(f"--archs: unknown architecture(s) {bad}; choose from {','.join(ARCH_CHOICES)}")
    if (a.data is None) != (a.test is None) and a.data is None:
        raise DataError("--test: given without --data")
    s = run_report(a.out, seed=a.seed, subjects=a.subjects, epochs=a.epochs, archs=archs, data=a.data,
                   test=a.test, minutes=a.minutes, jobs=a.jobs, within=not a.no_within, reuse=a.reuse,
                   progress=not a.no_progress, folds=a.folds, selection=a.selection, reuse_only=a.reuse_only)
    for arch, m in s["loso"].items():
        print(f"{arch:>8} LOSO macro-F1 {m['macro_f1']:.3f}"
              + (f"  within {s['within'][arch]['macro_f1']:.3f}" if arch in s["within"] else ""))
    if s["detector"]:
        print(f"detector recall {s['detector']['recall']:.3f} precision {s['detector']['precision']:.3f}")
    print(f"wrote {Path(a.out) / 'report.md'}")
    return 0


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    from models.dataset import DataError

    cmds = {"train": cmd_train, "stream-train": cmd_stream_train, "evaluate": cmd_evaluate, "import": cmd_import, "select": cmd_select,
            "report": cmd_report}
    # DataError names the file and field; OSError/ValueError: unreadable file, unwritable --out, ...
    return run(lambda: cmds[args.command](args), bad_input=(DataError, OSError, ValueError),
               what=f"models {args.command}", extra="train")


if __name__ == "__main__":
    sys.exit(main())
