"""python -m export bundle: a torch-free runtime wheel, verified assets, a config, checksums --
and the installed wheel runs the wearable loop in a fresh venv without torch."""
import hashlib
import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest
from support import REPO_ROOT

from edge_runtime.core.manifest import load_manifest
from export.__main__ import main as export_main
from export.bundle import SUMS_NAME, BundleError, build_bundle, measure_install, runtime_metadata, venv_python

ROOT = REPO_ROOT
RUNTIME = ROOT / "edge_runtime"

pytestmark = pytest.mark.skipif(not (RUNTIME / "assets" / "manifest.json").exists(), reason="no shipped assets")


@pytest.fixture(scope="module")
def bundle(tmp_path_factory):
    return build_bundle(tmp_path_factory.mktemp("b") / "bundle")


def _sha(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


@pytest.mark.slow
def test_bundle_contents_and_checksums(bundle):
    out = bundle.out
    listed = dict(reversed(line.split("  ", 1)) for line in (out / SUMS_NAME).read_text().splitlines())
    on_disk = {p.relative_to(out).as_posix() for p in out.rglob("*") if p.is_file() and p.name != SUMS_NAME}
    assert set(listed) == on_disk  # every file, nothing else
    assert all(_sha(out / name) == h for name, h in listed.items())
    manifest = load_manifest(out / "assets")
    for e in manifest["models"]:
        assert _sha(out / "assets" / e["file"]) == e["sha256"]
    assert (out / "box.toml").read_text() == (RUNTIME / "box.example.toml").read_text()
    assert bundle.wheel.name in (out / "INSTALL.md").read_text()


@pytest.mark.slow
def test_wheel_is_the_runtime_only(bundle):
    with zipfile.ZipFile(bundle.wheel) as z:
        names = z.namelist()
        meta = z.read(next(n for n in names if n.endswith(".dist-info/METADATA"))).decode()
        tops = {n.split("/")[0] for n in names}
        assert {t for t in tops if not t.endswith(".dist-info")} == {"edge_runtime"}
        for e in load_manifest(RUNTIME / "assets")["models"]:
            assert hashlib.sha256(z.read(f"edge_runtime/assets/{e['file']}")).hexdigest() == e["sha256"]
        assert "edge_runtime/box.example.toml" in names
    requires = [line.split(":", 1)[1].strip().lower() for line in meta.splitlines()
                if line.startswith("Requires-Dist:")]
    assert requires and not any(r.startswith(("torch", "onnx ", "onnx>", "onnxscript")) for r in requires)
    assert any(r.startswith("onnxruntime") for r in requires)
    assert tuple(r.lower() for r in runtime_metadata()[1]) == tuple(requires)


def test_tampered_model_is_not_bundled(tmp_path, capsys):
    pkg = tmp_path / "edge_runtime"
    shutil.copytree(RUNTIME, pkg, ignore=shutil.ignore_patterns("__pycache__"))
    victim = pkg / "assets" / load_manifest(pkg / "assets")["models"][0]["file"]
    victim.write_bytes(victim.read_bytes()[:-1] + b"\0")
    from edge_runtime.core.manifest import ModelIntegrityError

    with pytest.raises(ModelIntegrityError, match=victim.name):
        build_bundle(tmp_path / "out", package=pkg)
    assert not (tmp_path / "out").exists()


def test_torch_requirement_is_refused(tmp_path):
    cfg = (ROOT / "setup.cfg").read_text().replace("install_requires =\n", "install_requires =\n    torch==2.13.0\n")
    (tmp_path / "setup.cfg").write_text(cfg)
    with pytest.raises(BundleError, match="torch"):
        runtime_metadata(tmp_path / "setup.cfg")


def test_cli_refuses_a_foreign_directory(tmp_path, capsys):
    (tmp_path / "precious.txt").write_text("not a bundle")
    assert export_main(["bundle", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and str(tmp_path) in err[0] and "refusing" in err[0]
    assert (tmp_path / "precious.txt").exists()


@pytest.mark.slow
def test_cli_replaces_a_previous_bundle(bundle, tmp_path, capsys):
    out = tmp_path / "b"
    shutil.copytree(bundle.out, out)
    (out / "stale.txt").write_text("from an older bundle")
    assert export_main(["bundle", "--out", str(out)]) == 0
    assert not (out / "stale.txt").exists() and (out / SUMS_NAME).exists()
    assert bundle.wheel.name in capsys.readouterr().out


@pytest.mark.slow
@pytest.mark.timeout(300)
def test_installed_wheel_runs_without_torch(bundle, tmp_path):
    """A fresh venv (no system site-packages), the wheel and its dependencies from PyPI or
    pip's cache, then the installed ``python -m edge_runtime wearable --replay`` on a drive."""
    drive = tmp_path / "drive"
    r = subprocess.run([sys.executable, "-m", "firmware_sim", "drive", "--minutes", "1", "--seed", "1", "--out",
                        str(drive)], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    try:
        rep = measure_install(bundle.wheel, tmp_path / "venv", timeout_s=240)
    except BundleError as e:
        if "No matching distribution" in str(e):  # no package index reachable and nothing cached
            pytest.skip(str(e))
        raise
    assert not rep.torch_importable and rep.site_packages_bytes > 0
    py = str(venv_python(rep.venv))
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    where = subprocess.run([py, "-c", "import edge_runtime, sys; print(edge_runtime.__file__); "
                            "print('torch' in sys.modules)"], capture_output=True, text=True, cwd=tmp_path, env=env)
    path, torch_loaded = where.stdout.split()
    assert Path(path).is_relative_to(rep.venv) and torch_loaded == "False"  # the installed copy, not the repo's
    alerts = tmp_path / "alerts.jsonl"
    r = subprocess.run([py, "-m", "edge_runtime", "wearable", "--replay", str(drive / "imu.csv"), "--alerts",
                        str(alerts), "--quiet"], capture_output=True, text=True, cwd=tmp_path, env=env, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    decisions = [json.loads(line) for line in alerts.read_text().splitlines()]
    keys = {"t_trigger_s", "t_alert_s", "label", "confidence", "alerted"}
    assert decisions and all(keys <= set(d) for d in decisions)
    assert "summary:" in r.stdout
