"""Helpers shared by the tests (not tests themselves): ``tests/`` is on pytest's pythonpath,
so a test module says ``from support.robot import FakeLink``; test modules never import each other."""
from pathlib import Path

REPO_ROOT = Path(__file__).resolve().parents[2]
"""The repository's root folder."""
