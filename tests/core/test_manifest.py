"""edge_runtime.core.manifest: every field of manifest.json checked by type, one line naming it."""
from __future__ import annotations

import json

import pytest

from edge_runtime.core.manifest import ASSETS_DIR, MANIFEST_NAME, load_manifest
from edge_runtime.errors import ManifestError


def _manifest(tmp_path, edit=None, text: bytes | None = None):
    data = json.loads((ASSETS_DIR / MANIFEST_NAME).read_text(encoding="utf-8"))
    if edit:
        edit(data)
    path = tmp_path / MANIFEST_NAME
    path.write_bytes(text if text is not None else json.dumps(data).encode())
    return path


def _set(key, value, i=0):
    return lambda d: d["models"][i].__setitem__(key, value)


@pytest.mark.parametrize("edit, match", [
    (_set("name", 3), r"models\[0\].name': expected a non-empty string, got 3"),
    (_set("arch", ["lifter"]), r"models\[0\].arch': expected a non-empty string"),
    (_set("precision", ["int8"]), r"models\[0\].precision': \['int8'\] not one of"),
    (_set("inputs", [{"name": "imu", "shape": ["N", 6.5]}]), r"models\[0\].inputs': expected a list of"),
    (_set("outputs", [{"name": "probs", "dtype": 4}]), r"models\[0\].outputs': expected a list of"),
    (_set("parameters", 79998), r"models\[0\].parameters': expected an object, got 79998"),
    (_set("model_version", 2), r"models\[0\].model_version': expected a string"),
    (lambda d: d.__setitem__("version", True), r"field 'version': True"),
    (lambda d: d.__setitem__("models", {}), r"field 'models': expected a non-empty list"),
])
def test_a_field_of_the_wrong_type_is_one_line_naming_it(tmp_path, edit, match):
    path = _manifest(tmp_path, edit)
    with pytest.raises(ManifestError, match=match) as e:
        load_manifest(path)
    assert str(e.value).startswith(f"{path}: ") and "\n" not in str(e.value)


@pytest.mark.parametrize("text, match", [
    (b'{"version": 1, "models": [' + b"[" * 5000 + b"]" * 5000 + b"]}", "nested more than 64 levels"),
    (b'{"version": 1' + b"1" * 400 + b', "models": []}', r"field 'version': 1111"),
    (b'{"version": NaN, "models": []}', "NaN is not JSON"),
    (b'{"version": 1, "created_by": "\xff"}', "not UTF-8 text"),
])
def test_json_that_python_would_accept_or_choke_on_is_one_line(tmp_path, text, match):
    path = _manifest(tmp_path, text=text)
    with pytest.raises(ManifestError, match=match):
        load_manifest(path)


def test_the_shipped_manifest_loads(tmp_path):
    assert load_manifest(_manifest(tmp_path))["version"] == 1
