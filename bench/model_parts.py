"""``python -m bench.model_parts [--assets DIR] [--n N] [--json OUT.json]``: where the ConvLSTM's
time goes, each part measured as a model of its own on the box's session settings.

onnxruntime's profiler inflates small nodes (a profiled call takes 2-3 times an unprofiled one),
so its per-node times are shares, not costs. Here the shipped graphs are cut at the LSTM's input
(``onnx.utils.extract_model``) and every part is timed alone as ``python -m bench`` times a model
(``edge_runtime.core.onnx.open_session``: one intra-op thread, no spinning, all graph
optimisations; batch 1, ``session.run`` with a pre-built feed), in interleaved rounds so that
the parts share the machine's noise:

* ``full``: the model; ``conv stack``: its input to the LSTM's input (the captures of a
  simulated drive, preprocessed); ``lstm+head``: the LSTM's input to the probabilities;
* ``lstm``: the fp32 LSTM node alone, and ``lstm dynamic int8``: the same node after
  ``onnxruntime.quantization.quantize_dynamic`` (DynamicQuantizeLSTM, int8 weights);
* ``empty run``: an Identity graph, what one ``session.run`` costs before any node runs.

Each part's time includes one empty run, so the parts add up to more than the whole. Needs the
``onnx`` package (the export extra).
"""
from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

import numpy as np

from bench.timing import interleaved_calls, summarize
from edge_runtime.cli import CliError, OneLineParser, positive_int, run

ARCH = "convlstm"


def _lstm_input(model) -> str:
    return next(n.input[0] for n in model.graph.node if n.op_type == "LSTM")


def _parts(assets: Path, tmp: Path) -> dict[str, tuple[Path, str, str]]:
    """name -> (ONNX file, its input, its output)."""
    import onnx
    import onnx.utils
    from onnx import TensorProto, helper
    from onnxruntime.quantization import QuantType, quantize_dynamic

    from edge_runtime.core.manifest import load_manifest

    parts: dict[str, tuple[Path, str, str]] = {}
    for e in load_manifest(assets)["models"]:
        if e["arch"] != ARCH:
            continue
        src = assets / e["file"]
        model = onnx.load(src)
        mid, out = _lstm_input(model), model.graph.output[0].name
        inp = model.graph.input[0].name
        parts[f"{e['precision']} full"] = (src, inp, out)
        for name, a, b in (("conv stack", inp, mid), ("lstm+head", mid, out)):
            path = tmp / f"{e['precision']}-{name.replace(' ', '_')}.onnx"
            onnx.utils.extract_model(str(src), str(path), [a], [b])
            parts[f"{e['precision']} {name}"] = (path, a, b)
        if e["precision"] == "fp32":
            lstm = next(n for n in model.graph.node if n.op_type == "LSTM")
            path = tmp / "lstm.onnx"
            onnx.utils.extract_model(str(src), str(path), [mid], [lstm.output[1]])
            parts["fp32 lstm"] = (path, mid, lstm.output[1])
            quantize_dynamic(str(path), str(tmp / "lstm-dyn.onnx"), op_types_to_quantize=["LSTM"],
                             weight_type=QuantType.QInt8)
            parts["lstm dynamic int8"] = (tmp / "lstm-dyn.onnx", mid, lstm.output[1])
    empty = helper.make_graph([helper.make_node("Identity", ["x"], ["y"])], "empty",
                              [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 6])],
                              [helper.make_tensor_value_info("y", TensorProto.FLOAT, [1, 6])])
    onnx.save(helper.make_model(empty, opset_imports=[helper.make_opsetid("", 17)]), tmp / "empty.onnx")
    parts["empty run"] = (tmp / "empty.onnx", "x", "y")
    return parts


def _capture_input(seed: int) -> np.ndarray:
    """One preprocessed detector capture of a simulated drive (1, 6, 33, 3)."""
    from edge_runtime.wearable.classifier import preprocess
    from edge_runtime.wearable.detector import detect_triggers, extract_captures
    from firmware_sim.devices.wrist import simulate_drive

    acc = simulate_drive(5.0, seed=seed).acc_mps2
    return preprocess(extract_captures(acc, detect_triggers(acc))[0].data[None])


def measure(assets: Path, n: int, seed: int = 1) -> list[dict]:
    from edge_runtime.core.onnx import open_session

    with tempfile.TemporaryDirectory(prefix="bench-parts-") as tmp:
        parts = _parts(assets, Path(tmp))
        sessions = {k: open_session(str(path), 1) for k, (path, _, _) in parts.items()}
    x = _capture_input(seed)
    values = {parts["fp32 full"][1]: x, "x": np.zeros((1, 6), np.float32)}
    for k in ("fp32 conv stack", "int8 conv stack"):  # each precision's LSTM input, from its own conv stack
        _, a, b = parts[k]
        values[b] = sessions[k].run([b], {a: x})[0]
    calls = {}
    for k, (_, a, b) in parts.items():
        feed = {a: values[a]}
        calls[k] = (lambda s, o, f: lambda: s.run(o, f))(sessions[k], [b], feed)
    times = interleaved_calls(calls, n, rounds=4, warmup=200)
    return [{"part": k, **summarize(t)} for k, t in times.items()]


def main(argv: list[str] | None = None) -> int:
    p = OneLineParser(prog="python -m bench.model_parts", description=__doc__.splitlines()[0])
    p.add_argument("--assets", default=None, help="assets directory (default: the shipped one)")
    p.add_argument("--n", type=positive_int, default=4000, help="timed calls per part (default 4000)")
    p.add_argument("--json", default=None, metavar="OUT.json")
    a = p.parse_args(argv)

    def cmd() -> int:
        import os

        from edge_runtime.core.manifest import ASSETS_DIR

        if a.json and not Path(a.json).resolve().parent.is_dir():  # before minutes of measuring, not after
            raise CliError(f"--json {a.json}: directory {Path(a.json).parent} does not exist")
        rows = measure(Path(a.assets) if a.assets else ASSETS_DIR, a.n)
        print(f"load average {[round(v, 2) for v in os.getloadavg()]}; p50/p99 us of session.run, 1 thread, batch 1")
        for r in rows:
            print(f"  {r['part']:<20} p50 {r['p50_us']:8.1f}  p99 {r['p99_us']:9.1f}")
        if a.json:
            Path(a.json).write_text(json.dumps({"command": "python -m bench.model_parts " + " ".join(sys.argv[1:]),
                                                "load_average": os.getloadavg(), "rows": rows}, indent=2))
        return 0

    from edge_runtime.errors import ManifestError, ModelIntegrityError

    return run(cmd, bad_input=(ManifestError, ModelIntegrityError, ValueError), what="bench.model_parts",
               extra="export")


if __name__ == "__main__":
    sys.exit(main())
