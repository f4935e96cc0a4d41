"""The box installs edge_runtime and its assets, nothing else, and inside it imports flow one way.

1. A subprocess in which torch (and onnx, models, export, bench, firmware_sim)
   cannot be imported loads the SHIPPED assets through the manifest and
   classifies a window and a capture.
2. An AST scan of every module of edge_runtime checks the dependency rules of
   docs/design.md section 2, one test per rule. It sees module-level and
   function-level imports, relative and absolute, the string literals given to
   ``importlib.import_module`` / ``__import__`` / ``find_spec``, and the strings
   that name a module to import later: "package.module:Name" specs (as config's
   SECTIONS has them) and plain "edge_runtime.<package>..." module names.
"""
from __future__ import annotations

import ast
import importlib.util
import json
import re
import subprocess
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest
from support import REPO_ROOT
from support.source import module_name, repo_files

RUNTIME = REPO_ROOT / "edge_runtime"
TORCH_SIDE = ("torch", "torchvision", "onnx", "onnxscript", "models", "export", "bench", "firmware_sim")
FEATURES = ("edge_runtime.wearable", "edge_runtime.robot", "edge_runtime.posture")


@dataclass(frozen=True)
class Rule:
    name: str
    importer: str
    """The module, or package of modules, the rule applies to."""
    forbidden: tuple[str, ...]
    """Modules (and everything under them) the importer must not import."""
    why: str


RULES = (
    Rule("runtime-is-torch-free", "edge_runtime", TORCH_SIDE,
         "a box carries edge_runtime and its assets only: no torch, no training, export, bench or simulator code"),
    Rule("wearable-imports-no-robot", "edge_runtime.wearable", ("edge_runtime.robot",),
         "the features are installed separately: the wearable never needs the robot side"),
    Rule("robot-imports-no-wearable", "edge_runtime.robot", ("edge_runtime.wearable",),
         "the features are installed separately: the robot side never needs the wearable"),
    Rule("core-imports-no-feature", "edge_runtime.core", FEATURES,
         "core is below every feature: shared code must not depend on what it serves"),
    Rule("canbus-imports-no-feature", "edge_runtime.canbus", FEATURES,
         "canbus is below every feature: shared code must not depend on what it serves"),
    Rule("config-imports-no-feature", "edge_runtime.config", FEATURES,
         "config imports no feature: each feature registers its own section"),
)

IMPORT_SPEC = re.compile(r"(?P<module>[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*):[A-Za-z_]\w*(?:\.[A-Za-z_]\w*)*")
"""An entry-point style "package.module:Name" string: a module named now, imported later."""
RUNTIME_MODULE_NAME = re.compile(r"edge_runtime(?:\.[A-Za-z_]\w*)+")


@dataclass(frozen=True)
class Reference:
    """One statement or string of a module that imports, or names for importing, other modules."""
    line: int
    modules: tuple[str, ...]
    """What it makes importable, broadest first (``from a import b`` may import ``a`` or ``a.b``)."""
    how: str


def within(module: str, packages: tuple[str, ...]) -> bool:
    return any(module == p or module.startswith(p + ".") for p in packages)


def _literal(node: ast.AST | None) -> str | None:
    return node.value if isinstance(node, ast.Constant) and isinstance(node.value, str) else None


def _call_name(call: ast.Call) -> str:
    return getattr(call.func, "attr", getattr(call.func, "id", ""))


def _dynamic_import(call: ast.Call) -> tuple[str | None, str | None]:
    """(the literal module name, the literal ``package``) of an import_module/__import__/find_spec call."""
    package = next((_literal(k.value) for k in call.keywords if k.arg == "package"), None)
    if package is None and len(call.args) > 1 and _call_name(call) != "__import__":
        package = _literal(call.args[1])
    return (_literal(call.args[0]) if call.args else None), package


def references(root: Path, path: Path) -> Iterator[Reference]:
    module = module_name(root, path)
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    consumed: set[int] = set()  # string literals already seen as an importlib argument
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"), filename=str(path))):
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield Reference(node.lineno, (alias.name,), f"import {alias.name}")
        elif isinstance(node, ast.ImportFrom):
            base = importlib.util.resolve_name("." * node.level + (node.module or ""), package)
            names = ", ".join(a.name for a in node.names)
            yield Reference(node.lineno, (base, *(f"{base}.{a.name}" for a in node.names if a.name != "*")),
                            f"from {'.' * node.level}{node.module or ''} import {names}")
        elif isinstance(node, ast.Call) and _call_name(node) in ("import_module", "__import__", "find_spec"):
            name, anchor = _dynamic_import(node)
            if name is None:
                continue  # a computed name: the strings it is made from are scanned below
            consumed.add(id(node.args[0]))
            target = importlib.util.resolve_name(name, anchor) if name.startswith(".") and anchor else name
            if _call_name(node) == "find_spec":
                # find_spec imports the parents of a dotted name; a top-level name is only looked up
                # (sim_source probes for firmware_sim that way and then starts it as a process)
                target = target.rpartition(".")[0]
                if not target:
                    continue
            yield Reference(node.lineno, (target,), f"{_call_name(node)}({name!r})")
        elif (text := _literal(node)) is not None and id(node) not in consumed:
            spec = IMPORT_SPEC.fullmatch(text)
            if spec or RUNTIME_MODULE_NAME.fullmatch(text):
                yield Reference(node.lineno, (spec["module"] if spec else text,), f"the string {text!r}")


def violations(root: Path, rule: Rule) -> list[str]:
    """``file:line: how -> module`` for every reference of the rule's modules to a forbidden one."""
    out = []
    for path in repo_files(root / "edge_runtime", ".py"):
        if not within(module_name(root, path), (rule.importer,)):
            continue
        for ref in sorted(references(root, path), key=lambda r: r.line):
            hit = next((m for m in ref.modules if within(m, rule.forbidden)), None)
            if hit is not None:
                out.append(f"{path.relative_to(root)}:{ref.line}: {ref.how} -> {hit}")
    return out


@pytest.mark.parametrize("rule", RULES, ids=[r.name for r in RULES])
def test_import_rule(rule):
    scope = RUNTIME / Path(*rule.importer.split(".")[1:])
    assert scope.is_dir() or scope.with_suffix(".py").is_file(), f"{rule.importer} is gone: update the rule"
    bad = violations(REPO_ROOT, rule)
    assert not bad, f"{rule.importer} must not import {', '.join(rule.forbidden)} ({rule.why}):\n" + "\n".join(bad)


def _relative(importer_package: str, target: str) -> str | None:
    """``from ..robot import x`` spelling of ``target`` seen from ``importer_package``, if both are ours."""
    here, there = importer_package.split("."), target.split(".")
    common = 0
    while common < min(len(here), len(there)) and here[common] == there[common]:
        common += 1
    return "." * (len(here) - common + 1) + ".".join(there[common:]) if common else None


@pytest.mark.parametrize("rule", RULES, ids=[r.name for r in RULES])
def test_import_rule_catches_planted_violations(rule, tmp_path):
    """Every way of importing a forbidden module, planted in a module the rule covers, is reported
    on its own line; allowed imports are not."""
    parts = rule.importer.split(".")
    planted = tmp_path.joinpath(*parts).with_suffix(".py") if rule.importer.endswith(".config") \
        else tmp_path.joinpath(*parts, "planted.py")
    planted.parent.mkdir(parents=True, exist_ok=True)
    target = f"{rule.forbidden[-1]}.sub"
    lines = [
        "import importlib, importlib.util",
        "import numpy as np",
        "from edge_runtime.errors import EdgeError",
        "importlib.util.find_spec('firmware_sim')",
        "PORT = 'serial:PATH'",
        f"import {target}",
        "def lazy():",
        f"    from {target} import Thing",
        f"    return importlib.import_module({target!r})",
        f"SPEC = importlib.util.find_spec({target + '.deeper'!r})",
        f"SECTIONS = (('planted', {target + ':Params'!r}),)",
    ]
    relative = _relative(module_name(tmp_path, planted).rpartition(".")[0], target)
    if relative:
        lines += [f"from {relative} import Thing", f"NAME = {target!r}"]
    planted.write_text("\n".join(lines) + "\n")
    found = violations(tmp_path, rule)
    rel = planted.relative_to(tmp_path)
    assert [v.split(":", 2)[1] for v in found] == [str(n) for n in range(6, len(lines) + 1) if n != 7], found
    assert all(v.startswith(f"{rel}:") and v.endswith(f"-> {target}") for v in found), found


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


@pytest.mark.slow
def test_runtime_runs_shipped_models_without_torch():
    if not (RUNTIME / "assets" / "manifest.json").exists():
        pytest.fail("edge_runtime/assets/manifest.json is missing: build it with `python -m export assets --seed 0`")
    code = BLOCKER.format(blocked=sorted(TORCH_SIDE)) + PROGRAM
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=REPO_ROOT, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    out = json.loads(r.stdout.strip().splitlines()[-1])
    for prec in ("int8", "fp32"):
        k = len(out[prec]["classes"])
        assert out[prec]["shape"] == [k] and abs(out[prec]["sum"] - 1) < 1e-4
        assert out[prec]["batch"] == [2, k]
    assert out["blocked_loaded"] == []
