"""canbus/dbc.py: a DBC that cannot be parsed is one line naming the file."""
import pytest

from edge_runtime.canbus.bus import CanLinkError
from edge_runtime.canbus.dbc import load_dbc


def test_unparsable_dbc_is_one_line_naming_the_file(tmp_path):
    bad = tmp_path / "broken.dbc"
    bad.write_text("BO_ x\n")
    with pytest.raises(CanLinkError) as e:
        load_dbc(bad)
    assert "\n" not in str(e.value) and str(bad) in str(e.value)
