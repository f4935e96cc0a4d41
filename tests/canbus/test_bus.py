"""canbus/bus.py: only allow-listed interfaces open, and a bus that cannot be opened is one line."""
import pytest

from edge_runtime.canbus.bus import CanLinkError, open_bus


def test_open_bus_one_line_error():
    with pytest.raises(CanLinkError) as e:
        open_bus("no_such_interface", "can0")
    assert "\n" not in str(e.value) and "no_such_interface" in str(e.value)
    with pytest.raises(CanLinkError, match="not allowed"):
        open_bus("udp", "x")  # only the allow-listed bus interfaces open
