"""Fixtures shared across the suite. Helpers that are not fixtures live in ``support/``."""
import pytest

from firmware_sim.devices.can_hub import CanHub


@pytest.fixture
def hub():
    """A socketcand-protocol CAN hub on 127.0.0.1 (an ephemeral port), stopped after the test."""
    h = CanHub(port=0, seed=3).start()
    yield h
    h.stop()
