"""Do the shipped models run on another onnxruntime, or another machine, and give this one's outputs?

``python -m export.runtime_check --python PY [--python PY ...] [--assets DIR] [--wrap CMD]``

For every model of the manifest, fixed inputs (seeded, batch 4) are run here and in each
interpreter ``PY`` (another venv with another onnxruntime, or an emulated aarch64 Python
under ``--wrap "qemu-aarch64-static -L ROOT"``). The child gets only a short script on its
command line and needs numpy and onnxruntime, nothing of this repository, so it runs in a
bare venv or an installed bundle. Per interpreter and model it reports whether onnxruntime
loaded the model, the largest output difference from this process's outputs and, for
classifiers, whether the argmax agrees; exit status 1 when a model fails to load or an
output differs by more than ``--tol``. This is how docs/install.md's tested onnxruntime
range was measured.
"""
from __future__ import annotations

import argparse
import json
import shlex
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from edge_runtime.core.manifest import example_shape

# The child: numpy and onnxruntime only. argv: assets dir, inputs .npz, outputs .npz, timed calls.
CHILD = r"""
import json, sys, time, numpy as np, onnxruntime as ort
assets, inp, out = sys.argv[1:4]  # then the timed batch-1 calls per model
m = json.load(open(assets + "/manifest.json"))
x = np.load(inp)
res = {"__version__": np.array(ort.__version__)}
for e in m["models"]:
    so = ort.SessionOptions(); so.intra_op_num_threads = 1; so.log_severity_level = 3
    try:
        s = ort.InferenceSession(assets + "/" + e["file"], so, providers=["CPUExecutionProvider"])
    except Exception as err:
        res[e["name"] + "/__error__"] = np.array(str(err).strip().splitlines()[0][:300])
        continue
    feed = {i.name: x[e["name"] + "/" + i.name] for i in s.get_inputs()}
    for k, v in zip([o.name for o in s.get_outputs()], s.run(None, feed)):
        res[e["name"] + "/" + k] = v
    one = {k: v[:1] for k, v in feed.items()}
    ts = []
    for _ in range(int(sys.argv[4])):
        t = time.perf_counter_ns(); s.run(None, one); ts.append(time.perf_counter_ns() - t)
    res[e["name"] + "/__p50_us__"] = np.array(np.median(ts) / 1e3 if ts else np.nan)
np.savez(out, **res)
"""
TOL = 1e-3
"""Largest output difference allowed between runtimes (probabilities, metres): int8 kernels
may round differently on another instruction set, by a quantisation step at most."""


def fixed_inputs(manifest: dict, n: int = 4, seed: int = 0) -> dict[str, np.ndarray]:
    """Per model input, ``n`` seeded examples of the manifest's shape (batch n, see
    :func:`edge_runtime.core.manifest.example_shape` for the other symbolic axes)."""
    rng = np.random.default_rng(seed)
    feed = {}
    for e in manifest["models"]:
        for spec in e["inputs"]:
            shape = example_shape(spec, n)
            scale = 3.0 if e["classes"] else 0.3  # m/s^2 around gravity for classifiers; normalised pixels
            x = rng.normal(0.0, scale, shape)
            if e["classes"]:
                x[..., 2] += 9.80665
            feed[f"{e['name']}/{spec['name']}"] = x.astype(spec.get("dtype", "float32"))
    return feed


def run_outputs(python: list[str], assets: Path, feed: dict[str, np.ndarray], *, env: dict | None = None,
                timed_calls: int = 50, timeout_s: float = 3600) -> dict[str, np.ndarray]:
    """The child's outputs (``name/output`` arrays, ``name/__error__``, ``__version__``) and the
    median time of ``timed_calls`` batch-1 calls per model (``name/__p50_us__``), in an
    environment ``env`` (default this one's)."""
    with tempfile.TemporaryDirectory() as td:
        inp, out = Path(td) / "in.npz", Path(td) / "out.npz"
        np.savez(inp, **feed)
        r = subprocess.run([*python, "-c", CHILD, str(assets), str(inp), str(out), str(timed_calls)],
                           capture_output=True, text=True, timeout=timeout_s, env=env)
        if r.returncode != 0:
            tail = (r.stderr.strip().splitlines() or ["no output"])[-1]
            raise RuntimeError(f"{' '.join(python)}: exit {r.returncode}: {tail}")
        with np.load(out) as z:
            return {k: z[k] for k in z.files}


def compare(manifest: dict, ref: dict[str, np.ndarray], other: dict[str, np.ndarray], tol: float = TOL) -> dict:
    """Per model: ``loaded``, ``error``, ``max_abs`` over its outputs, ``argmax_agree`` (classifiers), ``ok``."""
    rows = {}
    for e in manifest["models"]:
        name = e["name"]
        if f"{name}/__error__" in other:
            rows[name] = {"loaded": False, "error": str(other[f"{name}/__error__"]), "ok": False}
            continue
        keys = [k for k in ref if k.startswith(name + "/") and not k.endswith("__")]
        diff = max(float(np.abs(ref[k].astype(np.float64) - other[k]).max()) for k in keys)
        row = {"loaded": True, "max_abs": diff, "ok": diff <= tol}
        probs = f"{name}/probs"
        if probs in ref:
            row["argmax_agree"] = float(np.mean(ref[probs].argmax(1) == other[probs].argmax(1)))
        rows[name] = row
    return rows


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m export.runtime_check", description=__doc__.split("\n\n")[0])
    p.add_argument("--python", action="append", required=True, help="another interpreter (repeatable)")
    p.add_argument("--assets", default=None, help="assets directory (default: edge_runtime/assets)")
    p.add_argument("--wrap", default="", help="command prefix for every --python, e.g. 'qemu-aarch64-static -L ROOT'")
    p.add_argument("--tol", type=float, default=TOL)
    p.add_argument("--json", default=None, help="write the comparison here")
    a = p.parse_args(argv)
    from edge_runtime.core.manifest import ASSETS_DIR, verify_all

    assets = Path(a.assets or ASSETS_DIR).resolve()
    manifest = verify_all(assets)  # the files compared are the ones the manifest names
    feed = fixed_inputs(manifest)
    ref = run_outputs([sys.executable], assets, feed)
    report = {"reference": str(ref["__version__"]), "runs": []}
    ok = True
    for py in a.python:
        cmd = shlex.split(a.wrap) + [py]
        try:
            other = run_outputs(cmd, assets, feed)
        except (RuntimeError, OSError, subprocess.TimeoutExpired) as e:
            print(f"{py}: {e}")
            report["runs"].append({"python": py, "error": str(e)})
            ok = False
            continue
        rows = compare(manifest, ref, other, a.tol)
        report["runs"].append({"python": py, "onnxruntime": str(other["__version__"]), "models": rows})
        for name, r in rows.items():
            ok &= r["ok"]
            what = (f"max |d| {r['max_abs']:.2e}" + (f", argmax agree {r['argmax_agree']:.2f}" if "argmax_agree" in r
                                                      else "")) if r["loaded"] else f"REFUSED: {r['error']}"
            print(f"onnxruntime {other['__version__']} vs {ref['__version__']}: {name}: {what}")
    if a.json:
        Path(a.json).write_text(json.dumps(report, indent=2))
    return 0 if ok else 1


if __name__ == "__main__":
    sys.exit(main())
