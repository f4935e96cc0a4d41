"""The repository's own files, for the checks that read them (imports, citations, slow markers)."""
from __future__ import annotations

import ast
import io
import os
import tokenize
from collections.abc import Iterator
from pathlib import Path

NOT_SOURCE = {"build", "dist", "demo_out", "out", "runs", "__pycache__", "node_modules"}
"""Folders that hold build output or scratch results, never the project's own files (.gitignore)."""


def repo_files(root: Path, suffix: str) -> list[Path]:
    """Every ``*suffix`` file under ``root``, without hidden folders (.git, .venv) and build output."""
    found = []
    for folder, subfolders, names in os.walk(root):
        subfolders[:] = sorted(d for d in subfolders
                               if not d.startswith(".") and d not in NOT_SOURCE and not d.endswith(".egg-info"))
        found += [Path(folder, n) for n in sorted(names) if n.endswith(suffix)]
    return found


def module_name(root: Path, path: Path) -> str:
    """``root/edge_runtime/robot/__init__.py`` -> ``edge_runtime.robot``."""
    parts = list(path.relative_to(root).with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def docstrings_and_comments(path: Path) -> Iterator[tuple[int, str]]:
    """(first line, text) of every bare string statement (docstrings, attribute docstrings) and comment."""
    source = path.read_text(encoding="utf-8")
    for node in ast.walk(ast.parse(source, filename=str(path))):
        if isinstance(node, ast.Expr) and isinstance(node.value, ast.Constant) and isinstance(node.value.value, str):
            yield node.lineno, node.value.value
    for tok in tokenize.generate_tokens(io.StringIO(source).readline):
        if tok.type == tokenize.COMMENT:
            yield tok.start[0], tok.string
