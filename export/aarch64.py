"""``python -m export.aarch64 --work DIR`` (``make aarch64-check``): the aarch64 wearable bundle on
an emulated arm64 Debian 12, against this machine's x86 run of the same recording.

1. **Root.** ``mmdebstrap --mode=unshare --variant=extract --arch=arm64`` builds an arm64
   bookworm root with python3.11 (and its headers) from the Debian mirror apt knows; it is
   run as ``qemu-aarch64-static -L ROOT ROOT/usr/bin/python3.11`` (no binfmt_misc needed).
2. **autosar-e2e.** PyPI has no aarch64 wheel of it: its sdist (pip download) is compiled with
   Debian's cross compiler (``aarch64-linux-gnu-gcc``) against the root's Python 3.11 headers
   into a ``cp311-abi3-manylinux_2_36_aarch64`` wheel (C modules linking libc only, Debian 12's
   glibc 2.36), the layout its own build (scikit-build-core) gives.
3. **Bundle.** ``python -m export bundle --product wearable --platform aarch64 --find-links``
   that wheel; the bundle pins onnxruntime to :data:`export.bundle.ONNXRUNTIME_PINS` for aarch64.
4. **Install.** The bundle's wheels go into ``DIR/site`` with this machine's pip
   (``--target``, ``--platform``: nothing runs under emulation to install).
5. **Replay.** The same simulated drive replayed with ``--alerts`` here (x86, the development
   checkout) and under emulation (the installed runtime): the decisions must be the same
   (trigger time, label, status, alerted, AlertSeq; confidence within 1e-3).
6. **Models.** :mod:`export.runtime_check` runs every shipped model under emulation: int8 and
   fp32 outputs against x86's, argmax agreement, and the time per inference under emulation
   (not a speed claim: qemu translates every instruction).

Needs Debian's ``qemu-user-static``, ``mmdebstrap`` and ``gcc-aarch64-linux-gnu`` (``apt-get
install``) and the network (Debian mirror, PyPI). Exit status 0 when the alerts and models
agree, 1 otherwise; a missing tool is one line, exit 2.
"""
from __future__ import annotations

import argparse
import base64
import hashlib
import json
import os
import shutil
import subprocess
import sys
import tarfile
import tempfile
import zipfile
from pathlib import Path

from edge_runtime.cli import CliError

ROOT = Path(__file__).resolve().parent.parent
SUITE = "bookworm"
PACKAGES = "python3.11,libpython3.11-stdlib,libpython3.11-dev,libstdc++6,libgcc-s1,libgomp1"
E2E_VERSION = "1.0.0"
E2E_TAG = "cp311-abi3-manylinux_2_36_aarch64"
CROSS_CC = "aarch64-linux-gnu-gcc"
QEMU = "qemu-aarch64-static"
E2E_MODULES = {"crc": ["crclib.c"], "p01": ["crclib.c"], "p02": ["crclib.c"], "p04": ["crclib.c", "util.c"],
               "p05": ["crclib.c", "util.c"], "p06": ["crclib.c", "util.c"], "p07": ["crclib.c", "util.c"],
               "p11": ["crclib.c"]}
"""Each C module of autosar-e2e and the static helpers it links (its CMakeLists.txt)."""
COMPARED = ("t_trigger_s", "t_alert_s", "label", "status", "alerted", "alert_seq")
"""Decision fields that must be equal on both machines; ``confidence`` within CONFIDENCE_TOL."""
CONFIDENCE_TOL = 1e-3


class Aarch64Error(CliError):
    """A tool or download is missing (one line, exit 2)."""


def _run(cmd: list[str], what: str, **kw) -> subprocess.CompletedProcess:
    try:
        r = subprocess.run(cmd, capture_output=True, text=True, **kw)
    except FileNotFoundError:
        raise Aarch64Error(f"{what}: {cmd[0]} not found (apt-get install qemu-user-static mmdebstrap "
                           "gcc-aarch64-linux-gnu)") from None
    if r.returncode != 0:
        tail = (r.stderr.strip() or r.stdout.strip() or "no output").splitlines()[-1]
        raise Aarch64Error(f"{what}: exit {r.returncode}: {tail}")
    return r


def debian_mirror() -> str:
    """The Debian mirror apt uses here (deb822 or one-line sources), else deb.debian.org."""
    for f in [Path("/etc/apt/sources.list"), *sorted(Path("/etc/apt/sources.list.d").glob("*"))]:
        try:
            text = f.read_text()
        except OSError:
            continue
        for line in text.splitlines():
            words = line.split()
            if words[:1] == ["URIs:"] and len(words) > 1 and "security" not in words[1]:
                return words[1]
            if words[:1] == ["deb"] and "security" not in line:
                return next(w for w in words[1:] if "://" in w)
    return "http://deb.debian.org/debian"


def build_root(root: Path) -> Path:
    """The arm64 Debian root (kept: rebuilt only when it has no python3.11)."""
    if (root / "usr/bin/python3.11").exists():
        return root
    shutil.rmtree(root, ignore_errors=True)
    root.parent.mkdir(parents=True, exist_ok=True)
    _run(["mmdebstrap", "--mode=unshare", "--variant=extract", "--arch=arm64", "--skip=check/qemu",
          f"--include={PACKAGES}", SUITE, str(root), debian_mirror()], "mmdebstrap", timeout=1800)
    return root


def _record_line(name: str, data: bytes) -> str:
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    return f"{name},sha256={digest},{len(data)}"


def e2e_wheel(root: Path, out: Path) -> Path:
    """autosar-e2e's aarch64 wheel, cross-compiled from its sdist against ``root``'s headers."""
    wheel = out / f"autosar_e2e-{E2E_VERSION}-{E2E_TAG}.whl"
    if wheel.exists():
        return wheel
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="e2e-") as td:
        td = Path(td)
        _run([sys.executable, "-m", "pip", "download", "--quiet", "--no-deps", "--no-binary", "autosar-e2e",
              f"autosar-e2e=={E2E_VERSION}", "-d", str(td)], "pip download autosar-e2e (sdist)", timeout=600)
        sdist = next(td.glob("autosar_e2e-*.tar.gz"))
        with tarfile.open(sdist) as t:
            t.extractall(td, filter="data")
        src = td / f"autosar_e2e-{E2E_VERSION}"
        pkg = src / "src" / "e2e"
        files: dict[str, bytes] = {}
        for mod, helpers in E2E_MODULES.items():
            so = td / f"{mod}.abi3.so"
            # the limited API of 3.11 (abi3), as the PyPI wheels are built; -idirafter: the cross
            # compiler's own libc headers first, the root's only for Debian's multiarch pyconfig.h
            _run([CROSS_CC, "-shared", "-fPIC", "-O2", "-DPy_LIMITED_API=0x030B0000",
                  f"-I{root}/usr/include/python3.11", f"-idirafter{root}/usr/include", f"-I{pkg}",
                  str(pkg / f"{mod}.c"), *(str(pkg / h) for h in helpers), "-o", str(so)], f"{CROSS_CC} {mod}.c")
            files[f"e2e/{mod}.abi3.so"] = so.read_bytes()
        for p in sorted(pkg.iterdir()):
            if p.suffix in (".py", ".pyi") or p.name == "py.typed":
                files[f"e2e/{p.name}"] = p.read_bytes()
        info = f"autosar_e2e-{E2E_VERSION}.dist-info"
        files[f"{info}/METADATA"] = (src / "PKG-INFO").read_bytes()
        files[f"{info}/WHEEL"] = (f"Wheel-Version: 1.0\nGenerator: edge-safety export.aarch64\n"
                                  f"Root-Is-Purelib: false\nTag: {E2E_TAG}\n").encode()
        files[f"{info}/LICENSE.txt"] = (src / "LICENSE.txt").read_bytes()
        record = [_record_line(n, d) for n, d in files.items()] + [f"{info}/RECORD,,"]
        files[f"{info}/RECORD"] = ("\n".join(record) + "\n").encode()
        with zipfile.ZipFile(wheel, "w", zipfile.ZIP_DEFLATED) as z:
            for name, data in files.items():
                z.writestr(name, data)
    return wheel


def install_site(bundle: Path, site: Path) -> Path:
    """The bundle's runtime wheel and its wheels, unpacked for aarch64 into ``site`` (no index)."""
    from export.bundle import PYTHON_VERSION, platform_tags

    shutil.rmtree(site, ignore_errors=True)
    runtime_wheel = next(bundle.glob("edge_safety_runtime-*.whl"))
    _run([sys.executable, "-m", "pip", "install", "--quiet", "--no-index", "--find-links", str(bundle / "wheels"),
          "--only-binary=:all:", "--target", str(site), "--python-version", PYTHON_VERSION, "--implementation", "cp",
          *(a for tag in platform_tags("aarch64") for a in ("--platform", tag)), str(runtime_wheel)],
         "pip install --target (aarch64 wheels)", timeout=900)
    return site


def emulated(root: Path) -> list[str]:
    return [QEMU, "-L", str(root), str(root / "usr/bin/python3.11")]


def _decisions(path: Path) -> list[dict]:
    return [d for d in map(json.loads, path.read_text().splitlines()) if "t_trigger_s" in d]


def compare_decisions(x86: list[dict], arm: list[dict]) -> dict:
    """Equal decisions (COMPARED fields) and the largest confidence difference."""
    same = len(x86) == len(arm) and all(all(a.get(k) == b.get(k) for k in COMPARED) for a, b in zip(x86, arm))
    dconf = max((abs(a["confidence"] - b["confidence"]) for a, b in zip(x86, arm)), default=0.0)
    return {"decisions_x86": len(x86), "decisions_aarch64": len(arm),
            "alerts_x86": sum(bool(d.get("alerted")) for d in x86),
            "alerts_aarch64": sum(bool(d.get("alerted")) for d in arm),
            "same_sequence": same, "max_confidence_diff": dconf, "ok": same and dconf <= CONFIDENCE_TOL}


def label_agreement(a: list[dict], b: list[dict]) -> dict:
    """Of the captures both runs classified (same trigger time), the share with the same class."""
    by_t = {d["t_trigger_s"]: d["label"] for d in b}
    both = [d for d in a if d["t_trigger_s"] in by_t]
    same = sum(d["label"] == by_t[d["t_trigger_s"]] for d in both)
    return {"captures": len(both), "same_class": same, "agreement": same / len(both) if both else float("nan")}


def replay(python: list[str], csv: Path, alerts: Path, env: dict | None = None, model: str = "int8") -> float:
    """``wearable --replay`` with ``--alerts``; returns the wall time in seconds."""
    import time

    t = time.perf_counter()
    _run([*python, "-m", "edge_runtime", "wearable", "--replay", str(csv), "--alerts", str(alerts), "--quiet",
          "--model", model], f"replay on {python[0]}", env=env, timeout=7200)
    return time.perf_counter() - t


def check(work: Path, minutes: float = 30.0, seed: int = 2027, log=print) -> dict:
    from edge_runtime.core.manifest import ASSETS_DIR, verify_all
    from export.runtime_check import compare as compare_models
    from export.runtime_check import fixed_inputs, run_outputs

    work = work.resolve()
    log(f"[1/6] arm64 {SUITE} root -> {work / 'root'}")
    root = build_root(work / "root")
    log("[2/6] autosar-e2e for aarch64 (cross-compiled)")
    wheel = e2e_wheel(root, work / "wheels")
    log("[3/6] wearable bundle for aarch64")
    bundle = work / "bundle"
    _run([sys.executable, "-m", "export", "bundle", "--product", "wearable", "--platform", "aarch64",
          "--find-links", str(wheel.parent), "--out", str(bundle)], "export bundle --platform aarch64", timeout=1800)
    log("[4/6] installing the bundle's wheels for aarch64")
    site = install_site(bundle, work / "site")
    env = {**os.environ, "PYTHONPATH": str(site), "PYTHONNOUSERSITE": "1"}
    log(f"[5/6] replaying a {minutes:g}-minute drive (seed {seed}) on x86 and under emulation")
    drive = work / "drive"
    _run([sys.executable, "-m", "firmware_sim", "drive", "--minutes", str(minutes), "--seed", str(seed), "--out",
          str(drive)], "firmware_sim drive", timeout=1800)
    report: dict = {"root": str(root), "e2e_wheel": wheel.name, "drive": {"minutes": minutes, "seed": seed}}
    for model in ("int8", "fp32"):
        x86_s = replay([sys.executable], drive / "imu.csv", work / f"alerts_x86_{model}.jsonl", model=model)
        arm_s = replay(emulated(root), drive / "imu.csv", work / f"alerts_aarch64_{model}.jsonl", env, model)
        report[f"replay_{model}"] = {**compare_decisions(_decisions(work / f"alerts_x86_{model}.jsonl"),
                                                         _decisions(work / f"alerts_aarch64_{model}.jsonl")),
                                     "wall_s_x86": round(x86_s, 2), "wall_s_aarch64_emulated": round(arm_s, 2)}
        log(f"      {model}: {report[f'replay_{model}']}")
    report["int8_fp32_label_agreement_aarch64"] = label_agreement(_decisions(work / "alerts_aarch64_int8.jsonl"),
                                                                  _decisions(work / "alerts_aarch64_fp32.jsonl"))
    log("[6/6] every shipped model under emulation against x86")
    manifest = verify_all(ASSETS_DIR)
    feed = fixed_inputs(manifest)
    ref = run_outputs([sys.executable], ASSETS_DIR, feed)
    arm = run_outputs(emulated(root), ASSETS_DIR, feed, env=env)
    report["onnxruntime_aarch64"] = str(arm["__version__"])
    report["models"] = compare_models(manifest, ref, arm)
    report["models_x86_p50_us"] = {k.split("/")[0]: float(v) for k, v in ref.items() if k.endswith("/__p50_us__")}
    report["models_aarch64_emulated_p50_us"] = {k.split("/")[0]: float(v) for k, v in arm.items()
                                                 if k.endswith("/__p50_us__")}
    report["ok"] = all(report[f"replay_{m}"]["ok"] for m in ("int8", "fp32")) and all(
        r["ok"] for r in report["models"].values())
    (work / "report.json").write_text(json.dumps(report, indent=2))
    return report


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m export.aarch64", description=__doc__.split("\n\n")[0])
    p.add_argument("--work", default=str(ROOT / "runs" / "aarch64"), help="work directory (default runs/aarch64)")
    p.add_argument("--minutes", type=float, default=30.0, help="minutes of the simulated drive (default 30)")
    p.add_argument("--seed", type=int, default=2027)
    a = p.parse_args(argv)
    from edge_runtime.cli import run

    def go() -> int:
        r = check(Path(a.work), a.minutes, a.seed)
        print(json.dumps({k: v for k, v in r.items() if k != "models"}, indent=2))
        for name, m in r["models"].items():
            print(f"{name}: {m}")
        return 0 if r["ok"] else 1

    return run(go, bad_input=(Aarch64Error,), what="aarch64 check")


if __name__ == "__main__":
    sys.exit(main())
