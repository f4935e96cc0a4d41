"""Fixtures shared across the suite. Helpers that are not fixtures live in ``support/``.

Plugins: ``support.process_guard`` fails a test that starts a process without the ``slow``
marker; ``pytester`` runs pytest inside a test (for that guard's own test).

``make test`` runs the suite on both cores (pytest-xdist, ``-n 2 --dist loadfile``); the hook
below decides which tests share a worker (tests/README.md, "Parallel")."""
from pathlib import Path

import pytest

from firmware_sim.devices.can_hub import CanHub

pytest_plugins = ["support.process_guard", "pytester"]

TESTS = Path(__file__).resolve().parent
E2E = TESTS / "e2e"


@pytest.hookimpl(optionalhook=True)  # a hook of pytest-xdist, absent without it
def pytest_xdist_make_scheduler(config, log):
    """``--dist loadfile`` as xdist does it (a file's tests on one worker, so its module-scoped fixtures,
    a trained model or a simulated run, are built once), but with the whole of ``e2e/`` as one unit:
    its tests run processes on the wall clock, so they take turns rather than starve each other."""
    if config.getvalue("dist") != "loadfile":
        return None
    from xdist.scheduler import LoadFileScheduling

    e2e = E2E.relative_to(config.rootpath).as_posix() + "/"

    class FilesAndE2E(LoadFileScheduling):
        def _split_scope(self, nodeid: str) -> str:
            scope = super()._split_scope(nodeid)
            return e2e if scope.startswith(e2e) else scope

    return FilesAndE2E(config, log)


@pytest.fixture
def hub():
    """A socketcand-protocol CAN hub on 127.0.0.1 (an ephemeral port), stopped after the test."""
    h = CanHub(port=0, seed=3).start()
    yield h
    h.stop()

