"""``python -m export.aarch64 --work DIR`` (``make aarch64-check``): the aarch64 wearable bundle,
installed by its own ``install.sh`` on an emulated arm64 Debian 12, against the x86 bundle
installed the same way on this machine, on the same simulated drive.

1. **Root.** ``mmdebstrap --mode=unshare --variant=extract --arch=arm64`` builds a bookworm root
   with python3.11 (headers, venv) and what ``install.sh`` runs (dash, coreutils, diffutils, sed)
   from the Debian mirror apt knows. This machine has no binfmt_misc, so an aarch64 program cannot
   start another one by itself: ``proot -q qemu-aarch64-static -r ROOT`` runs every program of the
   root, and every program those start, under qemu (``install.sh`` starts sh, sha256sum, python,
   pip...), with the work directory bound at its own path.
2. **autosar-e2e.** PyPI has no aarch64 wheel of it (a C extension): its sdist (sha256 pinned) is
   compiled with Debian's cross compiler against the root's Python 3.11 headers into a
   ``cp311-abi3-manylinux_2_36_aarch64`` wheel with fixed timestamps, so the same sdist gives the
   same bytes. ``python -m export.aarch64 --e2e-wheel DIR`` does this alone.
3. **Bundles.** ``python -m export bundle --product wearable`` for aarch64 (``--find-links`` that
   wheel; onnxruntime pinned, :data:`export.bundle.ONNXRUNTIME_PINS`) and for x86_64.
4. **Install.** Each bundle's ``install.sh`` with no package index (:data:`export.bundle.OFFLINE_ENV`):
   the aarch64 one under emulation, the x86 one here.
5. **Replay.** The installed ``edge-wearable`` replays the same drive on both, int8 and fp32, with
   the shipped streaming decider and the capture path's early and full-window decisions: the decisions must be the same (trigger and alert times,
   class, status, alerted, AlertSeq; confidence within :data:`CONFIDENCE_TOL`) and so must every
   CAN frame sent, but for the measured time in an alert's TimeSinceTrigger (and the CRC over it);
   every aarch64 frame must pass x86's E2E check.
6. **Models and E2E.** Every shipped model under emulation against x86 (:mod:`export.runtime_check`,
   timed per inference: not a speed claim, qemu translates every instruction), and the aarch64
   autosar-e2e's CRCs against x86's.

The result is written as JSON and Markdown (``--report-dir``; by default reports/box/aarch64.json and reports/box/aarch64.md).
Exit status 0 when everything agrees, 1 otherwise; a missing tool, download or build step is one
line, exit 2.
"""
from __future__ import annotations

import argparse
import base64
import hashlib
import json
import platform
import re
import shutil
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
import zipfile
from pathlib import Path

from edge_runtime.cli import CliError

ROOT = Path(__file__).resolve().parent.parent
SUITE = "bookworm"
PACKAGES = ("python3.11", "libpython3.11-stdlib", "libpython3.11-dev", "python3.11-venv", "libstdc++6",
            "libgcc-s1", "libgomp1", "dash", "coreutils", "diffutils", "sed")
"""The root's packages: Python with headers (the cross build) and venv (install.sh), onnxruntime's
C++ runtime, and what install.sh runs; the extract variant brings no Essential set of its own."""
E2E_VERSION = "1.0.0"
E2E_SDIST_SHA256 = "e740c9896000a164769c8d4294cdb0504b76d7728e571e11d2e8c1d69967d932"
"""autosar_e2e-1.0.0.tar.gz as PyPI serves it: the wheel is built from these bytes only."""
E2E_TAG = "cp311-abi3-manylinux_2_36_aarch64"
WHEEL_DATE = (1980, 1, 1, 0, 0, 0)
"""Every wheel member's zip timestamp (the earliest zip allows): no build time in the bytes."""
CROSS_CC = "aarch64-linux-gnu-gcc"
QEMU = "qemu-aarch64-static"
TOOLS = {"mmdebstrap": "mmdebstrap", QEMU: "qemu-user-static", "proot": "proot", CROSS_CC: "gcc-aarch64-linux-gnu"}
"""Each program this check runs and the Debian package that has it."""
E2E_MODULES = {"crc": ["crclib.c"], "p01": ["crclib.c"], "p02": ["crclib.c"], "p04": ["crclib.c", "util.c"],
               "p05": ["crclib.c", "util.c"], "p06": ["crclib.c", "util.c"], "p07": ["crclib.c", "util.c"],
               "p11": ["crclib.c"]}
"""Each C module of autosar-e2e and the static helpers it links (its CMakeLists.txt)."""
COMPARED = ("t_trigger_s", "t_alert_s", "label", "status", "alerted", "alert_seq")
"""Decision fields that must be equal on both machines; ``confidence`` within CONFIDENCE_TOL."""
CONFIDENCE_TOL = 1e-3
CAN_MEASURED = ("TimeSinceTrigger", "E2E_CRC")
"""Alert signals that may differ between machines: TimeSinceTrigger adds the measured inference
time (emulation is ~1000x slower), and the CRC covers it."""
ONNXRUNTIME_ALSO = ("1.22.1", "1.28.0", "1.32.0")
"""onnxruntime versions whose aarch64 wheels also run the shipped models under emulation, beside the
bundle's pinned one: the range the bundle's install notes state (export.bundle.ONNXRUNTIME_TESTED) comes from here."""
MODELS = ("int8", "fp32")
DECISIONS = ("stream", "early", "full_window")
"""The shipped decider first, then the capture path's two (``--model int8|fp32`` names each one's model)."""
EMU_ENV = {"PATH": "/usr/local/bin:/usr/bin:/bin", "HOME": "/tmp", "LANG": "C.UTF-8"}
"""The emulated programs' whole environment: nothing of this machine's Python or pip leaks in."""
E2E_PROBE = ("import importlib, json, e2e.crc as c; d = bytes(range(1, 10)); "
             "[importlib.import_module('e2e.' + m) for m in {mods!r}]; "
             "print(json.dumps({{n: getattr(c, n)(d) for n in sorted(dir(c)) if n.startswith('calculate_')}}))")
"""Imports every C module of autosar-e2e and prints every CRC of fixed bytes."""


class Aarch64Error(CliError):
    """A tool, download or build step failed (one line, exit 2)."""


def missing_tools(which=None) -> list[str]:
    """The Debian packages to install for the programs this check runs that are not on PATH."""
    which = which or shutil.which
    return sorted({pkg for prog, pkg in TOOLS.items() if which(prog) is None})


def _run(cmd: list[str], what: str, **kw) -> subprocess.CompletedProcess:
    try:
        r = subprocess.run(cmd, capture_output=True, text=True, **kw)
    except FileNotFoundError:
        raise Aarch64Error(f"{what}: {cmd[0]} not found (apt-get install {' '.join(sorted(set(TOOLS.values())))})") \
            from None
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
    """The arm64 Debian root, kept between runs while it was built with today's PACKAGES."""
    stamp = root / ".edge-safety-packages"
    if stamp.exists() and stamp.read_text() == ",".join(PACKAGES):
        return root
    shutil.rmtree(root, ignore_errors=True)
    root.parent.mkdir(parents=True, exist_ok=True)
    _run(["mmdebstrap", "--mode=unshare", "--variant=extract", "--arch=arm64", "--skip=check/qemu",
          f"--include={','.join(PACKAGES)}", SUITE, str(root), debian_mirror()], "mmdebstrap", timeout=1800)
    stamp.write_text(",".join(PACKAGES))
    return root


def _record_line(name: str, data: bytes) -> str:
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    return f"{name},sha256={digest},{len(data)}"


def write_wheel(path: Path, files: dict[str, bytes], info: str) -> Path:
    """A wheel of ``files`` plus ``info/RECORD``: members sorted, fixed timestamps and modes, so
    the same files give the same bytes."""
    record = [_record_line(n, d) for n, d in sorted(files.items())] + [f"{info}/RECORD,,"]
    members = {**files, f"{info}/RECORD": ("\n".join(record) + "\n").encode()}
    tmp = path.with_suffix(".part")
    with zipfile.ZipFile(tmp, "w") as z:
        for name in sorted(members, key=lambda n: (n.startswith(info), n)):  # dist-info last, as pip writes
            zi = zipfile.ZipInfo(name, WHEEL_DATE)
            zi.compress_type = zipfile.ZIP_DEFLATED
            zi.external_attr = (0o755 if name.endswith(".so") else 0o644) << 16
            z.writestr(zi, members[name])
    tmp.replace(path)
    return path


def e2e_wheel(root: Path, out: Path) -> Path:
    """autosar-e2e's aarch64 wheel, cross-compiled from its pinned sdist against ``root``'s headers.

    Cross-compiled rather than built by the root's own gcc under qemu: seconds instead of an
    emulated toolchain, and the modules link libc only, so nothing of the root but Python's
    headers goes in; the emulated run then proves them (E2E_PROBE, every CAN frame's CRC)."""
    wheel = out / f"autosar_e2e-{E2E_VERSION}-{E2E_TAG}.whl"
    if wheel.exists():
        return wheel
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="e2e-") as td:
        td = Path(td)
        _run([sys.executable, "-m", "pip", "download", "--quiet", "--no-deps", "--no-binary", "autosar-e2e",
              f"autosar-e2e=={E2E_VERSION}", "-d", str(td)], "pip download autosar-e2e (sdist)", timeout=600)
        sdist = next(td.glob("autosar_e2e-*.tar.gz"))
        got = hashlib.sha256(sdist.read_bytes()).hexdigest()
        if got != E2E_SDIST_SHA256:
            raise Aarch64Error(f"{sdist.name}: sha256 {got}, expected {E2E_SDIST_SHA256} (E2E_SDIST_SHA256)")
        with tarfile.open(sdist) as t:
            t.extractall(td, filter="data")
        src = td / f"autosar_e2e-{E2E_VERSION}"
        pkg = src / "src" / "e2e"
        files: dict[str, bytes] = {}
        for mod, helpers in E2E_MODULES.items():
            so = td / f"{mod}.abi3.so"
            # the limited API of 3.11 (abi3), as the PyPI wheels are built; -idirafter: the cross
            # compiler's own libc headers first, the root's only for Debian's multiarch pyconfig.h;
            # -ffile-prefix-map: the temporary directory's name stays out of the binary
            _run([CROSS_CC, "-shared", "-fPIC", "-O2", "-DPy_LIMITED_API=0x030B0000", f"-ffile-prefix-map={td}=.",
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
        return write_wheel(wheel, files, info)


def emulated(root: Path, work: Path) -> list[str]:
    """The command prefix that runs a program of the arm64 root (and all it starts) under qemu,
    with ``work`` at its own path. /proc, /dev and /sys from this machine: onnxruntime's cpuinfo
    aborts the process when it cannot read /sys/devices/system/cpu."""
    binds = [a for d in ("/proc", "/dev", "/sys", "/tmp", str(work)) for a in ("-b", d)]
    return ["proot", "-q", QEMU, "-r", str(root), *binds, "-w", str(work)]


def install_emulated(bundle: Path, prefix: Path, root: Path, work: Path) -> float:
    """The bundle's install.sh, run under emulation with no package index; its wall time (s)."""
    from export.bundle import OFFLINE_ENV

    shutil.rmtree(prefix, ignore_errors=True)
    shutil.rmtree(prefix.with_name(prefix.name + "-etc"), ignore_errors=True)
    t = time.perf_counter()
    _run([*emulated(root, work), "/bin/sh", str(bundle / "install.sh"), "--prefix", str(prefix),
          "--etc", str(prefix.with_name(prefix.name + "-etc")), "--no-systemd", "--python", "python3.11"],
         "install.sh under emulation", env=EMU_ENV | OFFLINE_ENV, timeout=3600)
    return time.perf_counter() - t


def install_here(bundle: Path, prefix: Path) -> float:
    from export.bundle import install_offline

    shutil.rmtree(prefix, ignore_errors=True)
    shutil.rmtree(prefix.with_name(prefix.name + "-etc"), ignore_errors=True)
    t = time.perf_counter()
    r = install_offline(bundle, prefix, prefix.with_name(prefix.name + "-etc"))
    if r.returncode != 0:
        raise Aarch64Error(f"{bundle}/install.sh: exit {r.returncode}: "
                           f"{(r.stderr.strip().splitlines() or ['no output'])[-1]}")
    return time.perf_counter() - t


def decisions(path: Path) -> list[dict]:
    return [d for d in map(json.loads, path.read_text().splitlines()) if "t_trigger_s" in d]


def compare_decisions(x86: list[dict], arm: list[dict]) -> dict:
    """Equal decisions (COMPARED fields) and the largest confidence difference."""
    same = len(x86) == len(arm) and all(all(a.get(k) == b.get(k) for k in COMPARED) for a, b in zip(x86, arm))
    dconf = max((abs(a["confidence"] - b["confidence"]) for a, b in zip(x86, arm)), default=0.0)
    return {"decisions_x86": len(x86), "decisions_aarch64": len(arm),
            "alerts_x86": sum(bool(d.get("alerted")) for d in x86),
            "alerts_aarch64": sum(bool(d.get("alerted")) for d in arm),
            "same_sequence": same, "max_confidence_diff": dconf, "ok": same and dconf <= CONFIDENCE_TOL}


def class_agreement(a: list[dict], b: list[dict], which: str = "last") -> dict:
    """Of the captures (trigger times) both runs decided, the share whose ``which`` decision
    ("first": the earliest, e.g. a preliminary; "last": the final one) has the same class."""
    pick = (lambda ds: ds[0]) if which == "first" else (lambda ds: ds[-1])

    def per_capture(ds):
        by_t: dict[float, list[dict]] = {}
        for d in ds:
            by_t.setdefault(d["t_trigger_s"], []).append(d)
        return {t: pick(v)["label"] for t, v in by_t.items()}

    pa, pb = per_capture(a), per_capture(b)
    both = [t for t in pa if t in pb]
    same = sum(pa[t] == pb[t] for t in both)
    return {"captures": len(both), "same_class": same, "agreement": same / len(both) if both else None}


def compare_can(x86: list, arm: list, db) -> dict:
    """The CAN frames each machine sent (python-can Messages, in order): how many are identical,
    how many differ only in CAN_MEASURED signals, the first other difference, and the E2E check
    (x86's autosar-e2e) of every frame each sent."""
    from edge_runtime.canbus.e2e import E2EChecker

    def e2e_errors(frames):
        checker = E2EChecker(db=db)
        return sum(not checker.check(m).valid for m in frames)

    def signals(m):
        return {k: v for k, v in db.decode_message(m.arbitration_id, m.data, decode_choices=False).items()
                if k not in CAN_MEASURED}

    identical = measured_only = 0
    first_other = None
    for i, (a, b) in enumerate(zip(x86, arm)):
        if (a.timestamp, a.arbitration_id, bytes(a.data)) == (b.timestamp, b.arbitration_id, bytes(b.data)):
            identical += 1
        elif (a.timestamp, a.arbitration_id) == (b.timestamp, b.arbitration_id) and signals(a) == signals(b):
            measured_only += 1
        elif first_other is None:
            first_other = {"frame": i, "x86": f"{a.timestamp} {a.arbitration_id:#x} {bytes(a.data).hex()}",
                           "aarch64": f"{b.timestamp} {b.arbitration_id:#x} {bytes(b.data).hex()}"}
    r = {"frames_x86": len(x86), "frames_aarch64": len(arm), "identical": identical,
         "differ_only_in_" + "_".join(CAN_MEASURED): measured_only, "first_other_difference": first_other,
         "e2e_errors_x86": e2e_errors(x86), "e2e_errors_aarch64": e2e_errors(arm)}
    r["ok"] = (len(x86) == len(arm) == identical + measured_only and first_other is None
               and r["e2e_errors_x86"] == r["e2e_errors_aarch64"] == 0)
    return r


def read_can_log(path: Path) -> list:
    import can

    return list(can.CSVReader(str(path)))


def replay(cmd: list[str], csv: Path, out: Path, model: str, decision: str, env: dict | None = None) -> float:
    """The installed ``edge-wearable --replay`` with ``--alerts out.jsonl`` and ``--can-log out.csv``;
    its wall time in seconds."""
    t = time.perf_counter()
    _run([*cmd, "--replay", str(csv), "--alerts", str(out.with_suffix(".jsonl")), "--can-log",
          str(out.with_suffix(".csv")), "--quiet", "--model", model, "--decision", decision],
         f"{cmd[-1]} --replay --model {model} --decision {decision}", env=env, timeout=7200)
    return time.perf_counter() - t


def _median_compute_us(ds: list[dict]) -> float | None:
    xs = [d["compute_us"] for d in ds if d.get("compute_us") is not None]
    return round(statistics.median(xs), 1) if xs else None


def _installed_assets(prefix: Path) -> Path:
    return next(prefix.glob("lib/python3.11/site-packages/edge_runtime/assets"))


def e2e_probe(python: list[str], env: dict | None = None) -> dict:
    r = _run([*python, "-c", E2E_PROBE.format(mods=sorted(E2E_MODULES))], f"autosar-e2e probe on {python[0]}",
             env=env, timeout=600)
    return json.loads(r.stdout.strip().splitlines()[-1])


def _version(cmd: list[str]) -> str:
    """``program X.Y.Z`` from a tool's version output (proot's comes under a banner)."""
    try:
        r = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired):
        return f"{cmd[0]} (version unknown)"
    m = re.search(r"\d+\.\d+(\.\d+)?", r.stdout + r.stderr)
    return f"{cmd[0]} {m.group(0) if m else '(version unknown)'}"


def other_onnxruntime(version: str, work: Path, python: list[str], assets: Path, feed: dict, ref: dict,
                      manifest: dict) -> dict:
    """The shipped models under emulation with onnxruntime ``version``'s aarch64 wheel (put ahead of
    the installed one on PYTHONPATH; its dependencies are the bundle's) against x86's outputs."""
    from export.bundle import PYTHON_VERSION, platform_tags
    from export.runtime_check import compare as compare_models
    from export.runtime_check import run_outputs

    target = work / "onnxruntime" / version
    if not (target / "onnxruntime").is_dir():
        shutil.rmtree(target, ignore_errors=True)
        _run([sys.executable, "-m", "pip", "install", "--quiet", "--no-deps", "--only-binary=:all:", "--target",
              str(target), "--python-version", PYTHON_VERSION, "--implementation", "cp",
              *(a for tag in platform_tags("aarch64") for a in ("--platform", tag)), f"onnxruntime=={version}"],
             f"pip install onnxruntime=={version} for aarch64", timeout=900)
    try:
        out = run_outputs(python, assets, feed, env=EMU_ENV | {"PYTHONPATH": str(target)}, timed_calls=0)
    except RuntimeError as e:  # an import that crashes under qemu: the reason a pin exists
        return {"ok": False, "error": re.sub(r"pid \d+: ", "", str(e).split(": ", 1)[-1])[:200]}
    if str(out["__version__"]) != version:
        raise Aarch64Error(f"onnxruntime {version} under emulation imported {out['__version__']} instead")
    models = compare_models(manifest, ref, out)
    return {"ok": all(m["ok"] for m in models.values()), "models": models}


def _shown(path: Path) -> str:
    """``path`` relative to the checkout when inside it (reports name no machine's directories)."""
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)


def check(work: Path, minutes: float = 5.0, seed: int = 2027, also: tuple[str, ...] = ONNXRUNTIME_ALSO,
          log=print) -> dict:
    from edge_runtime.canbus.dbc import load_dbc
    from export.runtime_check import compare as compare_models
    from export.runtime_check import fixed_inputs, run_outputs

    missing = missing_tools()
    if missing:
        raise Aarch64Error(f"missing tools: apt-get install {' '.join(missing)}")
    work = work.resolve()
    log(f"[1/7] arm64 {SUITE} root -> {work / 'root'}")
    root = build_root(work / "root")
    log("[2/7] autosar-e2e for aarch64 (cross-compiled from its sdist)")
    wheel = e2e_wheel(root, work / "wheels")
    log("[3/7] wearable bundles for aarch64 and x86_64")
    bundles = {arch: work / f"bundle-{arch}" for arch in ("aarch64", "x86_64")}
    for arch, out in bundles.items():
        _run([sys.executable, "-m", "export", "bundle", "--product", "wearable", "--platform", arch,
              *(["--find-links", str(wheel.parent)] if arch == "aarch64" else []), "--out", str(out)],
             f"export bundle --platform {arch}", timeout=1800)
    log("[4/7] install.sh offline: aarch64 under emulation, x86_64 here")
    box = {arch: work / f"box-{arch}" for arch in bundles}
    install_s = {"aarch64_emulated": install_emulated(bundles["aarch64"], box["aarch64"], root, work),
                 "x86_64": install_here(bundles["x86_64"], box["x86_64"])}
    emu = emulated(root, work)
    cmds = {"x86_64": ([str(box["x86_64"] / "bin" / "edge-wearable")], None),
            "aarch64": ([*emu, str(box["aarch64"] / "bin" / "edge-wearable")], EMU_ENV)}
    log(f"[5/7] a {minutes:g}-minute drive (seed {seed}) replayed by both installed edge-wearable commands")
    drive = work / "drive"
    _run([sys.executable, "-m", "firmware_sim", "drive", "--minutes", str(minutes), "--seed", str(seed), "--out",
          str(drive)], "firmware_sim drive", timeout=1800)
    db = load_dbc(_installed_assets(box["x86_64"]) / "vehicle_alerts.dbc")
    replays: dict = {}
    for model in MODELS:
        for decision in DECISIONS:
            key, runs = f"{model}_{decision}", {}
            for arch, (cmd, env) in cmds.items():
                out = work / "replays" / f"{arch}_{model}_{decision}"
                out.parent.mkdir(exist_ok=True)
                wall = replay(cmd, drive / "imu.csv", out, model, decision, env)
                runs[arch] = (decisions(out.with_suffix(".jsonl")), read_can_log(out.with_suffix(".csv")), wall)
            replays[key] = {"decisions": compare_decisions(runs["x86_64"][0], runs["aarch64"][0]),
                            "can": compare_can(runs["x86_64"][1], runs["aarch64"][1], db),
                            "compute_us_median": {a: _median_compute_us(r[0]) for a, r in runs.items()},
                            "wall_s": {a: round(r[2], 2) for a, r in runs.items()}}
            replays[key]["ok"] = replays[key]["decisions"]["ok"] and replays[key]["can"]["ok"]
            log(f"      {key}: decisions {replays[key]['decisions']['ok']}, CAN {replays[key]['can']['ok']}")
    agreement = {}
    for decision in DECISIONS:
        arm = {m: decisions(work / "replays" / f"aarch64_{m}_{decision}.jsonl") for m in MODELS}
        agreement[decision] = {w: class_agreement(arm["int8"], arm["fp32"], w)
                               for w in (("first", "last") if decision == "early" else ("last",))}
    log("[6/7] every shipped model under emulation against x86")
    ref_python = [str(box["x86_64"] / "bin" / "python")]
    arm_python = [*emu, str(box["aarch64"] / "bin" / "python")]
    from edge_runtime.core.manifest import verify_all

    manifest = verify_all(_installed_assets(box["x86_64"]))
    feed = fixed_inputs(manifest)
    ref = run_outputs(ref_python, _installed_assets(box["x86_64"]), feed)
    arm = run_outputs(arm_python, _installed_assets(box["aarch64"]), feed, env=EMU_ENV)
    models = compare_models(manifest, ref, arm)
    onnxruntime_range = {v: other_onnxruntime(v, work, arm_python, _installed_assets(box["aarch64"]), feed, ref,
                                              manifest) for v in also if v != str(arm["__version__"])}
    log("[7/7] autosar-e2e's CRCs under emulation against x86")
    e2e_ref, e2e_arm = e2e_probe(ref_python), e2e_probe(arm_python, EMU_ENV)
    report = {
        "command": f"python -m export.aarch64 --work {_shown(work)} --minutes {minutes:g} --seed {seed}"
                   + "".join(f" --onnxruntime {v}" for v in also),
        "machine": platform.machine(),
        "emulator": _version([QEMU, "--version"]), "proot": _version(["proot", "-V"]),
        "root": {"suite": SUITE, "packages": list(PACKAGES)},
        "e2e_wheel": {"name": wheel.name, "sha256": hashlib.sha256(wheel.read_bytes()).hexdigest(),
                      "sdist_sha256": E2E_SDIST_SHA256, "in_bundle": (bundles["aarch64"] / "wheels" / wheel.name).exists()},
        "onnxruntime": {"x86_64": str(ref["__version__"]), "aarch64": str(arm["__version__"])},
        "install_wall_s": {k: round(v, 1) for k, v in install_s.items()},
        "drive": {"minutes": minutes, "seed": seed},
        "replays": replays,
        "int8_fp32_class_agreement_aarch64": agreement,
        "models": models,
        "onnxruntime_also_aarch64": onnxruntime_range,
        "model_p50_us_batch1": {arch: {k.split("/")[0]: round(float(v), 1) for k, v in out.items()
                                       if k.endswith("/__p50_us__")} for arch, out in (("x86_64", ref),
                                                                                       ("aarch64_emulated", arm))},
        "e2e_crc": {"x86_64": e2e_ref, "aarch64": e2e_arm, "ok": e2e_ref == e2e_arm},
    }
    report["ok"] = (all(r["ok"] for r in replays.values()) and all(m["ok"] for m in models.values())
                    and report["e2e_crc"]["ok"] and report["e2e_wheel"]["in_bundle"])
    return report


def _pct(a: dict) -> str:
    return "–" if a["agreement"] is None else f"{a['same_class']}/{a['captures']} ({100 * a['agreement']:.1f} %)"


def markdown(r: dict) -> str:
    """The report as Markdown: every figure from ``r``, nothing typed in."""
    yes = {True: "**yes**", False: "**NO**"}
    lines = [
        "# aarch64 (emulated) against x86_64: the wearable bundle", "",
        f"Written by `{r['command']}` (`make aarch64-check`) on {r['machine']}. Overall: "
        f"{'agree' if r['ok'] else '**DISAGREE**'}.", "",
        f"- Emulation: {r['emulator']}; {r['proot']} (no binfmt_misc here: proot starts every program "
        f"under qemu); Debian {r['root']['suite']} arm64 root.",
        f"- autosar-e2e for aarch64: `{r['e2e_wheel']['name']}` (sha256 `{r['e2e_wheel']['sha256']}`), "
        f"cross-compiled from the sdist (sha256 `{r['e2e_wheel']['sdist_sha256']}`); in the bundle's wheels/: "
        f"{yes[r['e2e_wheel']['in_bundle']]}.",
        f"- onnxruntime: x86_64 {r['onnxruntime']['x86_64']}, aarch64 {r['onnxruntime']['aarch64']}.",
        f"- install.sh (offline, `--no-index`): aarch64 under emulation {r['install_wall_s']['aarch64_emulated']} s, "
        f"x86_64 {r['install_wall_s']['x86_64']} s.",
        f"- Drive: {r['drive']['minutes']:g} simulated minutes, seed {r['drive']['seed']}, replayed by each "
        "installed `edge-wearable`.", "",
        "## Same alerts", "",
        "| model, decisions | decisions x86 / aarch64 | alerts x86 / aarch64 | same sequence | max confidence diff "
        "| CAN frames identical + only TimeSinceTrigger | E2E errors x86 / aarch64 | agree |",
        "|---|---:|---:|---|---:|---:|---:|---|",
    ]
    for key, rep in r["replays"].items():
        d, c = rep["decisions"], rep["can"]
        measured = c["differ_only_in_" + "_".join(CAN_MEASURED)]
        lines.append(f"| {key} | {d['decisions_x86']} / {d['decisions_aarch64']} | {d['alerts_x86']} / "
                     f"{d['alerts_aarch64']} | {yes[d['same_sequence']]} | {d['max_confidence_diff']:.1e} | "
                     f"{c['identical']} + {measured} of {c['frames_x86']} / {c['frames_aarch64']} | "
                     f"{c['e2e_errors_x86']} / {c['e2e_errors_aarch64']} | {yes[rep['ok']]} |")
    lines += ["", "Compared per decision: trigger and alert time, class, status, alerted, AlertSeq; confidence "
              f"within {CONFIDENCE_TOL:g}. CAN: every frame's time, ID and signals, but for "
              f"{' and '.join(CAN_MEASURED)} (the measured inference time is part of TimeSinceTrigger).", "",
              "## int8 against fp32 on aarch64 (same capture, same class)", ""]
    for decision, rows in r["int8_fp32_class_agreement_aarch64"].items():
        lines += [f"- {decision}: " + "; ".join(f"{w} decision per capture {_pct(a)}" for w, a in rows.items())]
    lines += ["", "## Every shipped model under emulation against x86 (fixed inputs, batch 4)", "",
              "| model | loaded | max abs difference | argmax agree | ok |", "|---|---|---:|---:|---|"]
    for name, m in r["models"].items():
        lines.append(f"| {name} | {m['loaded']} | {m.get('max_abs', float('nan')):.1e} | "
                     f"{m.get('argmax_agree', '–')} | {yes[m['ok']]} |")
    lines += ["", f"The same models with other onnxruntime versions' aarch64 wheels (bundle: "
              f"{r['onnxruntime']['aarch64']}; not part of the overall verdict):", ""]
    for version, o in r["onnxruntime_also_aarch64"].items():
        what = (f"every model within tolerance: {yes[o['ok']]}" if "models" in o
                else f"**fails**: {o['error']}")
        lines.append(f"- onnxruntime {version}: {what}")
    lines += ["", f"autosar-e2e CRCs of fixed bytes, aarch64 against x86: {yes[r['e2e_crc']['ok']]} "
              f"({len(r['e2e_crc']['aarch64'])} functions).", "",
              "## Time per inference under emulation: NOT a speed claim", "",
              "qemu translates every aarch64 instruction on this x86 machine; these times say the emulated "
              "run was exercised, not how fast an aarch64 box is.", "",
              "| | x86_64 | aarch64 (emulated) |", "|---|---:|---:|"]
    p50 = r["model_p50_us_batch1"]
    for name in p50["x86_64"]:
        lines.append(f"| {name}: p50, batch 1, 1 thread (µs) | {p50['x86_64'][name]} | "
                     f"{p50['aarch64_emulated'].get(name, '–')} |")
    for key, rep in r["replays"].items():
        lines.append(f"| replay {key}: median classifier call per decision, µs (compute_us: preprocessing + inference) | {rep['compute_us_median']['x86_64']} | "
                     f"{rep['compute_us_median']['aarch64']} |")
        lines.append(f"| replay {key}: wall time of the command (s) | {rep['wall_s']['x86_64']} | "
                     f"{rep['wall_s']['aarch64']} |")
    return "\n".join(lines) + "\n"


def write_report(r: dict, out_dir: Path) -> tuple[Path, Path]:
    out_dir.mkdir(parents=True, exist_ok=True)
    js, md = out_dir / "aarch64.json", out_dir / "aarch64.md"
    js.write_text(json.dumps(r, indent=2) + "\n")
    md.write_text(markdown(r))
    return js, md


def main(argv=None) -> int:
    p = argparse.ArgumentParser(prog="python -m export.aarch64", description=__doc__.split("\n\n")[0])
    # outside the repository: the work directory holds whole venvs and a Debian root (~800 MB), third-party
    # code the repository's own checks must not scan as if it were the project's
    p.add_argument("--work", default=str(Path.home() / ".cache" / "edge-safety" / "aarch64"),
                   help="work directory (default ~/.cache/edge-safety/aarch64)")
    p.add_argument("--minutes", type=float, default=5.0, help="minutes of the simulated drive (default 5)")
    p.add_argument("--seed", type=int, default=2027)
    p.add_argument("--report-dir", default=str(ROOT / "reports" / "box"),
                   help="where aarch64.json and aarch64.md go (default reports/box)")
    p.add_argument("--onnxruntime", action="append", default=None, metavar="VERSION",
                   help="also run the models with this onnxruntime's aarch64 wheel (repeatable; default "
                        + ", ".join(ONNXRUNTIME_ALSO) + ")")
    p.add_argument("--e2e-wheel", metavar="DIR", default=None,
                   help="only build autosar-e2e's aarch64 wheel into DIR (for export bundle --find-links DIR)")
    a = p.parse_args(argv)
    from edge_runtime.cli import run

    def go() -> int:
        if a.minutes <= 0:
            raise Aarch64Error(f"--minutes: {a.minutes:g}, expected more than 0")
        for flag, d in (("--work", a.work), ("--report-dir", a.report_dir), ("--e2e-wheel", a.e2e_wheel)):
            if d and Path(d).exists() and not Path(d).is_dir():
                raise Aarch64Error(f"{flag} {d}: not a directory")
        bad = [v for v in a.onnxruntime or () if not re.fullmatch(r"\d+(\.\d+)*", v)]
        if bad:
            raise Aarch64Error(f"--onnxruntime {bad[0]}: expected a version such as 1.22.1")
        if a.e2e_wheel:
            need = sorted({TOOLS["mmdebstrap"], TOOLS[CROSS_CC]} & set(missing_tools()))
            if need:
                raise Aarch64Error(f"missing tools: apt-get install {' '.join(need)}")
            print(e2e_wheel(build_root(Path(a.work).resolve() / "root"), Path(a.e2e_wheel).resolve()))
            return 0
        r = check(Path(a.work), a.minutes, a.seed, tuple(a.onnxruntime or ONNXRUNTIME_ALSO))
        js, md = write_report(r, Path(a.report_dir))
        print(markdown(r))
        print(f"written: {js}, {md}")
        return 0 if r["ok"] else 1

    return run(go, bad_input=(Aarch64Error,), what="aarch64 check")


if __name__ == "__main__":
    sys.exit(main())
