"""``python -m export lifter``: simulate, train, evaluate, export and ship the pose lifter.

    python -m export lifter --seed S [--channels 256] [--sweep 256,512,1024] [--epochs N]
                            [--out edge_runtime/assets] [--report reports/lifter] [--work runs/lifter-seed<S>]

1. Simulate the data (:func:`models.pose_data.build_splits`): train subjects x train camera
   placements; held-out subjects (``test_subjects``) and held-out subjects x held-out
   placements (``test``).
2. For the shipped size first, then every other size of ``--sweep``: train
   (:func:`models.lifter_train.fit`; a checkpoint in the work directory is reused with
   ``--reuse`` when its settings match), evaluate in torch on both held-out splits.
3. Export the strided model to ONNX (opset 17; input ``keypoints_2d`` (N, 27, 17, 2),
   outputs ``pose_3d`` (N, 1, 17, 3) and ``root_3d`` (N, 1, 3)); parity with torch checked.
4. int8 with onnxruntime.quantization: candidates :data:`CANDIDATES` (dynamic, and static
   QDQ calibrated on training-subject windows); each is scored on held-out windows and timed
   per frame on one thread against fp32; the fastest whose MPJPE stays within
   :data:`MAX_INT8_LOSS_MM` (or :data:`MAX_INT8_LOSS_REL`) of fp32 wins, else the most accurate.
5. The shipped size's ``lifter.fp32.onnx`` and ``lifter.int8.onnx`` go into ``--out``, and
   their manifest entries are MERGED into ``manifest.json``: every entry whose arch is not
   "lifter" (the ConvLSTM) is kept untouched; the lifter entries are replaced.
6. ``--report DIR/report.json`` and ``report.md`` (the channels table) and
   ``lifter_errors.png`` are rewritten after every size, so a long sweep reports as it goes.

Reproducible: the same seed and settings give the same data and the same weights (torch
with a fixed thread count on CPU).
"""
from __future__ import annotations

import json
import shutil
import time
from pathlib import Path

import numpy as np

from edge_runtime.cli import CliError, positive_float, positive_int, probability
from edge_runtime.core.manifest import SCHEMA_VERSION, ManifestError, load_manifest, sha256_file, write_manifest
from export.variants import Variant

REPO_ROOT = Path(__file__).resolve().parent.parent
DEFAULT_ASSETS = REPO_ROOT / "edge_runtime" / "assets"
DEFAULT_REPORT = REPO_ROOT / "reports" / "lifter"
ARCH = "lifter"
INPUT_NAME, POSE_OUTPUT, ROOT_OUTPUT = "keypoints_2d", "pose_3d", "root_3d"
OPSET = 17
PARITY_TOL_M = 1e-4
MAX_INT8_LOSS_MM = 2.0        # int8 may add this much MPJPE over fp32 ...
MAX_INT8_LOSS_REL = 0.03      # ... or this fraction of it, whichever is larger
MAX_INT8_BYTES = 10 * 1024 * 1024
N_CALIB = 1000


class LifterExportError(ValueError):
    """A lifter export that cannot go ahead (one line)."""


def add_arguments(p) -> None:
    p.add_argument("--seed", type=int, required=True, help="seeds the simulation and the training")
    p.add_argument("--channels", type=positive_int, default=256, help="the size to ship (default 256)")
    p.add_argument("--sweep", default=None, help="comma-separated sizes to train and report as well, "
                                                 "e.g. 256,512,1024")
    p.add_argument("--epochs", type=positive_int, default=4)
    p.add_argument("--epochs-by-size", default=None, help="per-size epochs, e.g. 1024=1,512=3")
    p.add_argument("--frames-per-epoch", type=positive_int, default=None,
                   help="training windows per epoch (default: every valid training frame)")
    p.add_argument("--batch-size", type=positive_int, default=256)
    p.add_argument("--lr-decay", type=positive_float, default=0.8,
                   help="learning-rate factor after every epoch, at most 1 (default 0.8)")
    p.add_argument("--trajectory-channels", type=positive_int, default=256)
    p.add_argument("--subjects", type=positive_int, default=32, help="training subjects")
    p.add_argument("--test-subjects", type=positive_int, default=8)
    p.add_argument("--seconds", type=float, default=90.0, help="seconds of activity per subject")
    p.add_argument("--cameras", type=positive_int, default=24, help="training camera placements")
    p.add_argument("--test-cameras", type=positive_int, default=8)
    p.add_argument("--views", type=positive_int, default=3, help="placements that see each session")
    p.add_argument("--data", choices=("walks", "varied"), default="walks",
                   help="walks: the first recipe (models.pose_data.build_splits); varied: every motion type of "
                        "firmware_sim record, a real detector's errors, distorted lenses, held-out motion types "
                        "(build_varied_splits; --subjects etc. do not apply)")
    p.add_argument("--scenes", type=positive_int, default=120, help="varied: training scenes")
    p.add_argument("--holdout-motions", default="carry,reach",
                   help="varied: motion types never trained on (comma-separated)")
    p.add_argument("--random-limbs", type=probability, default=0.0, metavar="SHARE",
                   help="varied: share of the training people whose arms, trunk, neck and legs also move along "
                        "random trajectories through their ranges of motion (pose-space augmentation; "
                        "firmware_sim.people.motions.random_limbs; default 0: none)")
    p.add_argument("--eval-frames", type=positive_int, default=20000, help="held-out frames scored per split")
    p.add_argument("--int8-fold-centering", action="store_true",
                   help="quantise the int8 candidates from the fp32 graph with its input centering folded into the "
                        "expand convolutions (export.lifter_fold: faster, less accurate; off: the shipped recipe)")
    p.add_argument("--latency-runs", type=positive_int, default=500, help="timed batch-1 calls per model")
    p.add_argument("--threads", type=positive_int, default=1, help="torch threads for training")
    p.add_argument("--out", default=None, help="assets directory (default: edge_runtime/assets)")
    p.add_argument("--report", default=None, help="report directory (default: reports/lifter)")
    p.add_argument("--work", default=None, help="scratch directory (default: runs/lifter-seed<S>)")
    p.add_argument("--reuse", action="store_true", help="reuse matching checkpoints in the work directory")
    p.add_argument("--no-progress", action="store_true")


BAD_INPUT = (LifterExportError, ManifestError)


def _sizes(a) -> list[int]:
    sizes = [a.channels]
    if a.sweep:
        try:
            extra = [int(s) for s in a.sweep.split(",") if s.strip()]
        except ValueError:
            raise CliError(f"--sweep: expected comma-separated integers, got {a.sweep!r}") from None
        if any(s < 1 for s in extra):
            raise CliError(f"--sweep: channel counts must be positive, got {a.sweep!r}")
        sizes += [s for s in extra if s not in sizes]
    return sizes


def _epochs_by_size(a) -> dict[int, int]:
    out = {}
    for part in (a.epochs_by_size or "").split(","):
        if not part.strip():
            continue
        try:
            c, e = part.split("=")
            out[int(c)] = int(e)
        except ValueError:
            raise CliError(f"--epochs-by-size: expected C=E pairs like 1024=1, got {part!r}") from None
        if out[int(c)] < 1:
            raise CliError(f"--epochs-by-size: epochs must be positive, got {part!r}")
    return out


# --------------------------------------------------------------------------- ONNX
def export_onnx(model, path: str | Path, meta: dict | None = None) -> Path:
    """The strided model (eval) -> ONNX at ``path``: keypoints_2d (N, 27, 17, 2) -> pose_3d, root_3d."""
    import io
    import warnings

    import onnx
    import torch

    from export.onnx_export import save_onnx, set_metadata

    model = model.eval()
    rf = model.config.receptive_field
    x = torch.zeros(2, rf, model.config.joints, 2)
    buf = io.BytesIO()
    with warnings.catch_warnings(), torch.no_grad():
        warnings.simplefilter("ignore")
        torch.onnx.export(model, (x,), buf, dynamo=False, opset_version=OPSET, do_constant_folding=True,
                          input_names=[INPUT_NAME], output_names=[POSE_OUTPUT, ROOT_OUTPUT],
                          dynamic_axes={INPUT_NAME: {0: "N"}, POSE_OUTPUT: {0: "N"}, ROOT_OUTPUT: {0: "N"}})
    onx = onnx.load_from_string(buf.getvalue())
    onx.producer_name = "edge-safety-export"
    onx.doc_string = (f"VideoPose3D-style causal pose lifter, {model.config.channels} channels: {INPUT_NAME} "
                      f"(N,{rf},17,2) normalised canonical pixels -> {POSE_OUTPUT} (N,1,17,3) root-relative m, "
                      f"{ROOT_OUTPUT} (N,1,3) m, camera frame, last input frame")
    set_metadata(onx, {k: v if isinstance(v, str) else json.dumps(v, sort_keys=True) for k, v in (meta or {}).items()})
    onnx.checker.check_model(onx)
    return save_onnx(onx, path)


def onnx_runner(path: str | Path, threads: int = 1):
    """``runner(windows (N, 27, 17, 2)) -> (pose (N, 1, 17, 3), root (N, 1, 3))`` on onnxruntime."""
    from edge_runtime.core.onnx import open_session

    return session_runner(open_session(path, threads))


def session_runner(sess):
    """:func:`onnx_runner` of an open onnxruntime session."""
    return lambda x: sess.run([POSE_OUTPUT, ROOT_OUTPUT], {INPUT_NAME: np.ascontiguousarray(x, np.float32)})


def check_parity(model, path: str | Path, windows: np.ndarray, tol: float = PARITY_TOL_M) -> dict:
    """Max |torch - onnxruntime| (metres) of pose and root on ``windows``, and on batch 1."""
    import torch

    run = onnx_runner(path)
    with torch.no_grad():
        tp, tr = (t.numpy() for t in model.eval()(torch.from_numpy(windows)))
    op, orr = run(windows)
    op1, or1 = run(windows[:1])
    d_pose = float(max(np.abs(op - tp).max(), np.abs(op1 - tp[:1]).max()))
    d_root = float(max(np.abs(orr - tr).max(), np.abs(or1 - tr[:1]).max()))
    return {"max_abs_pose_m": d_pose, "max_abs_root_m": d_root, "n": int(len(windows)), "tol_m": tol,
            "ok": bool(max(d_pose, d_root) < tol)}


# --------------------------------------------------------------------------- int8
def _output_convs(model) -> list[str]:
    """Names of the Conv nodes not followed by a ReLU: the shrink layers (BatchNorm is fused by then)."""
    relu_inputs = {i for n in model.graph.node if n.op_type == "Relu" for i in n.input}
    return [n.name for n in model.graph.node if n.op_type == "Conv" and n.output[0] not in relu_inputs]


CANDIDATES: tuple[Variant, ...] = (
    Variant("qdq", "static QDQ on every op, per-channel int8 weights, uint8 activations (MinMax)", static_ops=None),
    Variant("qdq_fp32_out", "static QDQ, per-channel, output convolutions kept fp32", static_ops=None,
            keep_fp32=_output_convs),
    Variant("qdq_pt", "static QDQ on every op, per-tensor weights", static_ops=None, per_channel=False),
    Variant("dynamic", "dynamic int8 convolutions (ConvInteger), activations quantised per call",
            dynamic_ops=("Conv",)),
)


def allowed_int8_mpjpe_mm(fp32_mm: float) -> float:
    """The export's int8 rule: the largest MPJPE an int8 lifter may have, max(MAX_INT8_LOSS_MM, MAX_INT8_LOSS_REL)
    above its fp32 graph's."""
    return fp32_mm + max(MAX_INT8_LOSS_MM, MAX_INT8_LOSS_REL * fp32_mm)


def choose_int8(fp32_mm: float, mpjpe_mm: dict[str, float], p50_us: dict[str, float]) -> str:
    """The fastest candidate within the allowed MPJPE loss; else the most accurate."""
    from export.quantize import fastest

    allowed = allowed_int8_mpjpe_mm(fp32_mm)
    ok = [k for k, mm in mpjpe_mm.items() if mm <= allowed]
    return fastest(p50_us, ok) if ok else min(mpjpe_mm, key=mpjpe_mm.get)


# --------------------------------------------------------------------------- manifest
def merge_manifest(out: str | Path, entries: list[dict], created_by: str) -> Path:
    """Write ``entries`` (arch "lifter") into ``out/manifest.json``, keeping every non-lifter entry untouched."""
    out = Path(out)
    kept: list[dict] = []
    try:
        old = load_manifest(out)
        kept = [e for e in old["models"] if e.get("arch") != ARCH]
        created_by = old.get("created_by", created_by) if kept else created_by
    except ManifestError as e:
        if (out / "manifest.json").exists():
            raise LifterExportError(f"refusing to overwrite an unreadable manifest: {e}") from None
    manifest = {"version": SCHEMA_VERSION, "created_by": created_by, "models": kept + entries}
    return write_manifest(out, manifest)


def _entry(precision: str, file: str, path: Path, row: dict, common: dict, metrics: dict, extra: dict) -> dict:
    return {"name": f"lifter-{precision}", "file": file, "sha256": sha256_file(path), "precision": precision,
            "arch": ARCH, "size_bytes": path.stat().st_size, **common, "metrics": metrics, **extra}


def manifest_entries(row: dict, fp32: Path, int8: Path, provenance: dict) -> list[dict]:
    """The two lifter manifest entries (the model contract) for a trained size."""
    from firmware_sim.devices.camera import CANONICAL

    cam = CANONICAL
    rf = row["config"]["filter_widths"]
    rfield = int(np.prod(rf))
    common = {
        # the training data's recipe is part of the version: two lifters of one size and seed trained on
        # different data are different models, and only the version tells a reader which one runs
        "model_version": (f"{provenance['version']}+lifter.{provenance.get('data', {}).get('recipe', 'walks')}"
                          f".c{row['channels']}.seed{provenance['seed']}"),
        "parameters": row["parameters"],
        "config": row["config"],
        "classes": [],
        "receptive_field": rfield,
        "joints": "h36m-17",
        "camera": {"width_px": cam.width_px, "height_px": cam.height_px, "fx_px": cam.fx_px, "fy_px": cam.fy_px,
                   "cx_px": cam.cx_px, "cy_px": cam.cy_px},
        "inputs": [{"name": INPUT_NAME, "shape": ["N", rfield, 17, 2], "dtype": "float32",
                    "layout": f"N,{rfield},17,2: the last {rfield} frames oldest first, H36M-17 joints "
                              "(edge_runtime.core.skeleton), x/y",
                    "units": "canonical-camera pixels normalised as u/w*2-1, v/w*2-h/w (w=1280, h=720)"}],
        "outputs": [{"name": POSE_OUTPUT, "shape": ["N", 1, 17, 3], "dtype": "float32",
                     "meaning": "root-relative joints (joint 0 = 0) of the LAST input frame, camera frame "
                                "(OpenCV axes: x right, y down, z forward)", "units": "m"},
                    {"name": ROOT_OUTPUT, "shape": ["N", 1, 3], "dtype": "float32",
                     "meaning": "the pelvis of the LAST input frame in the camera frame; absolute joints = "
                                "pose_3d + root_3d", "units": "m"}],
        "provenance": provenance,
    }
    fp32_metrics = {"held_out": row["fp32"], "parity_vs_torch": row["parity"],
                    "latency_1thread_us": row["latency"]["fp32"]}
    int8_metrics = {"held_out": row["int8"], "mpjpe_delta_vs_fp32_mm":
                    row["int8"]["test"]["mpjpe_mm"] - row["fp32"]["test"]["mpjpe_mm"],
                    "latency_1thread_us": row["latency"]["int8"]}
    return [_entry("fp32", "lifter.fp32.onnx", fp32, row, common, fp32_metrics, {}),
            _entry("int8", "lifter.int8.onnx", int8, row, common, int8_metrics, {"quantization": row["quantization"]})]


# --------------------------------------------------------------------------- one size
def held_out_splits(splits) -> list[str]:
    """The held-out splits present, the one to choose on first: ``val`` (varied recipe) or ``test_subjects``
    (walks recipe), then ``test``."""
    return [s for s in ("val", "test_subjects", "test") if s in splits]


def choice_split(splits) -> str:
    """Where choices (the int8 method) are made: ``val`` when the recipe has one (test is scored once);
    the walks recipe has none and chooses on ``test`` as it always did."""
    return "val" if "val" in splits else "test"


def choice_set(splits):
    """(the frames choices are scored on, what they are): :func:`choice_split`'s split, with the motion types
    held out of training left out: a choice on them would peek at the held-out test of unseen motion."""
    from models.pose_data import trained_types_only

    name = choice_split(splits)
    ps = splits[name]
    held = ps.meta.get("config", {}).get("holdout_motions") or []
    if not held:
        return ps, name
    return trained_types_only(ps), f"{name}, trained motion types only (not {', '.join(held)})"


def _slim(m: dict) -> dict:
    return {k: (round(v, 2) if isinstance(v, float) else v) for k, v in m.items()
            if not isinstance(v, dict) or k in ("per_joint_mm", "per_activity_mpjpe_mm", "per_activity_p_mpjpe_mm")}


def run_size(channels: int, epochs: int, splits: dict, a, work: Path, log) -> tuple[dict, Path, Path, object]:
    """Train (or reuse), evaluate, export and quantise one size; returns (row, fp32 path, int8 path, model)."""
    import torch

    from models.lifter_train import evaluate, fmt_metrics

    d = work / f"c{channels}"
    d.mkdir(parents=True, exist_ok=True)
    say = lambda s: log(f"c{channels}: {s}")
    model, mcfg, train = _trained(channels, epochs, splits, a, d, say)
    torch.set_num_threads(a.threads)
    fp32_torch = {s: evaluate(model, splits[s], a.eval_frames) for s in held_out_splits(splits)}
    say(f"torch held-out subjects+cameras: {fmt_metrics(fp32_torch['test'])}")
    fp32_path, parity = _export_checked(model, channels, mcfg, a.seed, splits["test"], d)
    int8_path, quantization, latency = _quantise(model, fp32_path, splits, a, d, say)
    runners = {"fp32": onnx_runner(fp32_path), "int8": onnx_runner(int8_path)}
    res = {prec: {s: evaluate(model, splits[s], a.eval_frames, runner=r) for s in held_out_splits(splits)}
           for prec, r in runners.items()}
    row = {
        "channels": channels, "config": mcfg.to_dict(), "parameters": model.parameter_counts(),
        "epochs": epochs, "train": train,
        "torch": {s: _slim(m) for s, m in fp32_torch.items()},
        "fp32": {s: _slim(m) for s, m in res["fp32"].items()},
        "int8": {s: _slim(m) for s, m in res["int8"].items()},
        "parity": parity,
        "latency": latency,
        "bytes": {"fp32": fp32_path.stat().st_size, "int8": int8_path.stat().st_size},
        "quantization": quantization,
    }
    say(f"fp32 {fmt_metrics(res['fp32']['test'])}; int8 MPJPE {res['int8']['test']['mpjpe_mm']:.1f} mm; "
        f"{latency['fp32']['p50_us']:.0f} / {latency['int8']['p50_us']:.0f} us per frame; "
        f"int8 {row['bytes']['int8'] / 1e6:.2f} MB")
    return row, fp32_path, int8_path, model


def _trained(channels: int, epochs: int, splits: dict, a, d: Path, say) -> tuple[object, object, dict]:
    """(model, its LifterConfig, the row's "train") of ``d/model.pt``: reused with ``--reuse`` when
    its settings and data match, else trained and saved there."""
    from models.lifter import LifterConfig
    from models.lifter_train import TrainConfig, fit, load_checkpoint, save_checkpoint, state_digest

    mcfg = LifterConfig(channels=channels, trajectory_channels=a.trajectory_channels)
    tcfg = TrainConfig(epochs=epochs, frames_per_epoch=a.frames_per_epoch, batch_size=a.batch_size, seed=a.seed,
                       threads=a.threads, lr_decay=getattr(a, "lr_decay", TrainConfig.lr_decay))
    data_key = splits["train"].meta["config"]
    ck_path = d / "model.pt"
    model, history, t_train = None, None, 0.0
    if a.reuse and ck_path.is_file():
        m, ck = load_checkpoint(ck_path)
        if ck.get("config") == mcfg.to_dict() and ck.get("train_config") == tcfg.to_dict() and ck.get("data") == data_key:
            model, history, t_train = m, ck.get("history"), ck.get("train_seconds", 0.0)
            say(f"reusing {ck_path}")
    if model is None:
        t0 = time.time()
        model, history = fit(splits["train"], mcfg, tcfg, progress=not a.no_progress, log=say)
        t_train = time.time() - t0
        save_checkpoint(ck_path, model, tcfg, data=data_key, history=history, train_seconds=t_train)
    return model, mcfg, {"history": history, "seconds": round(t_train, 1), "config": tcfg.to_dict(),
                         "weights_sha256_16": state_digest(model)}


def _export_checked(model, channels: int, mcfg, seed: int, test, d: Path) -> tuple[Path, dict]:
    """``d/lifter.fp32.onnx`` and its parity with torch on held-out windows (raises when it differs)."""
    from models.lifter_train import eval_frames

    meta = {"arch": ARCH, "channels": str(channels), "receptive_field": str(mcfg.receptive_field),
            "joints": "h36m-17", "seed": str(seed), "precision": "fp32"}
    fp32_path = export_onnx(model, d / "lifter.fp32.onnx", meta)
    parity = check_parity(model, fp32_path, test.windows(eval_frames(test, 256)).astype(np.float32))
    if not parity["ok"]:
        worst = max(parity["max_abs_pose_m"], parity["max_abs_root_m"])
        raise LifterExportError(f"{fp32_path}: onnxruntime differs from torch by {worst:.2e} m")
    return fp32_path, parity


def calibration_windows(train) -> np.ndarray:
    """The int8 calibration inputs: :data:`N_CALIB` evenly spread valid windows of the training split."""
    from models.lifter_train import eval_frames

    return train.windows(eval_frames(train, N_CALIB)).astype(np.float32)


def int8_source(fp32_path: Path, fold_centering: bool, d: Path) -> Path:
    """The fp32 graph the int8 lifter is quantised from: ``fp32_path`` itself, or with ``fold_centering`` a copy
    with its input centering folded into the expand convolutions (``d/lifter.fp32.folded.onnx``; the fp32
    asset itself always stays as exported)."""
    if not fold_centering:
        return fp32_path
    import onnx

    from export.lifter_fold import fold_input_centering

    source = d / "lifter.fp32.folded.onnx"
    onnx.save(fold_input_centering(onnx.load(str(fp32_path))), str(source))
    return source


def recipe_fields(n_calib: int, fold_centering: bool) -> dict:
    """The int8 entry's "quantization" fields that say what it was calibrated on and from which graph."""
    return {"calibration": f"{n_calib} windows of training subjects and cameras (MinMax)",
            **({"input_centering": FOLDED_CENTERING} if fold_centering else {})}


FOLDED_CENTERING = "folded into the expand convolutions (export.lifter_fold)"


def _quantise(model, fp32_path: Path, splits: dict, a, d: Path, say) -> tuple[Path, dict, dict]:
    """Every :data:`CANDIDATES` built (calibrated on training windows), scored on held-out frames
    and timed per frame against fp32; the :func:`choose_int8` one copied to ``d/lifter.int8.onnx``.
    Returns (that path, the row's "quantization", the row's "latency")."""
    from export.quantize import compare_variants, int8_report
    from models.lifter_train import evaluate

    train = splits["train"]
    test, scored_on = choice_set(splits)
    calib = calibration_windows(train)
    quick = max(1000, a.eval_frames // 4)
    fp32_mm = evaluate(model, test, quick, runner=onnx_runner(fp32_path))["mpjpe_mm"]
    frame = np.random.default_rng(0).normal(0, 0.3, (1, model.config.receptive_field, 17, 2)).astype(np.float32)
    folded = getattr(a, "int8_fold_centering", False)
    source = int8_source(fp32_path, folded, d)
    comp = compare_variants(
        source, CANDIDATES, calib, d, stem="lifter.int8.", describe=False,
        score=lambda s: {"mpjpe_mm": evaluate(model, test, quick, runner=session_runner(s))["mpjpe_mm"]},
        feed={INPUT_NAME: frame}, n_timing=a.latency_runs, warmup=max(20, a.latency_runs // 10), log=say)
    if not comp.paths:
        raise LifterExportError(f"{fp32_path}: no int8 candidate could be built")
    mm = {k: comp.results[k]["mpjpe_mm"] for k in comp.paths}
    p50 = {k: lat["p50_us"] for k, lat in comp.latency.items()}
    best = choose_int8(fp32_mm, mm, p50)
    int8_path = d / "lifter.int8.onnx"
    shutil.copyfile(comp.paths[best], int8_path)
    say(f"int8 candidates (MPJPE on {quick} frames, fp32 {fp32_mm:.1f} mm): " +
        ", ".join(f"{k} {mm[k]:.1f} mm {p50[k]:.0f} us" for k in mm) + f"; fp32 {p50['fp32']:.0f} us -> {best}")
    quantization = {
        "method": best, "description": comp.results[best]["description"],
        "reduce_range": comp.results[best]["reduce_range"],
        "integer_kernel_drift": comp.results[best]["integer_kernel_drift"],
        **recipe_fields(len(calib), folded),
        "rule": f"fastest candidate within max({MAX_INT8_LOSS_MM} mm, {MAX_INT8_LOSS_REL:.0%}) MPJPE of fp32, "
                "else the most accurate",
        "candidates": {k: {"mpjpe_mm": round(mm[k], 2), "bytes": comp.results[k]["size_bytes"],
                           "p50_us": round(p50[k], 1), "description": comp.results[k]["description"]} for k in mm},
        "scored_on_frames": quick, "scored_on": scored_on, **int8_report(int8_path)}
    return int8_path, quantization, {"fp32": comp.latency["fp32"], "int8": comp.latency[best]}


# --------------------------------------------------------------------------- report
def write_report(report_dir: Path, rows: dict[int, dict], shipped: int, info: dict, splits: dict, model) -> None:
    """report.json, report.md (the channels table) and lifter_errors.png."""
    report_dir.mkdir(parents=True, exist_ok=True)
    rep = {**info, "shipped_channels": shipped, "sizes": {str(k): v for k, v in rows.items()}}
    (report_dir / "report.json").write_text(json.dumps(rep, indent=2, sort_keys=True, default=float))
    (report_dir / "report.md").write_text(_markdown(rows, shipped, info))
    if model is not None and shipped in rows:
        _figure(report_dir / "lifter_errors.png", rows[shipped], splits["test"], model)


def _markdown(rows: dict[int, dict], shipped: int, info: dict) -> str:
    varied = info.get("data", {}).get("recipe") == "varied"
    split_text = (("New people seen from held-out camera placements with distorted lenses (split `test`, scored once; "
                   "the int8 method was chosen on split `val`, other held-out placements, on its trained motion types "
                   "since session 24), every motion type of "
                   "`firmware_sim record`, of which " + ", ".join(info["data"]["holdout_motions"]) +
                   " never in training, at a real detector's errors (`REAL_DETECTOR`)") if varied else
                  "Held-out subjects seen from held-out camera placements (split `test`), with the detector noise model "
                  "of firmware_sim/camera.py")
    lines = ["# Pose lifter: channels sweep", "",
             f"Command: `{info['command']}`", "",
             split_text + "; errors in mm over the frames the streaming runtime would lift. "
             "Latency: one frame (batch 1, 27 x 17 x 2) on onnxruntime with 1 thread, median.", "",
             "| channels | parameters (pose + trajectory) | epochs | MPJPE | P-MPJPE | int8 MPJPE | root error | "
             f"{'val split' if varied else 'held-out subjects only'} MPJPE | latency fp32 | latency int8 | int8 size |",
             "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for c in sorted(rows):
        r = rows[c]
        t, t8, ts = r["fp32"]["test"], r["int8"]["test"], r["fp32"][held_out_splits(r["fp32"])[0]]
        mark = " (shipped)" if c == shipped else ""
        lines.append(f"| {c}{mark} | {r['parameters']['pose']:,} + {r['parameters']['trajectory']:,} | {r['epochs']} | "
                     f"{t['mpjpe_mm']:.1f} | {t['p_mpjpe_mm']:.1f} | {t8['mpjpe_mm']:.1f} | {t['root_error_mm']:.0f} | "
                     f"{ts['mpjpe_mm']:.1f} | {r['latency']['fp32']['p50_us']:.0f} us | "
                     f"{r['latency']['int8']['p50_us']:.0f} us | {r['bytes']['int8'] / 1e6:.2f} MB |")
    if shipped in rows:
        r = rows[shipped]
        t = r["fp32"]["test"]
        lines += ["", f"Shipped: {shipped} channels, int8 method `{r['quantization']['method']}` "
                      f"({r['quantization']['description']}); int8 candidates on "
                      f"{r['quantization']['scored_on_frames']} held-out frames"
                      f"{' (' + r['quantization']['scored_on'] + ')' if 'scored_on' in r['quantization'] else ''}: "
                      + ", ".join(
                          f"{k} {v['mpjpe_mm']:.1f} mm / {v['p50_us']:.0f} us"
                          for k, v in r["quantization"]["candidates"].items()) + ".", "",
                  _why_shipped(rows, shipped), "",
                  "Per activity (shipped, fp32, MPJPE mm): " + ", ".join(
                      f"{k} {v:.1f}" for k, v in t["per_activity_mpjpe_mm"].items()), "",
                  *(["Per activity (shipped, int8, P-MPJPE mm; * = never in training): " + ", ".join(
                      f"{k}{' *' if k in info['data'].get('holdout_motions', ()) else ''} {v:.1f}"
                      for k, v in t8["per_activity_p_mpjpe_mm"].items()), ""] if "per_activity_p_mpjpe_mm" in t8
                    else []),
                  "## Root position", "",
                  f"The trajectory network (VideoPose3D's, 1/z-weighted loss) puts the pelvis {t['root_error_mm']:.0f} mm "
                  f"from the truth on average (median {t['root_error_median_mm']:.0f} mm; depth alone "
                  f"{t['root_depth_error_mm']:.0f} mm; {t['root_relative_error_pct']:.1f} % of the distance). That is "
                  "about what depth from apparent size can do when body height varies by 11/172 = 6.4 %."]
        if "ground_plane_root_error_mm" in t:
            lines += ["", f"For comparison, the ground-plane method (ray through the lower ankle's 2D keypoint meets "
                          f"the floor, with the TRUE camera extrinsics; `models.lifter_train.ground_plane_root`) gets "
                          f"{t['ground_plane_root_error_mm']:.0f} mm (median {t['ground_plane_root_error_median_mm']:.0f} "
                          "mm). It needs the camera-to-floor calibration at inference time; the model contract asks for "
                          "the root in the camera frame before any calibration (the 3-marker calibration itself is "
                          "computed from the lifter's output), so the shipped model keeps the trajectory network, and a "
                          "calibrated runtime can re-anchor the root on the floor for a better robot-frame position."]
        lines += ["", "## Training", "", "Training MPJPE (mm, dropout on), mean over each epoch, "
                      "per size (wall time of the training):", ""]
        for c in sorted(rows):
            h = rows[c]["train"]["history"] or []
            lines.append(f"* {c} channels ({rows[c]['train']['seconds']:.0f} s): " +
                         ", ".join(f"{e['train_mpjpe_mm']:.1f}" for e in h))
        lines += ["", "![errors](lifter_errors.png)"]
    lines += ["", "Data: " + json.dumps(info.get("data", {})), ""]
    return "\n".join(lines)


def _why_shipped(rows: dict[int, dict], shipped: int) -> str:
    """One paragraph: why this size is the one on the box."""
    r = rows[shipped]
    text = (f"Why {shipped}: its int8 asset is {r['bytes']['int8'] / 1e6:.2f} MB (budget 10 MB) and lifts a frame in "
            f"{r['latency']['int8']['p50_us']:.0f} us on one thread, a small share of a 33 ms camera period on a "
            "2-core box that also runs the robot loop and the wearable chain.")
    for c in sorted(rows):
        if c == shipped:
            continue
        o = rows[c]
        diff = o["int8"]["test"]["mpjpe_mm"] - r["int8"]["test"]["mpjpe_mm"]
        text += (f" {c} channels: int8 MPJPE {o['int8']['test']['mpjpe_mm']:.1f} mm ({diff:+.1f} mm vs {shipped}), "
                 f"{o['latency']['int8']['p50_us']:.0f} us, {o['bytes']['int8'] / 1e6:.2f} MB, after "
                 f"{o['epochs']} epoch(s).")
    return text


def _figure(path: Path, row: dict, test, model) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from edge_runtime.core.skeleton import bones
    from models.lifter_train import eval_frames, predict

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.8))
    pj32, pj8 = row["fp32"]["test"]["per_joint_mm"], row["int8"]["test"]["per_joint_mm"]
    names = list(pj32)
    x = np.arange(len(names))
    axes[0].bar(x - 0.2, [pj32[n] for n in names], 0.4, label="fp32")
    axes[0].bar(x + 0.2, [pj8[n] for n in names], 0.4, label="int8")
    axes[0].set_xticks(x, names, rotation=70, fontsize=7)
    axes[0].set_ylabel("MPJPE (mm)")
    axes[0].set_title(f"{row['channels']} channels: error per joint (held-out)")
    axes[0].legend()
    idx = eval_frames(test, 400)
    pose, _ = predict(model, test, idx)
    err = np.linalg.norm(pose - test.pose3d[idx], axis=-1).mean(1)
    k = idx[int(np.argsort(err)[len(err) // 2])]           # a median-error frame
    pred = pose[int(np.argsort(err)[len(err) // 2])]
    true = test.pose3d[k]
    for ax, (i, j), title in ((axes[1], (0, 1), "front (x, -y)"), (axes[2], (2, 1), "side (z, -y)")):
        for p_, c_ in bones():
            ax.plot(true[[p_, c_], i], -true[[p_, c_], j], "k-", lw=2, label="true" if (p_, c_) == (0, 1) else None)
            ax.plot(pred[[p_, c_], i], -pred[[p_, c_], j], "r--", lw=1.5, label="predicted" if (p_, c_) == (0, 1) else None)
        ax.set_aspect("equal")
        ax.set_title(f"median-error frame, {title}")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


# --------------------------------------------------------------------------- command
def data_config(d: dict):
    """The :class:`models.pose_data.VariedConfig` or ``DataConfig`` a manifest's ``provenance.data`` records
    (``to_dict``'s inverse: JSON lists back to tuples, the recipe's name dropped)."""
    from models.pose_data import DataConfig, VariedConfig

    cls = VariedConfig if d.get("recipe") == "varied" else DataConfig
    return cls(**{k: tuple(v) if isinstance(v, list) else v for k, v in d.items() if k != "recipe"})


def simulate(dcfg, progress: bool = False) -> dict:
    """The splits of a data recipe's config (deterministic in its seed)."""
    from models.pose_data import VariedConfig, build_splits, build_varied_splits

    return build_varied_splits(dcfg, progress) if isinstance(dcfg, VariedConfig) else build_splits(dcfg, progress)


def _rel(p: Path) -> str:
    """``p`` relative to the repository when it lies inside it (portable provenance), else absolute."""
    p = p.resolve()
    return str(p.relative_to(REPO_ROOT)) if p.is_relative_to(REPO_ROOT) else str(p)


def cmd(a) -> int:
    import sys

    from export.assets import versions
    from export.onnx_export import git_commit, package_version
    from models.pose_data import DataConfig, VariedConfig, summary

    if not np.isfinite(a.seconds) or a.seconds < 2.0:
        raise CliError(f"--seconds: expected at least 2 s of activity per subject, got {a.seconds}")
    if a.lr_decay > 1.0:
        raise CliError(f"--lr-decay: expected a factor of at most 1, got {a.lr_decay}")
    sizes = _sizes(a)
    ebs = _epochs_by_size(a)
    out = Path(a.out) if a.out else DEFAULT_ASSETS
    report_dir = Path(a.report) if a.report else DEFAULT_REPORT
    work = Path(a.work) if a.work else REPO_ROOT / "runs" / f"lifter-seed{a.seed}"
    work.mkdir(parents=True, exist_ok=True)
    log = print
    command = "python -m export lifter " + " ".join(sys.argv[2:]) if sys.argv[1:2] == ["lifter"] else \
        f"python -m export lifter --seed {a.seed} --channels {a.channels}"
    t0 = time.time()
    if a.data == "varied":
        holdout = tuple(m.strip() for m in a.holdout_motions.split(",") if m.strip())
        dcfg = VariedConfig(train_scenes=a.scenes, seconds_per_scene=a.seconds, holdout_motions=holdout,
                            random_limbs_share=a.random_limbs, seed=a.seed)
        try:
            splits = simulate(dcfg, progress=not a.no_progress)
        except ValueError as e:
            raise CliError(f"--holdout-motions: {e}") from None
    else:
        dcfg = DataConfig(train_subjects=a.subjects, test_subjects=a.test_subjects, seconds_per_subject=a.seconds,
                          train_cameras=a.cameras, test_cameras=a.test_cameras, views=a.views, seed=a.seed)
        splits = simulate(dcfg, progress=not a.no_progress)
    info = {"command": command, "data": dcfg.to_dict(), "splits": {k: summary(v) for k, v in splits.items()}}
    log(f"simulated in {time.time() - t0:.0f} s: " + ", ".join(
        f"{k} {v['valid_frames']} valid frames" for k, v in info["splits"].items()))
    provenance = {"command": command, "seed": a.seed, "data": dcfg.to_dict(), "git_commit": git_commit(),
                  "versions": versions(), "version": package_version()}
    rows: dict[int, dict] = {}
    shipped_model = None
    for c in sizes:
        row, fp32, int8, model = run_size(c, ebs.get(c, a.epochs), splits, a, work, log)
        rows[c] = row
        if c == a.channels:
            shipped_model = model
            if row["bytes"]["int8"] > MAX_INT8_BYTES:
                raise LifterExportError(f"--channels {c}: the int8 lifter is {row['bytes']['int8'] / 1e6:.1f} MB, "
                                        f"over the {MAX_INT8_BYTES / 2**20:.0f} MB edge budget; ship a smaller size")
            prov = dict(provenance, checkpoint=_rel(work / f"c{c}" / "model.pt"))
            out.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(fp32, out / "lifter.fp32.onnx")
            shutil.copyfile(int8, out / "lifter.int8.onnx")
            mpath = merge_manifest(out, manifest_entries(row, out / "lifter.fp32.onnx", out / "lifter.int8.onnx", prov),
                                   f"{command} (edge-safety {package_version()})")
            log(f"shipped c{c}: {out / 'lifter.fp32.onnx'}, {out / 'lifter.int8.onnx'}, {mpath}")
        write_report(report_dir, rows, a.channels, info, splits, shipped_model)
        log(f"report: {report_dir / 'report.md'}")
    return 0
