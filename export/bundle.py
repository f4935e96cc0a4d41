"""``python -m export bundle --out DIR [--product wearable|robot|all] [--platform x86_64|aarch64]``:
what goes onto a box, installable there without a package index.

DIR receives:

* ``edge_safety_runtime-<version>-py3-none-any.whl``: the RUNTIME only -- the
  ``edge_runtime`` package with its assets (models, manifest.json, the DBC) and
  its TOML -- built from a minimal source tree generated in a temporary
  directory (the repository's setup.cfg packages the training side too). Its
  dependencies are setup.cfg's ``install_requires`` (the wearable box) and its
  product extras (``serial-imu``, ``robot``), none of which may name torch; its
  console scripts are setup.cfg's (``edge-wearable``, ``edge-robot``, ``edge-runtime``);
* ``wheels/``: every dependency of the product, as binary wheels for the target
  platform and Python (``pip download --only-binary=:all: --platform manylinux_2_36_<arch> ...
  --python-version 3.11``): ``install.sh`` installs from here alone;
* ``assets/``: the assets directory (models, manifest.json, DBCs), copied, each
  model's sha256 checked against the manifest after the copy (and every model
  inside the wheel too);
* ``box.toml``: the default configuration (``edge_runtime/box.example.toml``,
  every key with its default), checked to load; ``install.sh`` puts it at
  ``/etc/edge-safety/box.toml``, where the runtime looks when no ``--config`` is given;
* ``systemd/``: the product's units (``Type=notify``, ``WatchdogSec=``,
  ``Restart=on-failure``) and their environment files (export/box_files.py);
* ``install.sh``: the offline install (docs/install.md); ``INSTALL.md``: how to
  install and run it; ``SHA256SUMS``: ``sha256sum -c`` format over every other file.

``--measure-install`` then runs ``install.sh`` into a fresh prefix with no index
reachable, proves torch is not importable there, and reports the installed size
and what each distribution costs; :func:`measure_install` does the same for tests.
"""
from __future__ import annotations

import configparser
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import zipfile
from dataclasses import dataclass, field
from pathlib import Path

from edge_runtime.cli import CliError
from edge_runtime.core.manifest import ModelIntegrityError, sha256_bytes, sha256_file, verify_all
from export.box_files import INSTALL_SH, SKIP_COMPILE, UNIT, UNITS, fill

ROOT = Path(__file__).resolve().parent.parent
RUNTIME_PACKAGE = ROOT / "edge_runtime"
SETUP_CFG = ROOT / "setup.cfg"
DIST_NAME = "edge-safety-runtime"
REQUIRES_PYTHON = ">=3.11"
"""edge_runtime.config reads TOML with the standard library's tomllib (Python 3.11+)."""
PYTHON_VERSION = "3.11"
"""The box's Python (Debian 12's python3.11): the wheelhouse is built for it."""
PLATFORMS = ("x86_64", "aarch64")
ONNXRUNTIME_PINS = {"aarch64": "onnxruntime==1.27.0"}
"""The onnxruntime a platform's wheelhouse takes instead of the newest: the newest aarch64 wheel
that can be proven here. The aarch64 wheels of 1.28.0 and 1.32.0 die at import under Debian 12's
qemu-aarch64 7.2 (make aarch64-check runs them too, and shows it; reports/box/aarch64.md)."""
ONNXRUNTIME_TESTED = {
    "x86_64": "1.16.3, 1.22.1 and 1.32.0 (python -m export.runtime_check: the same outputs as the "
              "wheelhouse's onnxruntime; the runtime itself asks for >=1.17)",
    "aarch64": "1.22.1 and 1.27.0, 1.27.0 pinned (under qemu-aarch64 7.2, make aarch64-check: the same alerts "
               "as x86 with 1.27.0, every model's outputs with 1.22.1 and 1.27.0; 1.28.0 and 1.32.0 "
               "crash at import under that qemu; untested on aarch64 hardware)",
}
"""What INSTALL.md states each bundle's onnxruntime range was tested with (docs/install.md)."""
BUILD_HINTS = {"aarch64": "; autosar-e2e for aarch64: python -m export.aarch64 --e2e-wheel DIR"}
"""Where the wheels PyPI lacks for a platform come from (export/aarch64.py cross-compiles it)."""
GLIBC_MINOR = 36
"""The box's glibc is 2.36 (Debian 12): a wheel may need any glibc up to it. pip download matches
the platform tags it is given exactly, so :func:`platform_tags` lists every manylinux tag up to it
(with only ``manylinux_2_28``, pymavlink fell back to an old pure-Python wheel of 165 MiB)."""
PRODUCTS = {"wearable": ("wearable",), "robot": ("robot",), "all": ("wearable", "serial-imu", "robot")}
"""Each product's extras of the runtime wheel (setup.cfg); ``wearable`` is the base install."""
PRODUCT_EXTRAS = ("wearable", "serial-imu", "robot", "signed-models")
"""setup.cfg extras the runtime wheel carries: what a box may add (``--with serial-imu``)."""
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
    """What the product installs (setup.cfg install_requires and the product's extras)."""
    product: str = "all"
    platform: str = "x86_64"
    extras: tuple[str, ...] = ()
    files: dict[str, str] = field(default_factory=dict)
    """Relative path -> sha256 of every file listed in SHA256SUMS."""


@dataclass(frozen=True)
class InstallReport:
    venv: Path
    venv_bytes: int
    """Bytes of every file under the installed venv (apparent sizes), pip and setuptools included."""
    site_packages_bytes: int
    """Bytes of every file under the venv's site-packages."""
    distributions: tuple[tuple[str, int], ...]
    """Every installed distribution and the bytes of its files (its RECORD), largest first."""
    torch_importable: bool
    absent: tuple[str, ...]
    """Of torch, cv2 and pymavlink, those the installed venv cannot import."""


# ---------------------------------------------------------------------------------------------- inputs

def _requirement_name(req: str) -> str:
    return req.split(";")[0].split("[")[0].split("=")[0].split(">")[0].split("<")[0].split("~")[0].strip().lower()


def _lines(raw: str) -> tuple[str, ...]:
    return tuple(line.strip() for line in raw.splitlines() if line.strip() and not line.strip().startswith("#"))


def _read_setup_cfg(setup_cfg: Path) -> configparser.ConfigParser:
    cfg = configparser.ConfigParser()
    if not cfg.read(setup_cfg):
        raise BundleError(f"{setup_cfg}: not readable")
    return cfg


def runtime_metadata(setup_cfg: Path = SETUP_CFG) -> tuple[str, tuple[str, ...]]:
    """(version, install_requires) from setup.cfg; refuses a torch-side requirement."""
    cfg = _read_setup_cfg(setup_cfg)
    try:
        version = cfg["metadata"]["version"].strip()
        reqs = _lines(cfg["options"]["install_requires"])
    except KeyError as e:
        raise BundleError(f"{setup_cfg}: field {e.args[0]!r} missing") from None
    _refuse_training_side(setup_cfg, "options.install_requires", reqs)
    return version, reqs


def product_extras(setup_cfg: Path = SETUP_CFG) -> dict[str, tuple[str, ...]]:
    """The runtime wheel's extras (:data:`PRODUCT_EXTRAS`) and their requirements, from setup.cfg."""
    cfg = _read_setup_cfg(setup_cfg)
    extras = {}
    for name in PRODUCT_EXTRAS:
        if not cfg.has_option("options.extras_require", name):
            raise BundleError(f"{setup_cfg}: field 'options.extras_require.{name}' missing")
        extras[name] = _lines(cfg["options.extras_require"][name])
        _refuse_training_side(setup_cfg, f"options.extras_require.{name}", extras[name])
    return extras


def console_scripts(setup_cfg: Path = SETUP_CFG) -> dict[str, str]:
    """setup.cfg's console scripts (name -> module:function), the runtime wheel's too."""
    cfg = _read_setup_cfg(setup_cfg)
    raw = cfg.get("options.entry_points", "console_scripts", fallback="")
    return {k.strip(): v.strip() for k, v in (line.split("=", 1) for line in _lines(raw))}


def _refuse_training_side(setup_cfg: Path, where: str, reqs: tuple[str, ...]) -> None:
    for r in reqs:
        if _requirement_name(r) in FORBIDDEN_REQUIREMENTS:
            raise BundleError(f"{setup_cfg}: field {where!r}: {r!r} does not belong on a box (training side)")


def _pyproject(version: str, reqs: tuple[str, ...], extras: dict[str, tuple[str, ...]] | None = None,
               scripts: dict[str, str] | None = None) -> str:
    def toml_list(items):
        return "[" + ", ".join(f'"{r}"' for r in items) + "]"

    optional = "".join(f'"{name}" = {toml_list(items)}\n' for name, items in (extras or {}).items())
    entry = "".join(f'{name} = "{target}"\n' for name, target in (scripts or {}).items())
    return (
        '[build-system]\nrequires = ["setuptools>=64", "wheel"]\nbuild-backend = "setuptools.build_meta"\n\n'
        f'[project]\nname = "{DIST_NAME}"\nversion = "{version}"\n'
        'description = "Edge safety runtime: the torch-free edge_runtime package and its shipped models"\n'
        f'requires-python = "{REQUIRES_PYTHON}"\nlicense = {{text = "Apache-2.0"}}\n'
        f'dependencies = {toml_list(reqs)}\n\n'
        f'[project.optional-dependencies]\n{optional}\n'
        f'[project.scripts]\n{entry}\n'
        '[tool.setuptools]\ninclude-package-data = false\n\n'
        '[tool.setuptools.packages.find]\nnamespaces = true\ninclude = ["edge_runtime", "edge_runtime.*"]\n'
        'exclude = ["*.__pycache__"]\n\n'
        '[tool.setuptools.package-data]\nedge_runtime = ["*.toml"]\n"edge_runtime.assets" = ["*"]\n')


# ---------------------------------------------------------------------------------------------- build

def build_wheel(out: Path, package: Path, version: str, reqs: tuple[str, ...],
                extras: dict[str, tuple[str, ...]] | None = None, scripts: dict[str, str] | None = None) -> Path:
    """The runtime wheel, built from a generated source tree holding ``package`` only."""
    with tempfile.TemporaryDirectory(prefix="bundle-src-") as tmp:
        src = Path(tmp) / "src"
        shutil.copytree(package, src / "edge_runtime", ignore=shutil.ignore_patterns("__pycache__", "*.pyc",
                                                                                       "*.tmp.json"))
        (src / "pyproject.toml").write_text(_pyproject(version, reqs, extras, scripts))
        _pip(["wheel", "--quiet", "--no-deps", "--no-build-isolation", "--wheel-dir", str(out), str(src)],
             f"pip wheel {src}")
    wheels = sorted(out.glob(f"{DIST_NAME.replace('-', '_')}-{version}-*.whl"))
    if len(wheels) != 1:
        raise BundleError(f"{out}: expected one {DIST_NAME} {version} wheel, found {[w.name for w in wheels]}")
    return wheels[0]


def _pip(args: list[str], what: str, env: dict | None = None, timeout_s: float = 1800.0) -> None:
    r = subprocess.run([sys.executable, "-m", "pip", "--disable-pip-version-check", *args], capture_output=True,
                       text=True, env=env, timeout=timeout_s)
    if r.returncode != 0:
        errors = [line for line in r.stderr.splitlines() if line.startswith("ERROR")] or r.stderr.splitlines()
        raise BundleError(f"{what}: exit {r.returncode}: {(errors or ['no output'])[-1]}")


def platform_tags(platform_name: str) -> list[str]:
    """Every manylinux tag a wheel for the box may carry, newest glibc first."""
    legacy = ("manylinux2014", "manylinux2010", "manylinux1")
    return [f"manylinux_2_{minor}_{platform_name}" for minor in range(GLIBC_MINOR, 4, -1)] + \
        [f"{tag}_{platform_name}" for tag in legacy]


def download_wheelhouse(wheels: Path, requirements: tuple[str, ...], platform_name: str,
                        python_version: str = PYTHON_VERSION, find_links: tuple[str, ...] = ()) -> list[Path]:
    """Binary wheels of ``requirements`` and everything they need, for ``platform_name`` and CPython
    ``python_version``, into ``wheels`` (pip's index and configuration, plus ``find_links``:
    wheels built elsewhere for a package the index has none of for that platform)."""
    version = python_version.replace(".", "")
    args = ["download", "--quiet", "--only-binary=:all:", *(a for tag in platform_tags(platform_name)
                                                           for a in ("--platform", tag)),
            "--python-version", python_version, "--implementation", "cp", "--abi", f"cp{version}", "--abi", "abi3",
            "--abi", "none", "--dest", str(wheels)]
    for link in find_links:
        args += ["--find-links", link]
    _pip([*args, *requirements], f"pip download for {platform_name} Python {python_version} (a package with no "
         f"binary wheel for it can be built on such a machine and given with --find-links DIR"
         f"{BUILD_HINTS.get(platform_name, '')})")
    return sorted(wheels.glob("*.whl"))


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


def _units(product: str) -> list[str]:
    return list(UNITS) if product == "all" else [product]


def write_box_files(out: Path, wheel: Path, product: str, platform_name: str, python_version: str,
                    extras: tuple[str, ...]) -> None:
    """install.sh and systemd/ (units and their environment files) for ``product``."""
    units = _units(product)
    names = [UNITS[u]["NAME"] for u in units]
    extra_spec = f"[{','.join(extras)}]" if extras else ""
    sh = out / "install.sh"
    sh.write_text(fill(INSTALL_SH, PRODUCT=product, PLATFORM=platform_name, PYTHON_VERSION=python_version,
                       WHEEL=wheel.name, EXTRAS=extra_spec, UNITS=" ".join(names), SKIP_COMPILE=SKIP_COMPILE))
    sh.chmod(0o755)
    (out / "systemd").mkdir()
    for u in units:
        values = UNITS[u]
        (out / "systemd" / f"{values['NAME']}.service").write_text(
            fill(UNIT, **{k: v for k, v in values.items() if k != "ENV"}))
        (out / "systemd" / f"{values['NAME']}.env").write_text(values["ENV"])


def _install_text(b: Bundle, manifest: dict, wheels: list[Path]) -> str:
    models = "\n".join(f"  - `{e['file']}` ({e['name']}, {e['precision']}, sha256 `{e['sha256'][:16]}...`)"
                       for e in manifest["models"])
    units = [UNITS[u]["NAME"] for u in _units(b.product)]
    wheel_list = "\n".join(f"  - `{w.name}`" for w in wheels)
    return f"""# Edge safety runtime bundle: {b.product}, {b.platform}, Python {PYTHON_VERSION}

What a box needs to run the product, and nothing more (no torch), installable without a
package index.

| file | what |
|---|---|
| `{b.wheel.name}` | the `edge_runtime` package with its models, manifest and DBCs (Python {REQUIRES_PYTHON}) |
| `wheels/` | every dependency, as wheels for {b.platform} and CPython {PYTHON_VERSION} |
| `assets/` | the same models, `manifest.json` and DBCs, for integrators or `[model] assets` |
| `{CONFIG_NAME}` | the default configuration: every key with its default |
| `systemd/` | {", ".join(f"`{u}.service`" for u in units)} and their `.env` files (the command's arguments) |
| `install.sh` | the offline install |
| `{SUMS_NAME}` | sha256 of every file here |

Installs the runtime wheel with extras `{",".join(b.extras) or "none (the base install)"}`:
{", ".join(f"`{r}`" for r in b.requirements)}.

onnxruntime: the shipped models (they declare only the opset domains they use) were tested on
{b.platform} with onnxruntime {ONNXRUNTIME_TESTED[b.platform]}.

Models:
{models}

Wheels:
{wheel_list}

## Install (as root; Debian 12: `apt install python3.11-venv`)

```sh
sha256sum -c {SUMS_NAME}
./install.sh    # /opt/edge-safety (venv), /etc/edge-safety (box.toml, *.env), /etc/systemd/system
# or: ./install.sh --prefix DIR --etc DIR [--systemd DIR | --no-systemd] [--python PYTHON]
```

`install.sh` checks this bundle against `{SUMS_NAME}`, the machine ({b.platform}) and the
Python ({PYTHON_VERSION}), creates the venv, installs from `wheels/` only (no index, no pip
configuration), checks every installed model against `manifest.json`, and copies `box.toml` and
the `.env` files to `/etc/edge-safety` unless they are there already.

## Run

```sh
$EDITOR /etc/edge-safety/box.toml /etc/edge-safety/{units[0]}.env
systemctl daemon-reload && systemctl enable --now {" ".join(units)}
journalctl -t {units[0]} -f              # one line per record: level=... component=... event=...
/opt/edge-safety/bin/edge-runtime wearable --print-config           # the effective configuration
/opt/edge-safety/bin/edge-wearable --replay imu.csv --alerts alerts.jsonl   # a recording
```

The units are `Type=notify` with `WatchdogSec=` and `Restart=on-failure`: the runtime says
READY once its loop turns and keeps the watchdog fed from that loop, so a hung loop is
restarted. Every model file is checked against `manifest.json` (sha256) before it is loaded;
a mismatch stops the runtime with one line naming the file.
"""


def product_requirements(product: str, with_extras: tuple[str, ...] = (),
                         setup_cfg: Path = SETUP_CFG) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """(the runtime wheel's extras, every requirement they and the base install bring) of ``product``."""
    if product not in PRODUCTS:
        raise BundleError(f"--product: {product!r}, expected one of {', '.join(PRODUCTS)}")
    extras_reqs = product_extras(setup_cfg)
    unknown = [e for e in with_extras if e not in extras_reqs]
    if unknown:
        raise BundleError(f"--with: {unknown[0]!r}, expected one of {', '.join(extras_reqs)}")
    extras = tuple(dict.fromkeys((*PRODUCTS[product], *with_extras)))
    base = runtime_metadata(setup_cfg)[1]
    return extras, tuple(dict.fromkeys((*base, *(r for e in extras for r in extras_reqs[e]))))


def build_bundle(out: str | os.PathLike, package: str | os.PathLike = RUNTIME_PACKAGE,
                 setup_cfg: str | os.PathLike = SETUP_CFG, product: str = "all", platform_name: str | None = None,
                 with_extras: tuple[str, ...] = (), find_links: tuple[str, ...] = (),
                 wheelhouse: bool = True) -> Bundle:
    """Build the bundle into ``out`` (see the module docstring) from the runtime ``package``.
    ``wheelhouse=False`` leaves ``wheels/`` out (tests of the rest that need no index)."""
    out, package, setup_cfg = Path(out), Path(package), Path(setup_cfg)
    platform_name = platform_name or platform.machine()
    if platform_name not in PLATFORMS:
        raise BundleError(f"--platform: {platform_name!r}, expected one of {', '.join(PLATFORMS)}")
    version, reqs = runtime_metadata(setup_cfg)
    extras_reqs = product_extras(setup_cfg)
    extras, requirements = product_requirements(product, with_extras, setup_cfg)
    if platform_name in ONNXRUNTIME_PINS:
        requirements = tuple(ONNXRUNTIME_PINS[platform_name] if _requirement_name(r) == "onnxruntime" else r
                             for r in requirements)
    manifest = verify_all(package / "assets")  # a tampered model never gets into a bundle
    from edge_runtime.wearable.alerts import DBC_PATH, DBC_SCHEDULE_PATH, check_frame_schedule

    # ... nor a frame schedule that is not its DBC's (the runtime would refuse it at its first frame)
    check_frame_schedule(package / "assets" / DBC_PATH.name, package / "assets" / DBC_SCHEDULE_PATH.name)
    from edge_runtime.config import load as load_config

    load_config(package / "box.example.toml")
    _prepare_out(out)
    wheel = build_wheel(out, package, version, reqs, extras_reqs, console_scripts(setup_cfg))
    check_wheel_assets(wheel, manifest)
    wheels = download_wheelhouse(out / "wheels", requirements, platform_name, PYTHON_VERSION, find_links) \
        if wheelhouse else []
    assets = out / "assets"
    shutil.copytree(package / "assets", assets, ignore=shutil.ignore_patterns("*.tmp.json", "__pycache__"))
    verify_all(assets)
    shutil.copy2(package / "box.example.toml", out / CONFIG_NAME)
    write_box_files(out, wheel, product, platform_name, PYTHON_VERSION, extras)
    b = Bundle(out, wheel, requirements, product, platform_name, extras)
    (out / "INSTALL.md").write_text(_install_text(b, manifest, wheels))
    return Bundle(out, wheel, requirements, product, platform_name, extras, write_sums(out))


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


def _run_in_venv(venv: Path, code: str, timeout_s: float = 120.0) -> str:
    """``code``'s output, run by the venv's Python isolated (``-I``: no PYTHON* variables, neither the
    current directory nor the script's on sys.path) from inside the venv. Why: run from a development
    checkout, ``python -c`` also saw its ``edge_safety.egg-info`` (the current directory) and PYTHONPATH's
    source tree, and the report listed them as installed distributions (edge-safety beside edge-safety-runtime)."""
    r = subprocess.run([str(venv_python(venv)), "-I", "-c", code], capture_output=True, text=True, check=True,
                       cwd=venv, timeout=timeout_s)
    return r.stdout


def site_packages(venv: Path) -> Path:
    return Path(_run_in_venv(venv, "import sysconfig; print(sysconfig.get_paths()['purelib'])").strip())


def installed_distributions(venv: Path) -> tuple[dict[str, int], list[str]]:
    """What the venv itself holds: each distribution's bytes (its files and their bytecode), and which of
    torch, cv2 and pymavlink it cannot import."""
    found = json.loads(_run_in_venv(venv, _PROBE))
    return found["dists"], found["absent"]


OFFLINE_ENV = {"PIP_NO_INDEX": "1", "PIP_FIND_LINKS": "", "PIP_INDEX_URL": "http://127.0.0.1:9/none",
               "PIP_EXTRA_INDEX_URL": "", "PIP_CONFIG_FILE": os.devnull}
"""No package index reachable: what install.sh must do without (tests and --measure-install)."""

_PROBE = """
import importlib.metadata as md, importlib.util as u, json, os
def size(d):  # its files (RECORD), and the bytecode install.sh compiled for them
    paths = [str(d.locate_file(f)) for f in d.files or ()]
    paths += [u.cache_from_source(p) for p in paths if p.endswith(".py")]
    return sum(os.path.getsize(p) for p in set(paths) if os.path.isfile(p))
print(json.dumps({"dists": {d.metadata["Name"]: size(d) for d in md.distributions()},
                  "absent": [m for m in ("torch", "cv2", "pymavlink") if u.find_spec(m) is None]}))
"""


def install_offline(bundle_dir: str | os.PathLike, prefix: str | os.PathLike, etc: str | os.PathLike,
                    python: str = sys.executable, timeout_s: float = 900.0) -> subprocess.CompletedProcess:
    """Run the bundle's install.sh into ``prefix`` (``etc`` for the configuration, no systemd
    units) with no package index reachable (:data:`OFFLINE_ENV`)."""
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "PYTHONHOME")} | OFFLINE_ENV
    return subprocess.run(["sh", str(Path(bundle_dir) / "install.sh"), "--prefix", str(prefix), "--etc", str(etc),
                           "--no-systemd", "--python", python], capture_output=True, text=True, env=env,
                          timeout=timeout_s)


def measure_install(bundle_dir: str | os.PathLike, venv: str | os.PathLike, timeout_s: float = 900.0) -> InstallReport:
    """The bundle installed offline (install.sh) into a fresh venv: its size, what each
    distribution costs, and which of torch, cv2 and pymavlink it cannot import."""
    venv = Path(venv)
    if venv.exists():
        raise BundleError(f"--venv {venv}: exists; give a new directory")
    r = install_offline(bundle_dir, venv, venv.parent / f"{venv.name}-etc", timeout_s=timeout_s)
    if r.returncode != 0:
        last = (r.stderr.strip().splitlines() or ["no output"])[-1]
        raise BundleError(f"{Path(bundle_dir) / 'install.sh'} into {venv}: exit {r.returncode}: {last}")
    found, absent = installed_distributions(venv)
    dists = tuple(sorted(found.items(), key=lambda kv: -kv[1]))
    return InstallReport(venv, _tree_bytes(venv), _tree_bytes(site_packages(venv)), dists,
                         "torch" not in absent, tuple(absent))


def format_install(rep: InstallReport) -> str:
    mib = 2 ** 20
    costs = ", ".join(f"{name} {size / mib:.1f}" for name, size in rep.distributions)
    return (f"installed offline (install.sh, fresh venv, no index): venv {rep.venv_bytes / mib:.1f} MiB "
            f"({rep.venv_bytes / 1e6:.1f} MB), site-packages {rep.site_packages_bytes / mib:.1f} MiB; "
            f"not importable: {', '.join(rep.absent) or 'none of torch, cv2, pymavlink'}"
            f"{' -- BUT torch is importable' if rep.torch_importable else ''}\n"
            f"  each distribution (MiB): {costs}")


# ---------------------------------------------------------------------------------------------- command

def add_arguments(parser) -> None:
    parser.add_argument("--out", required=True, metavar="DIR", help="bundle directory (new, empty, or a "
                                                                    "previous bundle, which is replaced)")
    parser.add_argument("--product", choices=tuple(PRODUCTS), default="all",
                        help="wearable (the base install), robot, or all (both, and a serial IMU); default all")
    parser.add_argument("--platform", choices=PLATFORMS, default=None,
                        help="the box's CPU (default: this machine's); the wheels are for it and CPython "
                             f"{PYTHON_VERSION}")
    parser.add_argument("--with", dest="with_extras", action="append", default=[], metavar="EXTRA",
                        help=f"add a runtime extra to the product ({', '.join(PRODUCT_EXTRAS)}), e.g. serial-imu")
    parser.add_argument("--find-links", action="append", default=[], metavar="DIR",
                        help="more wheels for the wheelhouse (built on the target for a package without one)")
    parser.add_argument("--measure-install", action="store_true",
                        help="install the bundle offline into a fresh venv and report its size without torch")
    parser.add_argument("--venv", default=None, metavar="DIR",
                        help="--measure-install: keep the venv here (default: a temporary one)")


def cmd(args) -> int:
    b = build_bundle(args.out, product=args.product, platform_name=args.platform,
                     with_extras=tuple(args.with_extras), find_links=tuple(args.find_links))
    total = sum((b.out / name).stat().st_size for name in b.files)
    n_wheels = sum(1 for name in b.files if name.startswith("wheels/"))
    print(f"{b.out}: {b.product} for {b.platform}: {b.wheel.name} ({b.wheel.stat().st_size / 2**20:.2f} MiB), "
          f"wheels/ ({n_wheels} wheels), assets/, {CONFIG_NAME}, systemd/, install.sh, INSTALL.md, {SUMS_NAME} "
          f"({len(b.files)} files, {total / 2**20:.2f} MiB)")
    print(f"  installs: {', '.join(b.requirements)}")
    if args.measure_install:
        if b.platform != platform.machine():
            raise BundleError(f"--measure-install: a {b.platform} bundle cannot be installed on this "
                              f"{platform.machine()} machine")
        with tempfile.TemporaryDirectory(prefix="bundle-venv-") as tmp:
            rep = measure_install(b.out, Path(args.venv) if args.venv else Path(tmp) / "venv")
            print("  " + format_install(rep))
        if rep.torch_importable:
            return 1
    return 0
