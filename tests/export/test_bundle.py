"""python -m export bundle: a torch-free runtime wheel, a wheelhouse, verified assets, a config,
systemd units, install.sh and checksums -- and install.sh installs it into a fresh venv with no
package index reachable, where the installed `edge-wearable` gives the development checkout's alerts."""
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tomllib
import zipfile
from pathlib import Path

import pytest
from support import REPO_ROOT

from edge_runtime.__main__ import main as edge_main
from edge_runtime.core.manifest import load_manifest
from export.__main__ import main as export_main
from export.box_files import UNITS
from export.bundle import (
    SUMS_NAME,
    BundleError,
    build_bundle,
    console_scripts,
    installed_distributions,
    measure_install,
    product_requirements,
    runtime_metadata,
    venv_python,
    write_box_files,
)

ROOT = REPO_ROOT
RUNTIME = ROOT / "edge_runtime"

pytestmark = pytest.mark.skipif(not (RUNTIME / "assets" / "manifest.json").exists(), reason="no shipped assets")


@pytest.fixture(scope="module")
def bundle(tmp_path_factory):
    """The wearable product's bundle (its wheelhouse from the package index or pip's cache)."""
    try:
        return build_bundle(tmp_path_factory.mktemp("b") / "bundle", product="wearable")
    except BundleError as e:
        if "No matching distribution" in str(e):  # no package index reachable and nothing cached
            pytest.skip(str(e))
        raise


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
    # the box decides as shipped, by the streaming classifier, and the bundle carries it
    box = tomllib.loads((out / "box.toml").read_text())
    shipped = next(e for e in manifest["models"] if e["name"] == box["stream"]["model"])
    assert box["alerts"]["decision"] == "stream" and shipped["arch"] == "stream"
    assert (out / "assets" / shipped["file"]).is_file()


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
    base = [r for r in requires if "extra ==" not in r]
    assert not any(r.startswith(("torch", "onnx ", "onnx>", "onnxscript", "opencv", "pymavlink")) for r in base)
    assert tuple(r.lower() for r in runtime_metadata()[1]) == tuple(base)
    assert {"wearable", "serial-imu", "robot"} <= {line.split(":", 1)[1].strip() for line in meta.splitlines()
                                                   if line.startswith("Provides-Extra:")}
    assert any(r.startswith("opencv-python-headless") and 'extra == "robot"' in r for r in requires)
    with zipfile.ZipFile(bundle.wheel) as z:
        entry_points = z.read(next(n for n in z.namelist() if n.endswith("entry_points.txt"))).decode()
    assert all(f"{name} = {target}" in entry_points for name, target in console_scripts().items())
    assert {"edge-wearable", "edge-robot", "edge-runtime"} <= set(console_scripts())


@pytest.mark.parametrize("product, extras, has, lacks", [
    ("wearable", ("wearable",), "onnxruntime", ("opencv", "pymavlink", "pyserial", "torch")),
    ("robot", ("robot",), "opencv-python-headless", ("torch",)),
    ("all", ("wearable", "serial-imu", "robot"), "pymavlink", ("torch",)),
])
def test_each_product_installs_what_it_needs_and_nothing_of_the_training_side(product, extras, has, lacks):
    got_extras, reqs = product_requirements(product)
    names = [r.split(">")[0].split("=")[0] for r in reqs]
    assert got_extras == extras and has in names and not any(n.startswith(lacks) for n in names)
    assert names[:5] == ["numpy", "onnxruntime", "python-can", "cantools", "autosar-e2e"]
    assert "pymavlink" in [r.split(">")[0] for r in product_requirements("wearable", ("serial-imu",))[1]]
    with pytest.raises(BundleError, match="--with: 'gpu'"):
        product_requirements(product, ("gpu",))


def test_box_files_supervise_the_runtime_and_install_offline(tmp_path):
    write_box_files(tmp_path, Path("edge_safety_runtime-9-py3-none-any.whl"), "all", "aarch64", "3.11",
                    ("wearable", "robot"))
    sh = (tmp_path / "install.sh").read_text()
    assert os.access(tmp_path / "install.sh", os.X_OK)
    assert '--no-index --find-links "$HERE/wheels"' in sh
    assert '"$HERE/edge_safety_runtime-9-py3-none-any.whl[wearable,robot]"' in sh
    assert "PIP_CONFIG_FILE=/dev/null" in sh and "sha256sum --check" in sh
    assert '[ "$(uname -m)" = "aarch64" ]' in sh and "verify_all(ASSETS_DIR)" in sh
    for name, script in (("edge-wearable", "edge-wearable"), ("edge-robot", "edge-robot")):
        unit = (tmp_path / "systemd" / f"{name}.service").read_text().splitlines()
        assert {"Type=notify", "Restart=on-failure", "NotifyAccess=main"} <= set(unit)
        assert any(line.startswith("WatchdogSec=") and int(line.split("=")[1]) > 0 for line in unit)
        assert f"ExecStart=@PREFIX@/bin/{script} --config @ETC@/box.toml $EDGE_ARGS" in unit
        assert (tmp_path / "systemd" / f"{name}.env").read_text().count("EDGE_ARGS=") == 1


def _systemd_verify(unit: Path) -> list[str]:
    """What ``systemd-analyze verify`` says about the unit (it exits 0 on unknown keys, so read it)."""
    r = subprocess.run(["systemd-analyze", "verify", str(unit)], capture_output=True, text=True, timeout=60)
    said = [line for line in (r.stdout + r.stderr).splitlines() if unit.name in line]
    return said + ([f"exit {r.returncode}"] if r.returncode else [])


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("systemd-analyze") is None, reason="systemd-analyze not installed")
def test_systemd_accepts_the_installed_units(tmp_path):
    """The units as install.sh writes them (@PREFIX@ and @ETC@ filled in) pass systemd's own check:
    a misspelt directive would otherwise be ignored by systemd with a warning, not refused."""
    write_box_files(tmp_path, Path("edge_safety_runtime-9-py3-none-any.whl"), "all", "x86_64", "3.11", ())
    prefix, etc = tmp_path / "opt", tmp_path / "etc"
    (prefix / "bin").mkdir(parents=True)
    etc.mkdir()
    for u in UNITS.values():
        script = prefix / "bin" / u["NAME"]
        script.write_text("#!/bin/sh\n")
        script.chmod(0o755)
        shutil.copy(tmp_path / "systemd" / f"{u['NAME']}.env", etc)
        text = (tmp_path / "systemd" / f"{u['NAME']}.service").read_text()
        unit = tmp_path / f"{u['NAME']}.service"
        unit.write_text(text.replace("@PREFIX@", str(prefix)).replace("@ETC@", str(etc)))
        assert _systemd_verify(unit) == []
        unit.write_text(unit.read_text().replace("Restart=on-failure", "Restart=on-failure\nRestrat=always"))
        assert any("Restrat" in line for line in _systemd_verify(unit))  # the check does see a bad key


def test_tampered_model_is_not_bundled(tmp_path, capsys):
    pkg = tmp_path / "edge_runtime"
    shutil.copytree(RUNTIME, pkg, ignore=shutil.ignore_patterns("__pycache__"))
    victim = pkg / "assets" / load_manifest(pkg / "assets")["models"][0]["file"]
    victim.write_bytes(victim.read_bytes()[:-1] + b"\0")
    from edge_runtime.core.manifest import ModelIntegrityError

    with pytest.raises(ModelIntegrityError, match=victim.name):
        build_bundle(tmp_path / "out", package=pkg)
    assert not (tmp_path / "out").exists()


def test_a_frame_schedule_that_is_not_its_dbcs_is_not_bundled_and_export_schedule_writes_it(tmp_path):
    pkg = tmp_path / "edge_runtime"
    shutil.copytree(RUNTIME, pkg, ignore=shutil.ignore_patterns("__pycache__"))
    kept = pkg / "assets" / "vehicle_alerts.schedule.json"
    shipped = kept.read_text()
    kept.write_text(json.dumps(dict(json.loads(shipped), repetition_copies=1)))  # the DBC's sha256, not its content
    from edge_runtime.core.manifest import ModelIntegrityError

    with pytest.raises(ModelIntegrityError, match="schedule.json: differs"):
        build_bundle(tmp_path / "out", package=pkg)
    assert not (tmp_path / "out").exists()
    assert export_main(["schedule", "--assets", str(pkg / "assets")]) == 0  # written from the DBC again
    assert kept.read_text() == shipped


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


TIMING_KEYS = ("compute_us", "latency_ms")
"""What differs between two runs of the same recording: the time the model and the loop took."""


def _decisions(path: Path) -> list[dict]:
    return [{k: v for k, v in json.loads(line).items() if k not in TIMING_KEYS} for line in path.read_text().splitlines()]


@pytest.mark.slow
@pytest.mark.timeout(600)
def test_offline_install_gives_the_development_checkouts_alerts(bundle, tmp_path):
    """install.sh into a fresh venv with no index reachable (PIP_NO_INDEX, no find-links, no pip
    configuration): lean (no torch, OpenCV or pymavlink; <= 200 MB), then the installed `edge-wearable --replay` on a drive: the same decisions as
    this checkout's `python -m edge_runtime wearable --replay`."""
    drive = tmp_path / "drive"
    r = subprocess.run([sys.executable, "-m", "firmware_sim", "drive", "--minutes", "5", "--seed", "3", "--out",
                        str(drive)], capture_output=True, text=True, cwd=ROOT, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    rep = measure_install(bundle.out, tmp_path / "venv", timeout_s=540)  # install.sh, offline
    venv, etc = rep.venv, tmp_path / "venv-etc"
    assert (etc / "box.toml").read_text() == (RUNTIME / "box.example.toml").read_text()
    assert (etc / "edge-wearable.env").is_file()
    names = {name.lower() for name, _ in rep.distributions}
    assert not rep.torch_importable and set(rep.absent) == {"torch", "cv2", "pymavlink"}
    assert {"numpy", "onnxruntime", "python-can", "cantools", "autosar-e2e", "edge-safety-runtime"} <= names
    assert rep.venv_bytes <= 200e6  # the limit for the wearable box

    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")}
    where = subprocess.run([str(venv_python(venv)), "-c", "import edge_runtime; print(edge_runtime.__file__)"],
                           capture_output=True, text=True, cwd=tmp_path, env=env).stdout.strip()
    assert Path(where).is_relative_to(venv)  # the installed copy, not this checkout's

    installed, dev = tmp_path / "installed.jsonl", tmp_path / "dev.jsonl"
    r = subprocess.run([str(venv / "bin" / "edge-wearable"), "--config", str(etc / "box.toml"), "--replay",
                        str(drive / "imu.csv"), "--alerts", str(installed), "--quiet"], capture_output=True, text=True,
                       cwd=tmp_path, env=env, timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    assert "summary:" in r.stdout
    assert edge_main(["wearable", "--replay", str(drive / "imu.csv"), "--alerts", str(dev),
                                                 "--quiet"]) == 0
    assert _decisions(installed) == _decisions(dev) and any(d["alerted"] for d in _decisions(dev))
    assert {d["steps"] for d in _decisions(dev)} == {0}  # the shipped box.toml's decider: stream decisions


@pytest.mark.slow  # a venv and three interpreters
def test_the_install_report_lists_what_the_venv_holds_not_the_checkout_it_is_run_from(tmp_path, monkeypatch):
    """Run from a development checkout (an egg-info in the current directory, its source tree on PYTHONPATH),
    the report listed that checkout as a second installed distribution beside the runtime wheel."""
    venv = tmp_path / "venv"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(venv)], check=True, timeout=120)
    checkout = tmp_path / "checkout"
    (checkout / "edge_safety.egg-info").mkdir(parents=True)
    (checkout / "edge_safety.egg-info" / "PKG-INFO").write_text("Metadata-Version: 2.1\nName: edge-safety\n"
                                                                 "Version: 0.1.0\n")
    (checkout / "torch").mkdir()
    (checkout / "torch" / "__init__.py").write_text("")
    monkeypatch.chdir(checkout)
    monkeypatch.setenv("PYTHONPATH", str(checkout))
    leaky = subprocess.run([str(venv_python(venv)), "-c", "import importlib.metadata as md, importlib.util as u; "
                            "print([d.metadata['Name'] for d in md.distributions()], u.find_spec('torch') is None)"],
                           capture_output=True, text=True, check=True).stdout
    assert "edge-safety" in leaky and "False" in leaky  # what a probe run as before saw
    dists, absent = installed_distributions(venv)
    assert "edge-safety" not in dists and set(absent) == {"torch", "cv2", "pymavlink"}


@pytest.mark.slow  # pip builds the runtime wheel
def test_an_aarch64_bundle_pins_the_onnxruntime_that_runs_there_and_says_what_was_tested(tmp_path):
    from export.bundle import ONNXRUNTIME_PINS, ONNXRUNTIME_TESTED

    b = build_bundle(tmp_path / "arm", product="wearable", platform_name="aarch64", wheelhouse=False)
    assert ONNXRUNTIME_PINS["aarch64"] in b.requirements
    assert not any(r.startswith("onnxruntime>") for r in b.requirements)
    assert ONNXRUNTIME_TESTED["aarch64"] in (b.out / "INSTALL.md").read_text()
    x86 = build_bundle(tmp_path / "x86", product="wearable", platform_name="x86_64", wheelhouse=False)
    assert "onnxruntime>=1.17" in x86.requirements
    assert ONNXRUNTIME_TESTED["x86_64"] in (x86.out / "INSTALL.md").read_text()


@pytest.mark.slow  # pip download, with no index: only the wheel given with --find-links can be found
def test_an_aarch64_wheelhouse_takes_the_built_autosar_e2e_wheel_and_without_it_names_the_command(
        tmp_path, monkeypatch):
    from export.aarch64 import E2E_TAG, E2E_VERSION, write_wheel
    from export.bundle import download_wheelhouse

    monkeypatch.setenv("PIP_NO_INDEX", "1")
    built = tmp_path / "built"
    built.mkdir()
    info = f"autosar_e2e-{E2E_VERSION}.dist-info"
    write_wheel(built / f"autosar_e2e-{E2E_VERSION}-{E2E_TAG}.whl",
                {"e2e/__init__.py": b"", f"{info}/METADATA": f"Metadata-Version: 2.1\nName: autosar-e2e\n"
                                                             f"Version: {E2E_VERSION}\n".encode(),
                 f"{info}/WHEEL": f"Wheel-Version: 1.0\nRoot-Is-Purelib: false\nTag: {E2E_TAG}\n".encode()}, info)
    wheels = download_wheelhouse(tmp_path / "wheels", ("autosar-e2e",), "aarch64", find_links=(str(built),))
    assert [w.name for w in wheels] == [f"autosar_e2e-{E2E_VERSION}-{E2E_TAG}.whl"]
    with pytest.raises(BundleError, match="python -m export.aarch64 --e2e-wheel DIR"):
        download_wheelhouse(tmp_path / "none", ("autosar-e2e",), "aarch64")
