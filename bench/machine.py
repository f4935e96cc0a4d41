"""The machine a bench ran on, and CPU pinning (``--cpus``)."""
from __future__ import annotations

import os
import platform

import numpy as np


def torch_version() -> str | None:
    """torch's version, or None when torch cannot be imported (a box)."""
    try:
        import torch
    except ImportError:
        return None
    return torch.__version__


def _cpuinfo() -> tuple[str, list[str]]:
    cpu, flags = platform.processor() or platform.machine(), []
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                elif line.startswith("flags") and not flags:
                    flags = line.split(":", 1)[1].split()
                if flags and cpu:
                    break
    except OSError:
        pass
    return cpu, flags


def openvino_version() -> str | None:
    """OpenVINO's installed version (from its metadata: importing it takes a second), or None."""
    from importlib import metadata

    try:
        return metadata.version("openvino")
    except metadata.PackageNotFoundError:
        return None


def machine_info(with_torch: bool = True) -> dict:
    """CPU model, cores, the cores this process may use, ISA extensions that matter for int8,
    load average (a noisy machine shows here), python, numpy, onnxruntime, openvino and torch versions."""
    import onnxruntime

    cpu, flags = _cpuinfo()
    try:
        affinity = sorted(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        affinity = None
    try:
        load = [round(x, 2) for x in os.getloadavg()]
    except OSError:
        load = None
    return {
        "cpu": cpu,
        "cores": os.cpu_count(),
        "cpus_used": affinity,
        "isa": [f for f in ("avx2", "avx512f", "avx512_vnni", "avx_vnni", "amx_int8") if f in flags],
        "load_avg_1_5_15": load,
        "platform": platform.platform(),
        "python": platform.python_version(),
        "numpy": np.__version__,
        "onnxruntime": onnxruntime.__version__,
        "openvino": openvino_version(),
        "torch": torch_version() if with_torch else None,
    }


def parse_cpus(spec: str) -> list[int]:
    """``"0,1"`` or ``"0-1"`` -> [0, 1]; ValueError naming the bad part."""
    cpus: set[int] = set()
    for part in spec.split(","):
        part = part.strip()
        lo, sep, hi = part.partition("-")
        try:
            a, b = int(lo), int(hi) if sep else int(lo)
        except ValueError:
            raise ValueError(f"--cpus {spec!r}: {part!r} is not a CPU number or range (e.g. 0,1 or 0-1)") from None
        if a < 0 or b < a:
            raise ValueError(f"--cpus {spec!r}: {part!r} is not a valid CPU range")
        cpus.update(range(a, b + 1))
    return sorted(cpus)


def require_cpus(cpus: list[int], option: str) -> None:
    """ValueError naming ``option`` unless every one of ``cpus`` is available to this process."""
    allowed = os.sched_getaffinity(0)
    missing = sorted(set(cpus) - allowed)
    if missing:
        raise ValueError(f"{option}: CPU(s) {missing} not available to this process (available: {sorted(allowed)})")


def pin_cpus(cpus: list[int]) -> list[int]:
    """Pin this process (and the children it starts) to ``cpus``; ValueError if they are not available."""
    require_cpus(cpus, "--cpus")
    os.sched_setaffinity(0, cpus)
    return sorted(os.sched_getaffinity(0))


def _spin(cpu: int) -> None:
    os.sched_setaffinity(0, [cpu])
    while True:
        pass


class LoadGenerator:
    """One busy-looping process pinned to each of ``cpus`` while the ``with`` block runs: "the
    other core busy", as a box running the camera decoder or the wearable beside the robot loop
    would have it. Pin the bench itself elsewhere (``--cpus``) or the two share a core."""

    def __init__(self, cpus: list[int]):
        require_cpus(cpus, "--busy-cpus")
        self.cpus = list(cpus)
        self.procs: list = []

    def __enter__(self) -> "LoadGenerator":
        import multiprocessing as mp

        ctx = mp.get_context("spawn")  # no copy of the bench's state (sessions, threads) in the spinner
        self.procs = [ctx.Process(target=_spin, args=(c,), daemon=True) for c in self.cpus]
        for p in self.procs:
            p.start()
        return self

    def __exit__(self, *exc) -> None:
        for p in self.procs:
            p.terminate()
        for p in self.procs:
            p.join(5)
