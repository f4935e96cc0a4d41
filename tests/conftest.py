"""Fixtures shared across the suite. Helpers that are not fixtures live in ``support/``.

Plugins: ``support.process_guard`` fails a test that starts a process without the ``slow``
marker; ``pytester`` runs pytest inside a test (for that guard's own test)."""
import pytest

from firmware_sim.devices.can_hub import CanHub

pytest_plugins = ["support.process_guard", "pytester"]


@pytest.fixture
def hub():
    """A socketcand-protocol CAN hub on 127.0.0.1 (an ephemeral port), stopped after the test."""
    h = CanHub(port=0, seed=3).start()
    yield h
    h.stop()
