"""manifest.json -> load_manifest's checks -> model selection and the lifter's entry checks.

An input is the shipped ``edge_runtime/assets/manifest.json`` with a few fields, at any
depth, replaced by hostile values, deleted, or the bytes damaged
(:func:`fuzz.targets.calibration_json.mutated_json`). A refusal must be the documented
ModelIntegrityError (ManifestError is one); an accepted manifest must let the runtime
select its models by name, precision and arch without any other exception, and a lifter
entry it accepts must have a receptive field the lifter can allocate.
"""
from __future__ import annotations

import functools
import json
import tempfile
from pathlib import Path

from edge_runtime.core.manifest import ASSETS_DIR, MANIFEST_NAME, load_manifest, select_model
from edge_runtime.errors import ModelIntegrityError
from edge_runtime.robot.lifter import _check_entry
from fuzz.harness import SilentAcceptance
from fuzz.targets.calibration_json import mutated_json

NAME = "manifest_json"
DOCUMENTED = (ModelIntegrityError,)


@functools.lru_cache(maxsize=1)
def seed() -> dict:
    return json.loads((ASSETS_DIR / MANIFEST_NAME).read_text(encoding="utf-8"))


@functools.lru_cache(maxsize=1)
def scratch() -> Path:
    """One directory for the process's inputs (each run overwrites its manifest.json)."""
    return Path(tempfile.mkdtemp(prefix="fuzz-manifest-"))


def strategy():
    return mutated_json(seed())


def run(raw: bytes) -> None:
    path = scratch() / MANIFEST_NAME
    path.write_bytes(raw)
    manifest = load_manifest(path)
    for m in manifest["models"]:
        for key in (m["name"], m["precision"]):
            select_model(manifest, key, arch=m["arch"])
        if m["arch"] == "lifter":
            rf, _ = _check_entry(m, str(path))
            if not 1 <= rf <= 1024:
                raise SilentAcceptance(f"a lifter entry with receptive_field {rf} was accepted")
