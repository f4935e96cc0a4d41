"""Drive one target with N inputs from its hypothesis strategy and count what happened.

An input's outcome is one of: refused with the target's documented error (fine), accepted
(fine), a crash (any other exception), a silent acceptance (:class:`SilentAcceptance`: a
value outside the stated range reached a model or a command) or a hang (longer than the
per-input timeout). Hypothesis only generates here (no shrinking, no database): the harness
wants counts over many inputs, not the one minimal failure a property test reports.
"""
from __future__ import annotations

import importlib
import pkgutil
import signal
import threading
import time
import traceback
from dataclasses import asdict, dataclass, field
from pathlib import Path
from types import ModuleType

from hypothesis import HealthCheck, Phase, given, settings
from hypothesis import seed as hypothesis_seed

import fuzz.targets

REPO = Path(__file__).resolve().parent.parent
MAX_EXAMPLES_SHOWN = 5
"""Distinct tracebacks kept per outcome kind (deduplicated by exception type and location)."""


class SilentAcceptance(Exception):
    """Raised by a target when a value outside the stated range reached a model or a command."""


class GoodInputLost(Exception):
    """Raised by a target when genuine input after the fuzzed one was not delivered (a starved
    link, a parser that did not resynchronise). Counted as a crash: the input broke the parser."""


class Hang(BaseException):
    """Raised by the per-input timer; a BaseException so a target's ``except Exception`` cannot eat it."""


@dataclass
class Finding:
    kind: str
    """'crash', 'silent' or 'hang'."""
    key: str
    """Exception type and the innermost frame's file:line: what deduplicates findings."""
    count: int
    traceback: str
    example: str
    """The first input that produced it (repr, truncated)."""


@dataclass
class TargetReport:
    name: str
    inputs: int = 0
    refused: int = 0
    """Inputs refused with the documented error."""
    crashes: int = 0
    silent_acceptances: int = 0
    hangs: int = 0
    seconds: float = 0.0
    findings: list[Finding] = field(default_factory=list)
    commit: str = ""
    """The code commit the target ran on, when a merged report joins runs of several commits."""

    @property
    def rate_per_s(self) -> float:
        return self.inputs / self.seconds if self.seconds > 0 else 0.0

    @property
    def clean(self) -> bool:
        return self.crashes == 0 and self.silent_acceptances == 0 and self.hangs == 0

    def to_json(self) -> dict:
        out = asdict(self)
        out["rate_per_s"] = round(self.rate_per_s, 1)
        out["seconds"] = round(self.seconds, 2)
        return out


def discover() -> dict[str, ModuleType]:
    """Every module of fuzz/targets, by its NAME (a duplicate NAME is an error)."""
    found: dict[str, ModuleType] = {}
    for info in sorted(pkgutil.iter_modules(fuzz.targets.__path__), key=lambda i: i.name):
        mod = importlib.import_module(f"fuzz.targets.{info.name}")
        for attr in ("NAME", "DOCUMENTED", "strategy", "run"):
            if not hasattr(mod, attr):
                raise TypeError(f"fuzz/targets/{info.name}.py has no {attr} (see fuzz/README.md)")
        if mod.NAME in found:
            raise ValueError(f"two fuzz targets are named {mod.NAME!r}")
        found[mod.NAME] = mod
    return found


def _location(tb) -> str:
    frames = traceback.extract_tb(tb)
    if not frames:
        return "?"
    f = frames[-1]
    try:
        name = str(Path(f.filename).resolve().relative_to(REPO))
    except ValueError:
        name = Path(f.filename).name
    return f"{name}:{f.lineno}"


class _Timer:
    """SIGALRM after ``timeout_s`` when running in the main thread (an endless loop is
    interrupted); elsewhere an input over the timeout is still counted as a hang afterwards."""

    def __init__(self, timeout_s: float):
        self.timeout_s = timeout_s
        self.armed = threading.current_thread() is threading.main_thread() and hasattr(signal, "setitimer")

    def __enter__(self):
        if self.armed:
            self._old = signal.signal(signal.SIGALRM, self._fire)
            # repeating: a Hang raised inside a gc callback is swallowed by Python, so fire again
            signal.setitimer(signal.ITIMER_REAL, self.timeout_s, 0.5)
        return self

    @staticmethod
    def _fire(signum, frame):
        raise Hang()

    def __exit__(self, *exc):
        if self.armed:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, self._old)
        return False


def run_target(mod: ModuleType, inputs: int, seed: int = 0, timeout_s: float = 5.0) -> TargetReport:
    """``inputs`` inputs of ``mod.strategy()`` through ``mod.run``, seeded."""
    rep = TargetReport(mod.NAME)
    by_key: dict[str, Finding] = {}

    def record(kind: str, exc: BaseException, data) -> None:
        key = f"{kind}: {type(exc).__name__} at {_location(exc.__traceback__)}"
        f = by_key.get(key)
        if f is None:
            f = by_key[key] = Finding(kind, key, 0, "".join(traceback.format_exception(exc))[-3000:],
                                      repr(data)[:400])
        f.count += 1

    def one(data) -> None:
        rep.inputs += 1
        t0 = time.perf_counter()
        try:
            with _Timer(timeout_s):
                mod.run(data)
        except Hang as e:
            rep.hangs += 1
            record("hang", e, data)
            return
        except SilentAcceptance as e:
            rep.silent_acceptances += 1
            record("silent", e, data)
        except mod.DOCUMENTED:
            rep.refused += 1
        except Exception as e:  # noqa: BLE001 - counting every undocumented exception is the point
            rep.crashes += 1
            record("crash", e, data)
        if time.perf_counter() - t0 > timeout_s:  # not interrupted (not the main thread)
            rep.hangs += 1
            by_key.setdefault(f"hang: over {timeout_s} s", Finding("hang", f"hang: over {timeout_s} s", 0, "",
                                                                   repr(data)[:400])).count += 1

    drive = settings(max_examples=inputs, database=None, deadline=None, phases=[Phase.generate],
                     suppress_health_check=list(HealthCheck), derandomize=False)(given(mod.strategy())(one))
    t_start = time.perf_counter()
    hypothesis_seed(seed)(drive)()
    rep.seconds = time.perf_counter() - t_start
    shown: dict[str, int] = {}
    for f in sorted(by_key.values(), key=lambda f: -f.count):
        if shown.get(f.kind, 0) < MAX_EXAMPLES_SHOWN:
            rep.findings.append(f)
            shown[f.kind] = shown.get(f.kind, 0) + 1
    return rep
