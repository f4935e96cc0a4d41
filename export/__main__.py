"""python -m export {onnx,quantize,assets,compare-int8} ...

  onnx          --checkpoint DIR/model.pt --out F.onnx [--opset 17]
                torch checkpoint -> ONNX (input imu (N,6,33,3) m/s^2, outputs probs, logits), parity checked
  quantize      --onnx F.onnx --calib WINDOWS.npz --out F.int8.onnx [--variants a,b,...] [--json REPORT.json]
                int8 via onnxruntime.quantization; the fastest variant (1 thread) that keeps fp32's predictions
  assets        --seed S [--subjects 20] [--epochs 40] [--minutes 15] [--out edge_runtime/assets]
                [--train TRAIN.npz --test TEST.npz] [--loso-dir DIR | --no-loso] [--work DIR]
                simulate, train the ConvLSTM, export fp32 + int8, score, write manifest.json
  int8          [--variants a,b,...] [--assets DIR] [--train TRAIN.npz --test TEST.npz] [--loso-dir DIR] [--work DIR]
                the shipped fp32 ConvLSTM quantised again (no training): recipe chosen and gated as `assets` does
  step          --checkpoint DIR/model.pt [--assets DIR] [--train TRAIN.npz --test TEST.npz] [--work DIR]
                the shipped ConvLSTM's streaming step model (one sub-window + LSTM state per run), fp32 + int8,
                added to the assets (what `assets` does as its step 7; the one-shot files untouched)
  stream        --checkpoint DIR/model.pt [--assets DIR] [--work DIR] | --figures A/drive_eval.json,B/... [--assets DIR]
                the streaming classifier (python -m models stream-train) -> stream.fp32.onnx, stream.int8.onnx and
                their manifest entries (other entries untouched); --figures: add drive-eval's stream figures to
                the entry of the model that made them
  opsets        [--assets DIR]
                every shipped model declares only the opset domains its nodes use; manifest sha256 updated
  sign          --keygen DIR | --key PRIVATE.pem [--assets DIR]
                an Ed25519 signature of manifest.json (manifest.json.sig), or a new key pair
  compare-int8  --loso-dir DIR [--method NAME] [--train TRAIN.npz] [--test TEST.npz] [--json OUT.json]
                per LOSO fold (DIR/folds/*/model.pt): fp32 vs int8 on the held-out subject; pooled macro-F1

Bad input exits with status 2 and one line on stderr naming the file and field.
"""
from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from edge_runtime.cli import add_module_commands, make_parser, run


def _parser() -> argparse.ArgumentParser:
    p, sub = make_parser("python -m export", "torch checkpoints -> ONNX, int8 ONNX and the shipped assets.")

    o = sub.add_parser("onnx", help="export a checkpoint to ONNX")
    o.add_argument("--checkpoint", required=True, help="DIR/model.pt written by python -m models train")
    o.add_argument("--out", required=True, help="output .onnx")
    o.add_argument("--opset", type=int, default=17)

    q = sub.add_parser("quantize", help="int8 ONNX, calibrated on capture windows")
    q.add_argument("--onnx", required=True, help="fp32 .onnx from `python -m export onnx`")
    q.add_argument("--calib", required=True, help="dataset NPZ of capture windows (X (N,700,3), y, subject, classes)")
    q.add_argument("--out", required=True, help="output int8 .onnx")
    q.add_argument("--variants", default=None, help="comma-separated candidates (default: all)")
    q.add_argument("--calib-windows", type=int, default=1000)
    q.add_argument("--json", default=None, help="write the quantisation report here")

    a = sub.add_parser("assets", help="rebuild edge_runtime/assets from a seed")
    a.add_argument("--seed", type=int, required=True)
    a.add_argument("--subjects", type=int, default=20)
    a.add_argument("--epochs", type=int, default=None, help="default: the epochs chosen in selection.json")
    a.add_argument("--checkpoint", default=None, help="reuse the model.pt an earlier run wrote (WORK/convlstm) "
                                                      "instead of training again (deterministic: same weights)")
    a.add_argument("--selection", default=None, help="the training recipe and calibration cohort "
                                                     "(default: reports/wearable/selection/selection.json)")
    a.add_argument("--minutes", type=float, default=15.0, help="minutes per simulated trial")
    a.add_argument("--out", default=None, help="assets directory (default: edge_runtime/assets)")
    a.add_argument("--work", default=None, help="scratch directory (default: runs/assets-seed<S>)")
    a.add_argument("--train", default=None, help="use this training NPZ instead of simulating")
    a.add_argument("--test", default=None, help="use this test NPZ instead of simulating")
    a.add_argument("--loso-dir", default=None, help="also report LOSO fp32 vs int8 over this "
                                                    "`python -m models train --loso` directory")
    a.add_argument("--no-loso", action="store_true", help="do not look for reports/wearable/convlstm/loso")
    a.add_argument("--variants", default=None, help="comma-separated quantisation candidates (default: all)")
    a.add_argument("--no-progress", action="store_true")

    i = sub.add_parser("int8", help="quantise the shipped fp32 ConvLSTM again (no training)")
    i.add_argument("--variants", default=None, help="comma-separated quantisation candidates (default: all)")
    i.add_argument("--loso-dir", default=None, help="also compare fp32 and int8 over these LOSO folds")
    _shipped_model_args(i)

    t = sub.add_parser("step", help="add the shipped ConvLSTM's streaming step model (fp32, int8) to the assets")
    t.add_argument("--checkpoint", required=True, help="the model.pt the shipped ConvLSTM was exported from")
    t.add_argument("--selection", default=None, help="the selection cohort whose captures gate the int8 step "
                                                     "recipe (default: reports/wearable/selection/selection.json)")
    _shipped_model_args(t)

    st = sub.add_parser("stream", help="the streaming classifier's fp32 and int8 models into the assets")
    what = st.add_mutually_exclusive_group(required=True)
    what.add_argument("--checkpoint", help="DIR/model.pt written by python -m models stream-train")
    what.add_argument("--figures", help="comma-separated drive_eval.json of firmware_sim drive-eval --decision stream")
    st.add_argument("--assets", default=None, help="assets directory (default: edge_runtime/assets)")
    st.add_argument("--work", default=None, help="scratch directory (default: the system's temporary one)")

    f = sub.add_parser("schedule", help="write the vehicle DBC's frame schedule beside it (after a change of the DBC)")
    f.add_argument("--assets", default=None, help="assets directory (default: edge_runtime/assets)")

    s = sub.add_parser("opsets", help="declare only the opset domains each shipped model uses")
    s.add_argument("--assets", default=None, help="assets directory (default: edge_runtime/assets)")

    c = sub.add_parser("compare-int8", help="LOSO folds: fp32 vs int8 macro-F1 on held-out subjects")
    c.add_argument("--loso-dir", required=True)
    c.add_argument("--method", default=None, help="quantisation variant (default: the shipped model's)")
    c.add_argument("--train", default=None, help="training NPZ (default: from DIR/metrics.json)")
    c.add_argument("--test", default=None, help="test NPZ (default: from DIR/metrics.json)")
    c.add_argument("--json", default=None)

    add_module_commands(sub, __package__, _MODULE_COMMANDS)
    return p


# Commands that live in their own module: each module defines ``add_arguments(parser)`` and ``cmd(args)``.
_MODULE_COMMANDS = (
    ("lifter", "lifter_assets", "train, export and quantise the pose lifter into edge_runtime/assets"),
    ("lifter-int8", "lifter_int8", "quantise the shipped fp32 pose lifter again (no training), optionally with "
                                   "its input centering folded, into a scratch directory"),
    ("bundle", "bundle", "build what goes onto a box: runtime wheel, assets, default config, checksums"),
    ("sign", "sign", "sign the manifest with Ed25519 (or make a key pair): a box then refuses other models"),
)


def _shipped_model_args(p: argparse.ArgumentParser) -> None:
    """The options of a command that works on the shipped fp32 ConvLSTM and its cohort's windows."""
    p.add_argument("--assets", default=None, help="assets directory (default: edge_runtime/assets)")
    p.add_argument("--train", default=None, help="calibration windows NPZ instead of the fp32 entry's simulated cohort")
    p.add_argument("--test", default=None, help="gate windows NPZ instead of the fp32 entry's simulated cohort")
    p.add_argument("--work", default=None, help="scratch directory (default: runs/assets-seed<S>)")


def _variants(s: str | None):
    return [v.strip() for v in s.split(",") if v.strip()] if s else None


def _check_onnx_file(path: str) -> None:
    from export.onnx_export import ExportError

    p = Path(path)
    if not p.is_file():
        raise ExportError(f"{p}: file not found")
    import onnx

    try:
        m = onnx.load(str(p))
    except Exception as e:
        raise ExportError(f"{p}: not a readable ONNX model ({type(e).__name__})") from None
    names = [i.name for i in m.graph.input]
    if "imu" not in names:
        raise ExportError(f"{p}: field 'graph.input': expected an input named 'imu', got {names}")
    if "probs" not in [o.name for o in m.graph.output]:
        raise ExportError(f"{p}: field 'graph.output': expected an output named 'probs'")


def cmd_onnx(a) -> int:
    from export.onnx_export import export_checkpoint

    r = export_checkpoint(a.checkpoint, a.out, opset=a.opset)
    par = r["parity"]
    print(f"{r['path']}: {r['meta'].get('arch')} opset {a.opset}, ops {r['ops']}; parity with torch "
          f"max |d| logits {par['max_abs_logits']:.2e} probs {par['max_abs_probs']:.2e}")
    return 0


def cmd_quantize(a) -> int:
    from export.onnx_export import ExportError
    from export.quantize import quantize_file

    _check_onnx_file(a.onnx)
    if a.calib_windows < 1:
        raise ExportError(f"--calib-windows: must be at least 1, got {a.calib_windows}")
    rep = quantize_file(a.onnx, a.calib, a.out, n_calib=a.calib_windows, variants=_variants(a.variants), log=print)
    print(f"{a.out}: {rep['method']} ({rep['description']}); int8 operators {rep['int8_operators']}, "
          f"fp32 {rep['fp32_operators']}; agreement with fp32 {rep['agreement_with_fp32']:.4f}")
    if a.json:
        Path(a.json).parent.mkdir(parents=True, exist_ok=True)
        Path(a.json).write_text(json.dumps(rep, indent=2))
    return 0


def cmd_assets(a) -> int:
    from export.assets import DEFAULT_ASSETS, build_assets

    build_assets(seed=a.seed, subjects=a.subjects, epochs=a.epochs, minutes=a.minutes,
                 out=a.out or DEFAULT_ASSETS, work=a.work, train_npz=a.train, test_npz=a.test,
                 loso_dir=a.loso_dir, variants=_variants(a.variants), progress=not a.no_progress,
                 auto_loso=not a.no_loso, selection=a.selection, checkpoint=a.checkpoint)
    out = Path(a.out or DEFAULT_ASSETS)
    if (out / "vehicle_alerts.dbc").exists():  # the assets the runtime ships: their DBC's schedule, fresh
        write_schedule(out)
    return 0


def cmd_schedule(a) -> int:
    path = write_schedule(Path(a.assets) if a.assets else None)
    print(f"wrote {path}")
    return 0


def write_schedule(assets: Path | None = None) -> Path:
    """The frame schedule the runtime keeps beside the vehicle DBC, written from the DBC in ``assets``."""
    from edge_runtime.wearable.alerts import DBC_PATH, DBC_SCHEDULE_PATH, write_frame_schedule

    assets = assets or DBC_PATH.parent
    return write_frame_schedule(assets / DBC_PATH.name, assets / DBC_SCHEDULE_PATH.name)


def cmd_int8(a) -> int:
    from export.assets import DEFAULT_ASSETS, requantize

    requantize(out=a.assets or DEFAULT_ASSETS, work=a.work, train_npz=a.train, test_npz=a.test,
               variants=_variants(a.variants), loso_dir=a.loso_dir)
    return 0


def cmd_step(a) -> int:
    from export.assets import DEFAULT_ASSETS, add_step_models

    add_step_models(checkpoint=a.checkpoint, out=a.assets or DEFAULT_ASSETS, work=a.work, train_npz=a.train,
                    test_npz=a.test, selection=a.selection)
    return 0


def cmd_stream(a) -> int:
    from edge_runtime.core.manifest import ASSETS_DIR
    from export.stream_model import add_figures, build_stream_assets

    if a.figures:
        add_figures(a.assets or ASSETS_DIR, [p.strip() for p in a.figures.split(",") if p.strip()])
    else:
        build_stream_assets(a.checkpoint, a.assets or ASSETS_DIR, work=a.work)
    return 0


def cmd_opsets(a) -> int:
    from edge_runtime.core.manifest import ASSETS_DIR
    from export.opsets import apply_to_assets

    changed = apply_to_assets(a.assets or ASSETS_DIR)
    print(f"rewrote {', '.join(changed)}" if changed else "every model already declares only the domains it uses")
    return 0


def cmd_compare(a) -> int:
    from export.assets import compare_int8

    r = compare_int8(a.loso_dir, method=a.method, train_npz=a.train, test_npz=a.test, log=print)
    print(f"LOSO over {r['folds']} folds, {r['n']} windows ({r['method']}): macro-F1 fp32 {r['fp32_macro_f1']:.4f}, "
          f"int8 {r['int8_macro_f1']:.4f}, difference {r['macro_f1_delta']:+.4f} "
          f"({'within' if r['holds'] else 'OUTSIDE'} 0.01); argmax agreement {r['agreement']:.4f}")
    if a.json:
        Path(a.json).parent.mkdir(parents=True, exist_ok=True)
        Path(a.json).write_text(json.dumps(r, indent=2))
    return 0 if r["holds"] else 1


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    from edge_runtime.core.manifest import ModelIntegrityError

    cmds = {"onnx": cmd_onnx, "quantize": cmd_quantize, "assets": cmd_assets, "int8": cmd_int8, "step": cmd_step, "stream": cmd_stream, "opsets": cmd_opsets,
            "schedule": cmd_schedule,
            "compare-int8": cmd_compare}
    func = getattr(args, "func", None) or cmds[args.command]
    # ExportError, QuantizeError and DataError are ValueErrors: naming them here would import
    # torch and onnx, which `export bundle` on an install without the train extra does not have.
    return run(lambda: func(args),
               bad_input=(ModelIntegrityError, OSError, ValueError, KeyError,
                          *getattr(args, "bad_input", ())),
               what=f"export {args.command}", extra="train")


if __name__ == "__main__":
    sys.exit(main())
