"""A signed manifest (core/manifest.py, export/sign.py): a box configured with a public key
refuses a model replaced together with its sha256, an unsigned manifest and another builder's."""
from __future__ import annotations

import os

import pytest
from support.early_model import write_assets

from edge_runtime import __main__ as table
from edge_runtime.core.manifest import load_manifest, signature_path
from edge_runtime.errors import ManifestError
from edge_runtime.wearable.classifier import Engine
from export import __main__ as export_main
from export.sign import SignError, keygen, sign_manifest

pytest.importorskip("cryptography")


@pytest.fixture
def signed(tmp_path):
    """(assets signed by the builder, the builder's public key file)."""
    private, public = keygen(tmp_path / "keys")
    assets = write_assets(tmp_path / "assets", favour="Phone")
    sign_manifest(assets, private)
    return assets, public


def test_a_signed_manifest_loads_with_its_key(signed):
    assets, public = signed
    assert load_manifest(assets, public)["models"][0]["name"] == "standin-int8"
    assert Engine.from_manifest(assets, "int8", public_key_file=public).name == "standin-int8"


def test_a_model_replaced_with_its_hash_passes_the_hashes_but_not_the_signature(signed):
    assets, public = signed
    write_assets(assets, favour="Other")  # another model and a manifest with its correct sha256
    assert Engine.from_manifest(assets, "int8").name == "standin-int8"  # the hashes alone cannot tell
    with pytest.raises(ManifestError, match="does not verify"):
        Engine.from_manifest(assets, "int8", public_key_file=public)


def test_unsigned_or_signed_by_someone_else_is_refused(signed, tmp_path):
    assets, public = signed
    other_private, other_public = keygen(tmp_path / "other")
    with pytest.raises(ManifestError, match="does not verify"):
        load_manifest(assets, other_public)
    signature_path(assets / "manifest.json").unlink()
    with pytest.raises(ManifestError, match="requires a signed manifest"):
        load_manifest(assets, public)
    nonsense = tmp_path / "nonsense.pem"
    nonsense.write_text("x")
    with pytest.raises(ManifestError, match="not a PEM public key"):
        load_manifest(assets, nonsense)


def test_the_wearable_refuses_tampered_models_in_one_line(signed, tmp_path, capsys):
    assets, public = signed
    box = tmp_path / "box.toml"
    # the stand-in assets hold a capture-path ConvLSTM only: the box decides by it
    box.write_text(f'[alerts]\ndecision = "early"\n[model]\nmanifest_public_key = "{public}"\n')
    csv = tmp_path / "rest.csv"
    csv.write_text("t,ax,ay,az\n" + "".join(f"{i / 100:.2f},0,0,9.81\n" for i in range(300)))
    args = ["wearable", "--config", str(box), "--replay", str(csv), "--assets", str(assets)]
    assert table.main(args) == 0
    write_assets(assets, favour="Other")
    capsys.readouterr()
    assert table.main(args) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "manifest.json.sig" in err and "Traceback" not in err


def test_export_sign_keeps_keys_and_refuses_bad_ones(tmp_path, capsys):
    private, _ = keygen(tmp_path / "keys")
    assert oct(os.stat(private).st_mode & 0o777) == "0o600"
    with pytest.raises(SignError, match="refusing to overwrite"):
        keygen(tmp_path / "keys")
    assets = write_assets(tmp_path / "assets")
    not_a_key = tmp_path / "not_a_key.pem"
    not_a_key.write_text("-----BEGIN PRIVATE KEY-----\nAAAA\n-----END PRIVATE KEY-----\n")
    assert export_main.main(["sign", "--key", str(not_a_key), "--assets", str(assets)]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and "not_a_key.pem" in err
    assert export_main.main(["sign", "--key", str(private), "--assets", str(assets)]) == 0
    assert signature_path(assets / "manifest.json").stat().st_size == 64
