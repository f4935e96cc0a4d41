"""A pytest plugin: a test that starts a process must be marked ``slow``, or it fails.

``make test-fast`` runs ``-m "not slow"`` and promises a quick suite without child
processes (interpreters, the CAN hub or Sawyer controller as a process, venv builds,
git). Whether a test starts one is not visible in its source: it may happen deep in
a helper (``SawyerProcess``, ``--imu sim``, ``measure_install``). CPython raises an
audit event whenever a process is started, so one audit hook records them for the
test phase (setup, call, teardown) that is running, and the phase fails when its test
has no ``slow`` marker. A test run inside a test (pytester) reports to both.

tests/conftest.py loads this plugin for the whole suite.
"""
from __future__ import annotations

import sys
from collections.abc import Generator

import pytest

SPAWN_EVENTS = frozenset({"subprocess.Popen", "os.posix_spawn", "os.spawn", "os.exec", "os.fork", "os.forkpty",
                          "os.system"})
"""CPython's audit events for starting a process (see the audit events table of the docs)."""

_recorders: list[list[str]] = []
"""One list per running test phase (nested when a test runs pytest in-process)."""


def _describe(event: str, args: tuple) -> str:
    if event == "subprocess.Popen":  # (executable, args, cwd, env)
        argv = args[1]
        argv = " ".join(map(str, argv)) if isinstance(argv, list | tuple) else str(argv)
    else:
        argv = " ".join(str(a) for a in args[:2])
    return f"{event}: {argv[:160]}"


def _audit(event: str, args: tuple) -> None:
    if event in SPAWN_EVENTS:
        for spawned in _recorders:
            spawned.append(_describe(event, args))


sys.addaudithook(_audit)  # audit hooks cannot be removed: it records only while a phase runs


def _guard(item: pytest.Item) -> Generator[None, object, object]:
    spawned: list[str] = []
    _recorders.append(spawned)
    try:
        result = yield
    finally:
        _recorders.pop()
    if spawned and item.get_closest_marker("slow") is None:
        pytest.fail(f"{item.nodeid} started {len(spawned)} process(es) but is not marked @pytest.mark.slow "
                    f"(make test-fast must not start any); the first: {spawned[0]}", pytrace=False)
    return result


@pytest.hookimpl(wrapper=True)
def pytest_runtest_setup(item):
    return (yield from _guard(item))


@pytest.hookimpl(wrapper=True)
def pytest_runtest_call(item):
    return (yield from _guard(item))


@pytest.hookimpl(wrapper=True)
def pytest_runtest_teardown(item, nextitem):
    return (yield from _guard(item))
