"""``python -m export bundle --out DIR [--measure-install [--venv DIR]]``: what goes onto a box.

DIR receives:

* ``edge_safety_runtime-<version>-py3-none-any.whl``: the RUNTIME only -- the
  ``edge_runtime`` package with its assets (models, manifest.json, the DBC) and
  its TOML -- built from a minimal source tree generated in a temporary
  directory (the repository's setup.cfg packages the training side too). Its
  dependencies are setup.cfg's ``install_requires``, which must not name torch;
  ``pip wheel --no-deps --no-build-isolation`` builds it with the setuptools
  already installed;
* ``assets/``: the assets directory (models, manifest.json, DBCs), copied, each
  model's sha256 checked against the manifest after the copy (and every model
  inside the wheel too);
* ``box.toml``: the default configuration (``edge_runtime/box.example.toml``,
  every key with its default), checked to load;
* ``INSTALL.md``: how to install and run it;
* ``SHA256SUMS``: ``sha256sum -c`` format over every other file.

``--measure-install`` then installs the wheel into a fresh virtual environment
(``python -m venv``, dependencies from PyPI or pip's cache), proves torch is not
importable there, and reports the installed size (bytes under site-packages)
and the largest distributions; :func:`measure_install` does the same for tests.
"""
from __future__ import annotations

import configparser
import os
import shutil
import subprocess
import sys
import tempfile
import time
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

from edge_runtime.cli import CliError
from edge_runtime.core.manifest import ModelIntegrityError, sha256_bytes, sha256_file, verify_all

ROOT = Path(__file__).resolve().parent.parent
RUNTIME_PACKAGE = ROOT / "edge_runtime"
SETUP_CFG = ROOT / "setup.cfg"
DIST_NAME = "edge-safety-runtime"
REQUIRES_PYTHON = ">=3.11"
"""edge_runtime.config reads TOML with the standard library's tomllib (Python 3.11+)."""
FORBIDDEN_REQUIREMENTS = ("torch", "torchvision", "onnx", "onnxscript", "tensorflow")
SUMS_NAME = "SHA256SUMS"
CONFIG_NAME = "box.toml"
BAD_INPUT = (ModelIntegrityError,)


class BundleError(CliError):
    """The bundle cannot be built (one line naming the file or field)."""


@dataclass(frozen=True)
class Bundle:
    out: Path
    """The bundle directory."""
    wheel: Path
    """The runtime wheel inside it."""
    requirements: tuple[str, ...]
    """The wheel's dependencies (setup.cfg install_requires)."""
    files: dict[str, str] = field(default_factory=dict)
    """Relative path -> sha256 of every file listed in SHA256SUMS."""


@dataclass(frozen=True)
class InstallReport:
    venv: Path
    site_packages_bytes: int
    """Bytes of every file under the venv's site-packages (du, apparent sizes)."""
    largest: tuple[tuple[str, int], ...]
    """The biggest top-level entries of site-packages: (name, bytes)."""
    torch_importable: bool
    install_s: float
    """Wall time of ``pip install`` (s; network and cache dependent)."""


# ---------------------------------------------------------------------------------------------- inputs

def runtime_metadata(setup_cfg: Path = SETUP_CFG) -> tuple[str, tuple[str, ...]]:
    """(version, install_requires) from setup.cfg; refuses a torch-side requirement."""
    cfg = configparser.ConfigParser()
    if not cfg.read(setup_cfg):
        raise BundleError(f"{setup_cfg}: not readable")
    try:
        version = cfg["metadata"]["version"].strip()
        raw = cfg["options"]["install_requires"]
    except KeyError as e:
        raise BundleError(f"{setup_cfg}: field {e.args[0]!r} missing") from None
    reqs = tuple(line.strip() for line in raw.splitlines() if line.strip() and not line.strip().startswith("#"))
    for r in reqs:
        name = r.split(";")[0].split("[")[0].split("=")[0].split(">")[0].split("<")[0].split("~")[0].strip().lower()
        if name in FORBIDDEN_REQUIREMENTS:
            raise BundleError(f"{setup_cfg}: field 'options.install_requires': {r!r} does not belong on a box "
                              "(training side)")
    return version, reqs


def _pyproject(version: str, reqs: tuple[str, ...]) -> str:
    deps = "".join(f'    "{r}",\n' for r in reqs)
    return (
        '[build-system]\nrequires = ["setuptools>=64", "wheel"]\nbuild-backend = "setuptools.build_meta"\n\n'
        f'[project]\nname = "{DIST_NAME}"\nversion = "{version}"\n'
        'description = "Edge safety runtime: the torch-free edge_runtime package and its shipped models"\n'
        f'requires-python = "{REQUIRES_PYTHON}"\nlicense = {{text = "Apache-2.0"}}\ndependencies = [\n{deps}]\n\n'
        '[project.scripts]\nedge-runtime = "edge_runtime.__main__:main"\n\n'
        '[tool.setuptools]\ninclude-package-data = false\n\n'
        '[tool.setuptools.packages.find]\nnamespaces = true\ninclude = ["edge_runtime", "edge_runtime.*"]\n'
        'exclude = ["*.__pycache__"]\n\n'
        '[tool.setuptools.package-data]\nedge_runtime = ["*.toml"]\n"edge_runtime.assets" = ["*"]\n')


# ---------------------------------------------------------------------------------------------- build

def build_wheel(out: Path, package: Path, version: str, reqs: tuple[str, ...]) -> Path:
    """The runtime wheel, built from a generated source tree holding ``package`` only."""
    with tempfile.TemporaryDirectory(prefix="bundle-src-") as tmp:
        src = Path(tmp) / "src"
        shutil.copytree(package, src / "edge_runtime", ignore=shutil.ignore_patterns("__pycache__", "*.pyc",
                                                                                       "*.tmp.json"))
        (src / "pyproject.toml").write_text(_pyproject(version, reqs))
        r = subprocess.run([sys.executable, "-m", "pip", "wheel", "--quiet", "--no-deps", "--no-build-isolation",
                            "--disable-pip-version-check", "--wheel-dir", str(out), str(src)],
                           capture_output=True, text=True)
        if r.returncode != 0:
            last = (r.stderr.strip().splitlines() or ["no output"])[-1]
            raise BundleError(f"pip wheel {src}: exit {r.returncode}: {last}")
    wheels = sorted(out.glob(f"{DIST_NAME.replace('-', '_')}-{version}-*.whl"))
    if len(wheels) != 1:
        raise BundleError(f"{out}: expected one {DIST_NAME} {version} wheel, found {[w.name for w in wheels]}")
    return wheels[0]


def check_wheel_assets(wheel: Path, manifest: dict) -> None:
    """Every model the manifest lists is inside the wheel with the manifest's sha256."""
    with zipfile.ZipFile(wheel) as z:
        names = set(z.namelist())
        for entry in manifest["models"]:
            member = f"edge_runtime/assets/{entry['file']}"
            if member not in names:
                raise ModelIntegrityError(f"{wheel.name}: {member} missing from the wheel")
            if sha256_bytes(z.read(member)) != entry["sha256"]:
                raise ModelIntegrityError(f"{wheel.name}: {member}: sha256 differs from the manifest")


def _prepare_out(out: Path) -> None:
    """An empty or new directory, or a previous bundle (which is replaced); anything else is refused."""
    if out.exists() and not out.is_dir():
        raise BundleError(f"--out {out}: exists and is not a directory")
    if out.is_dir() and any(out.iterdir()):
        if not (out / SUMS_NAME).is_file():
            raise BundleError(f"--out {out}: not empty and not a previous bundle (no {SUMS_NAME}); refusing to "
                              "overwrite")
        shutil.rmtree(out)
    out.mkdir(parents=True, exist_ok=True)


def write_sums(out: Path) -> dict[str, str]:
    """``SHA256SUMS`` over every file under ``out`` (sorted relative paths; sha256sum -c format)."""
    files = {p.relative_to(out).as_posix(): sha256_file(p) for p in sorted(out.rglob("*"))
             if p.is_file() and p.name != SUMS_NAME}
    (out / SUMS_NAME).write_text("".join(f"{h}  {name}\n" for name, h in files.items()))
    return files


def _install_text(wheel: Path, reqs: tuple[str, ...], manifest: dict) -> str:
    models = "\n".join(f"  - `{e['file']}` ({e['name']}, {e['precision']}, sha256 `{e['sha256'][:16]}...`)"
                       for e in manifest["models"])
    return f"""# Edge safety runtime bundle

What a box needs to run the product, and nothing more (no torch).

| file | what |
|---|---|
| `{wheel.name}` | the `edge_runtime` package with its models, manifest and DBC (Python {REQUIRES_PYTHON}) |
| `assets/` | the same models, `manifest.json` and DBCs, for integrators or `[model] assets` |
| `{CONFIG_NAME}` | the default configuration: every key with its default |
| `{SUMS_NAME}` | sha256 of every file here |

Models:
{models}

Dependencies (installed by pip from PyPI or a local wheelhouse): {", ".join(f"`{r}`" for r in reqs)}.

## Install

```sh
sha256sum -c {SUMS_NAME}
python3.11 -m venv /opt/edge-safety
/opt/edge-safety/bin/pip install {wheel.name}
# offline: pip download the dependencies into a wheelhouse elsewhere, then
#   /opt/edge-safety/bin/pip install --no-index --find-links WHEELHOUSE {wheel.name}
```

## Run

```sh
/opt/edge-safety/bin/python -m edge_runtime wearable --config {CONFIG_NAME} --print-config
/opt/edge-safety/bin/python -m edge_runtime wearable --config {CONFIG_NAME} --imu serial:/dev/ttyUSB0
/opt/edge-safety/bin/python -m edge_runtime wearable --replay imu.csv --alerts alerts.jsonl   # a recording
```

Every model file is checked against `manifest.json` (sha256) before it is loaded; a
mismatch stops the runtime with one line naming the file.
"""


def build_bundle(out: str | os.PathLike, package: str | os.PathLike = RUNTIME_PACKAGE,
                 setup_cfg: str | os.PathLike = SETUP_CFG) -> Bundle:
    """Build the bundle into ``out`` (see the module docstring) from the runtime ``package``."""
    out, package = Path(out), Path(package)
    version, reqs = runtime_metadata(Path(setup_cfg))
    manifest = verify_all(package / "assets")  # a tampered model never gets into a bundle
    from edge_runtime.config import load as load_config

    load_config(package / "box.example.toml")
    _prepare_out(out)
    wheel = build_wheel(out, package, version, reqs)
    check_wheel_assets(wheel, manifest)
    assets = out / "assets"
    shutil.copytree(package / "assets", assets, ignore=shutil.ignore_patterns("*.tmp.json", "__pycache__"))
    verify_all(assets)
    shutil.copy2(package / "box.example.toml", out / CONFIG_NAME)
    (out / "INSTALL.md").write_text(_install_text(wheel, reqs, manifest))
    return Bundle(out, wheel, reqs, write_sums(out))


# ---------------------------------------------------------------------------------------------- install

def venv_python(venv: Path) -> Path:
    return venv / ("Scripts/python.exe" if os.name == "nt" else "bin/python")


def _tree_bytes(path: Path) -> int:
    total = 0
    for dirpath, _, files in os.walk(path):
        for f in files:
            try:
                total += os.lstat(os.path.join(dirpath, f)).st_size
            except OSError:
                pass
    return total


def site_packages(venv: Path) -> Path:
    r = subprocess.run([str(venv_python(venv)), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                       capture_output=True, text=True, check=True)
    return Path(r.stdout.strip())


def measure_install(wheel: str | os.PathLike, venv: str | os.PathLike, timeout_s: float = 900.0) -> InstallReport:
    """A fresh venv (no system site-packages) with ``wheel`` and its dependencies installed;
    its site-packages size, and whether torch is importable there (it must not be)."""
    venv = Path(venv)
    if venv.exists():
        raise BundleError(f"--venv {venv}: exists; give a new directory")
    subprocess.run([sys.executable, "-m", "venv", str(venv)], check=True, capture_output=True, timeout=timeout_s)
    t0 = time.perf_counter()
    r = subprocess.run([str(venv_python(venv)), "-m", "pip", "install", "--quiet", "--disable-pip-version-check",
                        str(wheel)], capture_output=True, text=True, timeout=timeout_s)
    install_s = time.perf_counter() - t0
    if r.returncode != 0:
        last = (r.stderr.strip().splitlines() or ["no output"])[-1]
        raise BundleError(f"pip install {Path(wheel).name} into {venv}: exit {r.returncode}: {last}")
    probe = subprocess.run([str(venv_python(venv)), "-c",
                            "import importlib.util, sys; sys.exit(0 if importlib.util.find_spec('torch') else 1)"],
                           capture_output=True, timeout=60)
    sp = site_packages(venv)
    sizes = sorted(((p.name, _tree_bytes(p) if p.is_dir() else p.stat().st_size) for p in sp.iterdir()),
                   key=lambda kv: -kv[1])
    return InstallReport(venv, _tree_bytes(sp), tuple(sizes[:8]), probe.returncode == 0, round(install_s, 1))


def format_install(rep: InstallReport) -> str:
    top = ", ".join(f"{name} {size / 2**20:.1f}" for name, size in rep.largest)
    return (f"installed runtime (fresh venv, no torch{' -- BUT torch is importable' if rep.torch_importable else ''}): "
            f"site-packages {rep.site_packages_bytes / 2**20:.1f} MiB; largest (MiB): {top}; "
            f"pip install took {rep.install_s:.0f} s")


# ---------------------------------------------------------------------------------------------- command

def add_arguments(parser) -> None:
    parser.add_argument("--out", required=True, metavar="DIR", help="bundle directory (new, empty, or a "
                                                                    "previous bundle, which is replaced)")
    parser.add_argument("--measure-install", action="store_true",
                        help="install the wheel into a fresh venv and report its size without torch")
    parser.add_argument("--venv", default=None, metavar="DIR",
                        help="--measure-install: keep the venv here (default: a temporary one)")


def cmd(args) -> int:
    b = build_bundle(args.out)
    total = sum((b.out / name).stat().st_size for name in b.files)
    print(f"{b.out}: {b.wheel.name} ({b.wheel.stat().st_size / 2**20:.2f} MiB), assets/, {CONFIG_NAME}, INSTALL.md, "
          f"{SUMS_NAME} ({len(b.files)} files, {total / 2**20:.2f} MiB)")
    print(f"  requires: {', '.join(b.requirements)}")
    if args.measure_install:
        with tempfile.TemporaryDirectory(prefix="bundle-venv-") as tmp:
            rep = measure_install(b.wheel, Path(args.venv) if args.venv else Path(tmp) / "venv")
            print("  " + format_install(rep))
        if rep.torch_importable:
            return 1
    return 0
