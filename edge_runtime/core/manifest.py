"""``assets/manifest.json``: what the box runs, and the proof that it is what was built.

numpy-free, torch-free: the standard library only (and :mod:`edge_runtime.core.strict_json`).

Schema (``SCHEMA_VERSION`` 1; ``python -m export assets`` writes it)::

    {
      "version": 1,                     # manifest schema version
      "created_by": "python -m export assets --seed 0 ...",
      "models": [
        {
          "name": "convlstm-int8",      # unique; Engine.from_manifest(dir, name_or_precision)
          "file": "convlstm.int8.onnx", # relative to the assets directory, no sub-directories
          "sha256": "...",              # of the file's bytes; checked before every load
          "precision": "int8",          # "fp32" | "int8"
          "arch": "convlstm",
          "model_version": "...",
          "parameters": {"torch": 79998, "keras": 79598},
          "inputs":  [{"name": "imu", "shape": ["N", 6, 33, 3], "dtype": "float32",
                       "layout": "...", "units": "m/s^2"}],
          "outputs": [{"name": "probs", "shape": ["N", 6], "dtype": "float32"}, ...],
          "classes": ["Phone", ...],    # model-output order; [] for a model that is not a
                                        # classifier (arch "lifter", which adds "receptive_field",
                                        # "joints" and "camera": see edge_runtime/robot/lifter.py)
          "metrics": {...},             # how well it does, and on what
          "quantization": {...},        # int8 only: method, calibration, int8 operators, candidates
          "provenance": {"command", "seed", "data", "git_commit", "versions": {...}}
        }, ...
      ]
    }

:func:`load_manifest` validates the structure; :func:`verify_file` checks a
model file against its sha256. Any problem raises :class:`ManifestError` or
:class:`ModelIntegrityError` (both one-line, both naming the file).

The sha256 proves integrity, not origin: whoever replaces a model can replace its hash too.
A box configured with a public key (``[model] manifest_public_key`` / ``[lifter]
manifest_public_key``) also requires ``manifest.json.sig``, an Ed25519 signature of the
manifest's bytes made by ``python -m export sign`` with the builder's private key, and refuses
a manifest it does not verify; the models are then bound to the builder through their hashes.
The check needs the ``signed-models`` extra (``cryptography``); without a key configured
nothing changes.
"""
from __future__ import annotations

import hashlib
import json
import os
from pathlib import Path
from typing import Any

from edge_runtime.core import strict_json
from edge_runtime.errors import ManifestError, ModelIntegrityError

SCHEMA_VERSION = 1
MANIFEST_NAME = "manifest.json"
SIGNATURE_SUFFIX = ".sig"
"""The manifest's detached Ed25519 signature: ``manifest.json.sig`` (64 raw bytes)."""
ASSETS_DIR = Path(__file__).resolve().parents[1] / "assets"
"""The shipped models, their manifest and the DBCs (edge_runtime/assets)."""
PRECISIONS = ("fp32", "int8")
CLASSIFIER_ARCHS = ("convlstm", "cnn", "lstm", "lda")
"""Architectures whose entries must list their ``classes``; other models (the pose
lifter) list ``[]``."""
STEP_ARCH = "convlstm_step"
"""The ConvLSTM's streaming step model (one sub-window and the LSTM state per run): the arch of the entry a
classifier entry's ``step_model`` names (``export.step_model`` writes it, the wearable runtime and the bench
read it; defined here, where all three may import it)."""
STREAM_ARCH = "stream"
"""The trigger-free streaming classifier (issue 12): the last W s of the wrist stream at 25 Hz in, the class out,
every hop (``export.stream_model`` writes its entries, ``edge_runtime.wearable.stream_decider`` reads them)."""
_REQUIRED_MODEL_KEYS = ("name", "file", "sha256", "precision", "arch", "parameters", "inputs",
                        "outputs", "classes")
_OBJECT_KEYS = ("parameters", "metrics", "quantization", "provenance", "camera")
"""Entry fields that, when present, must be JSON objects."""
_STRING_KEYS = ("model_version", "joints", "step_model")
"""Entry fields that, when present, must be strings."""


def sha256_file(path: str | os.PathLike) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for chunk in iter(lambda: f.read(1 << 20), b""):
            h.update(chunk)
    return h.hexdigest()


def sha256_bytes(data: bytes) -> str:
    return hashlib.sha256(data).hexdigest()


def manifest_path(assets_dir: str | os.PathLike) -> Path:
    p = Path(assets_dir)
    return p if p.suffix == ".json" else p / MANIFEST_NAME


def _check_model(entry: Any, i: int, where: str) -> None:
    """Every field of one model entry, by type (and the file name, hash and precision by value)."""
    def fail(field: str, msg: str):
        raise ManifestError(f"{where}: field 'models[{i}].{field}': {msg}")

    if not isinstance(entry, dict):
        raise ManifestError(f"{where}: field 'models[{i}]': expected an object")
    for key in _REQUIRED_MODEL_KEYS:
        if key not in entry:
            fail(key, "missing")
    for key in ("name", "arch"):
        if not (isinstance(entry[key], str) and entry[key]):
            fail(key, f"expected a non-empty string, got {_short(entry[key])}")
    f = entry["file"]
    if not isinstance(f, str) or not f or Path(f).name != f or f in (".", ".."):
        fail("file", f"{_short(f)} must be a plain file name inside the assets directory")
    sha = entry["sha256"]
    if not (isinstance(sha, str) and len(sha) == 64 and all(c in "0123456789abcdef" for c in sha)):
        fail("sha256", "expected 64 lowercase hex digits")
    if not isinstance(entry["precision"], str) or entry["precision"] not in PRECISIONS:
        fail("precision", f"{_short(entry['precision'])} not one of {PRECISIONS}")
    classes = entry["classes"]
    if not (isinstance(classes, list) and all(isinstance(c, str) and c for c in classes)
            and len(set(classes)) == len(classes)):
        fail("classes", "expected unique non-empty strings")
    if not classes and entry["arch"] in CLASSIFIER_ARCHS:
        fail("classes", f"a {entry['arch']} classifier needs its class list")
    for key in ("inputs", "outputs"):
        io = entry[key]
        if not (isinstance(io, list) and io and all(_is_tensor(t) for t in io)):
            fail(key, "expected a list of {name: string, shape: [integer or string, ...], dtype: string}")
    for key in _OBJECT_KEYS:
        if key in entry and not isinstance(entry[key], dict):
            fail(key, f"expected an object, got {_short(entry[key])}")
    for key in _STRING_KEYS:
        if key in entry and not isinstance(entry[key], str):
            fail(key, f"expected a string, got {_short(entry[key])}")


def _is_tensor(t: Any) -> bool:
    """An inputs/outputs entry: a name, and when given a shape of dimensions and a dtype."""
    if not (isinstance(t, dict) and isinstance(t.get("name"), str) and t["name"]):
        return False
    shape = t.get("shape", [])
    dims_ok = isinstance(shape, list) and all(
        isinstance(d, str) or (isinstance(d, int) and not isinstance(d, bool) and 0 <= d <= 2**31) for d in shape)
    return dims_ok and isinstance(t.get("dtype", ""), str)


def _short(value: Any) -> str:
    r = repr(value)
    return r if len(r) <= 40 else r[:37] + "..."


def example_shape(spec: dict, batch: int = 1) -> tuple[int, ...]:
    """A concrete shape for a manifest input ``spec``: the batch axis ``batch``, an axis named in
    ``spec["steps"]`` (the ConvLSTM's dynamic sub-window count ``S``) its ``full_capture`` value, so
    a timing or comparison runs the full-window decision, an axis ``spec["dims"]`` names its value there (the
    streaming classifier's window length ``T``: the runtime's), and any other symbolic axis 1."""
    full = spec.get("steps", {}).get("full_capture", 1) if isinstance(spec.get("steps"), dict) else 1
    named = spec.get("dims") if isinstance(spec.get("dims"), dict) else {}
    dims = spec.get("shape", [])
    return tuple([batch] + [d if isinstance(d, int) else full if d == "S" else int(named.get(d, 1))
                            for d in dims[1:]]) if dims else ()


def signature_path(manifest_file: str | os.PathLike) -> Path:
    p = Path(manifest_file)
    return p.with_name(p.name + SIGNATURE_SUFFIX)


def _ed25519():
    """cryptography's Ed25519 pieces, or a one-line ManifestError naming the extra."""
    try:
        from cryptography.exceptions import InvalidSignature
        from cryptography.hazmat.primitives import serialization
        from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PublicKey
    except ModuleNotFoundError:
        raise ManifestError("checking a signed manifest needs cryptography: "
                            "pip install 'edge-safety[signed-models]'") from None
    return serialization, Ed25519PublicKey, InvalidSignature


def load_public_key(key_file: str | os.PathLike):
    """The Ed25519 public key in ``key_file`` (PEM, as ``python -m export sign --keygen`` writes it)."""
    serialization, Ed25519PublicKey, _ = _ed25519()
    try:
        key = serialization.load_pem_public_key(Path(key_file).read_bytes())
    except OSError as e:
        raise ManifestError(f"{key_file}: cannot read the manifest public key ({e.strerror or e})") from None
    except ValueError:
        raise ManifestError(f"{key_file}: not a PEM public key") from None
    if not isinstance(key, Ed25519PublicKey):
        raise ManifestError(f"{key_file}: not an Ed25519 public key")
    return key


def verify_signature(manifest_file: Path, raw: bytes, public_key_file: str | os.PathLike) -> None:
    """ManifestError unless ``manifest_file.sig`` is the Ed25519 signature of ``raw`` (the very
    bytes that are then parsed) by the key in ``public_key_file``."""
    key = load_public_key(public_key_file)
    *_, invalid_signature = _ed25519()
    sig_file = signature_path(manifest_file)
    try:
        signature = sig_file.read_bytes()
    except OSError as e:
        raise ManifestError(f"{sig_file}: the box requires a signed manifest and cannot read its "
                            f"signature ({e.strerror or e})") from None
    try:
        key.verify(signature, raw)
    except invalid_signature:
        raise ManifestError(f"{sig_file}: the manifest's signature does not verify with "
                            f"{public_key_file}: refusing its models") from None


def load_manifest(assets_dir: str | os.PathLike, public_key_file: str | os.PathLike | None = None) -> dict:
    """Read and validate ``assets_dir/manifest.json`` (or a manifest path itself): every
    field the runtime reads is checked for its type, in one line naming the field. With
    ``public_key_file``, the manifest's signature is checked first (see the module docstring)."""
    path = manifest_path(assets_dir)
    if not path.is_file():
        raise ManifestError(f"{path}: manifest not found (rebuild with `python -m export assets --seed 0`)")
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise ManifestError(f"{path}: cannot read ({e.strerror or e})") from None
    if public_key_file:
        verify_signature(path, raw, public_key_file)
    data = strict_json.loads(raw, str(path), ManifestError)
    if not isinstance(data, dict):
        raise ManifestError(f"{path}: expected a JSON object at the top level")
    version = data.get("version")
    if version != SCHEMA_VERSION or isinstance(version, bool):
        raise ManifestError(f"{path}: field 'version': {_short(version)}, this runtime reads "
                            f"version {SCHEMA_VERSION}")
    if not isinstance(data.get("created_by", ""), str):
        raise ManifestError(f"{path}: field 'created_by': expected a string")
    models = data.get("models")
    if not isinstance(models, list) or not models:
        raise ManifestError(f"{path}: field 'models': expected a non-empty list")
    for i, m in enumerate(models):
        _check_model(m, i, str(path))
    names = [m["name"] for m in models]
    if len(set(names)) != len(names):
        raise ManifestError(f"{path}: field 'models[].name': names must be unique, got {names}")
    return data


def select_model(manifest: dict, name_or_precision: str = "int8", where: str = MANIFEST_NAME,
                 arch: str | tuple[str, ...] | None = None) -> dict:
    """The entry named ``name_or_precision``; else the first entry with that precision.

    With ``arch`` (a name or a tuple of names), only entries of that architecture are
    candidates (a manifest may ship a classifier and the pose lifter side by side)."""
    archs = (arch,) if isinstance(arch, str) else arch
    models = [m for m in manifest["models"] if archs is None or m["arch"] in archs]
    if not models:
        raise ManifestError(f"{where}: field 'models': no model of arch {arch!r} (the manifest lists "
                            f"{', '.join(sorted({m['arch'] for m in manifest['models']}))})")
    for m in models:
        if m["name"] == name_or_precision:
            return m
    for m in models:
        if m["precision"] == name_or_precision:
            return m
    choices = sorted({m["name"] for m in models} | {m["precision"] for m in models})
    raise ManifestError(f"{where}: field 'models': no model named or of precision {name_or_precision!r} "
                        f"(choose one of {', '.join(choices)})")


def read_verified(assets_dir: str | os.PathLike, entry: dict) -> bytes:
    """The model file's bytes, after checking them against the manifest's sha256.

    The bytes that were hashed are the bytes that get loaded (no window between
    the check and the load)."""
    path = Path(assets_dir) / entry["file"]
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise ModelIntegrityError(f"{path}: model file listed in the manifest is missing") from None
    except OSError as e:
        raise ModelIntegrityError(f"{path}: cannot read model file ({e.strerror or e})") from None
    got = sha256_bytes(data)
    if got != entry["sha256"]:
        raise ModelIntegrityError(f"{path}: sha256 mismatch (manifest {entry['sha256'][:12]}..., "
                                  f"file {got[:12]}...): refusing to load a model that is not the one shipped")
    return data


def load_verified(assets_dir: str | os.PathLike, name_or_precision: str = "int8",
                  arch: str | tuple[str, ...] | None = None,
                  public_key_file: str | os.PathLike | None = None) -> tuple[dict, bytes, Path]:
    """(manifest entry, hash-checked model bytes, model path) for ``name_or_precision``
    (a name or a precision), optionally among the entries of one ``arch``; with
    ``public_key_file``, from a manifest whose signature verifies."""
    mpath = manifest_path(assets_dir)
    entry = select_model(load_manifest(assets_dir, public_key_file), name_or_precision, str(mpath), arch=arch)
    return entry, read_verified(mpath.parent, entry), mpath.parent / entry["file"]


def verify_file(assets_dir: str | os.PathLike, entry: dict) -> None:
    read_verified(assets_dir, entry)


def verify_all(assets_dir: str | os.PathLike) -> dict:
    """Load the manifest and check every model file's hash; returns the manifest."""
    m = load_manifest(assets_dir)
    base = manifest_path(assets_dir).parent
    for entry in m["models"]:
        verify_file(base, entry)
    return m


def write_manifest(assets_dir: str | os.PathLike, manifest: dict) -> Path:
    """Validate and write ``manifest.json`` (sorted keys, stable bytes)."""
    path = manifest_path(assets_dir)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.stem + ".tmp.json")
    tmp.write_text(json.dumps(manifest, indent=2, sort_keys=True, allow_nan=False) + "\n", encoding="utf-8")
    try:
        load_manifest(tmp)
    except ManifestError:
        tmp.unlink(missing_ok=True)
        raise
    os.replace(tmp, path)
    return path
