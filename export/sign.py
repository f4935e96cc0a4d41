"""``python -m export sign``: who built the models, not only that they are intact.

    python -m export sign --keygen keys/            # keys/manifest_signing.pem (private, 0600) + .pub.pem
    python -m export sign --key keys/manifest_signing.pem [--assets DIR]   # writes DIR/manifest.json.sig

The signature is Ed25519 over the manifest's bytes; the manifest holds every model's sha256, so
a box that verifies it (``manifest_public_key`` in its ``[model]`` or ``[lifter]`` section)
refuses a model replaced together with its hash. Sign after the last change to the manifest (a
rebuild, ``export opsets``, ``export int8``): any later byte change voids the signature, and the
box then refuses the models, as it should. The private key stays on the build machine; only the
``.pub.pem`` goes onto boxes.
"""
from __future__ import annotations

import os
from pathlib import Path

PRIVATE_NAME = "manifest_signing.pem"
PUBLIC_NAME = "manifest_signing.pub.pem"


class SignError(ValueError):
    """A key or an assets directory that cannot be used; one line naming it."""


BAD_INPUT = (SignError,)


def _crypto():
    try:
        from cryptography.hazmat.primitives import serialization
        from cryptography.hazmat.primitives.asymmetric.ed25519 import Ed25519PrivateKey
    except ModuleNotFoundError:
        raise SignError("signing needs cryptography: pip install 'edge-safety[signed-models]'") from None
    return serialization, Ed25519PrivateKey


def keygen(out_dir: str | os.PathLike) -> tuple[Path, Path]:
    """A new Ed25519 key pair in ``out_dir``: (private PEM, readable by its owner only; public PEM)."""
    serialization, Ed25519PrivateKey = _crypto()
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    private, public = out / PRIVATE_NAME, out / PUBLIC_NAME
    if private.exists():
        raise SignError(f"{private}: exists; refusing to overwrite a signing key")
    key = Ed25519PrivateKey.generate()
    pem = key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                            serialization.NoEncryption())
    fd = os.open(private, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
    with os.fdopen(fd, "wb") as f:
        f.write(pem)
    public.write_bytes(key.public_key().public_bytes(serialization.Encoding.PEM,
                                                     serialization.PublicFormat.SubjectPublicKeyInfo))
    return private, public


def sign_manifest(assets_dir: str | os.PathLike, key_file: str | os.PathLike) -> Path:
    """Write ``manifest.json.sig`` beside the manifest of ``assets_dir``, after checking that the
    manifest is valid and every model matches its hash (a signature vouches for what is there)."""
    from edge_runtime.core.manifest import manifest_path, signature_path, verify_all

    serialization, Ed25519PrivateKey = _crypto()
    try:
        key = serialization.load_pem_private_key(Path(key_file).read_bytes(), password=None)
    except OSError as e:
        raise SignError(f"{key_file}: cannot read the signing key ({e.strerror or e})") from None
    except (ValueError, TypeError):
        raise SignError(f"{key_file}: not an unencrypted PEM private key") from None
    if not isinstance(key, Ed25519PrivateKey):
        raise SignError(f"{key_file}: not an Ed25519 private key")
    verify_all(assets_dir)
    manifest = manifest_path(assets_dir)
    sig = signature_path(manifest)
    sig.write_bytes(key.sign(manifest.read_bytes()))
    return sig


def add_arguments(p) -> None:
    what = p.add_mutually_exclusive_group(required=True)
    what.add_argument("--key", help="the Ed25519 private key (PEM) to sign with")
    what.add_argument("--keygen", metavar="DIR", help=f"write a new key pair: DIR/{PRIVATE_NAME}, DIR/{PUBLIC_NAME}")
    p.add_argument("--assets", default=None, help="assets directory (default: edge_runtime/assets)")


def cmd(args) -> int:
    if args.keygen:
        private, public = keygen(args.keygen)
        print(f"wrote {private} (keep it on the build machine) and {public} (for the boxes' "
              f"manifest_public_key)")
        return 0
    from edge_runtime.core.manifest import ASSETS_DIR

    sig = sign_manifest(args.assets or ASSETS_DIR, args.key)
    print(f"wrote {sig}")
    return 0
