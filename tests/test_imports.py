"""The box installs edge_runtime and its assets, nothing else: prove it runs without torch.

1. A subprocess in which torch (and onnx, models, export, bench, firmware_sim)
   cannot be imported loads the SHIPPED assets through the manifest and
   classifies a window and a capture.
2. An AST scan: no module of edge_runtime imports torch or the training-side packages.
"""
import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
RUNTIME = ROOT / "edge_runtime"
FORBIDDEN = {"torch", "torchvision", "onnx", "onnxscript", "models", "export", "bench", "firmware_sim"}

BLOCKER = """
import sys, importlib.abc
BLOCKED = {blocked!r}
class _Block(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name.split('.')[0] in BLOCKED:
            raise ImportError(f"{{name}} is blocked in this test (a box without torch)")
        return None
sys.meta_path.insert(0, _Block())
for _m in list(sys.modules):
    if _m.split('.')[0] in BLOCKED:
        del sys.modules[_m]
"""

PROGRAM = """
import json
try:
    import torch
except ImportError:
    pass
else:
    raise SystemExit("torch is importable: the blocker does not work")
import numpy as np
import edge_runtime
from edge_runtime.core.manifest import ASSETS_DIR
from edge_runtime.wearable.classifier import Engine
from edge_runtime.core.manifest import verify_all
verify_all(ASSETS_DIR)
out = {}
for prec in ("int8", "fp32"):
    e = Engine.from_manifest(ASSETS_DIR, prec, threads=1)
    rng = np.random.default_rng(0)
    x700 = (rng.normal(0, 2, (700, 3)) + [0, 0, 9.81]).astype(np.float32)
    p = e.classify_capture(x700)
    q = e.classify(np.zeros((2, 6, 33, 3), np.float32))
    out[prec] = {"name": e.name, "shape": list(p.shape), "sum": float(p.sum()), "batch": list(q.shape),
                 "classes": e.classes}
loaded = sorted(m for m in sys.modules if m.split('.')[0] in BLOCKED)
out["blocked_loaded"] = loaded
print(json.dumps(out))
"""


def test_runtime_runs_shipped_models_without_torch():
    if not (RUNTIME / "assets" / "manifest.json").exists():
        pytest.fail("edge_runtime/assets/manifest.json is missing: build it with `python -m export assets --seed 0`")
    code = BLOCKER.format(blocked=sorted(FORBIDDEN)) + PROGRAM
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    for prec in ("int8", "fp32"):
        k = len(out[prec]["classes"])
        assert out[prec]["shape"] == [k] and abs(out[prec]["sum"] - 1) < 1e-4
        assert out[prec]["batch"] == [2, k]
    assert out["blocked_loaded"] == []


def _imports(path: Path):
    tree = ast.parse(path.read_text(), filename=str(path))
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for a in node.names:
                yield node.lineno, a.name
        elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
            yield node.lineno, node.module
        elif isinstance(node, ast.Call) and getattr(node.func, "attr", getattr(node.func, "id", "")) in (
                "import_module", "__import__") and node.args and isinstance(node.args[0], ast.Constant):
            yield node.lineno, str(node.args[0].value)


def test_edge_runtime_source_never_imports_training_side():
    files = sorted(RUNTIME.rglob("*.py"))
    assert files
    bad = [f"{f.relative_to(ROOT)}:{line}: import {mod}" for f in files for line, mod in _imports(f)
           if mod.split(".")[0] in FORBIDDEN]
    assert not bad, "edge_runtime must stay torch-free:\n" + "\n".join(bad)
