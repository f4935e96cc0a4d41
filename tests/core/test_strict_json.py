"""edge_runtime.core.strict_json: what Python's json accepts or chokes on is one InputError."""
from __future__ import annotations

import math

import numpy as np
import pytest

from edge_runtime.core import strict_json
from edge_runtime.errors import InputError


@pytest.mark.parametrize("text, match", [
    (b'{"a": \xff}', r"^f.json: not UTF-8 text \(byte 7\)$"),
    ('{"a": NaN}', r"^f.json: NaN is not JSON"),
    ('{"a": -Infinity}', r"^f.json: -Infinity is not JSON"),
    ("[" * 100_000 + "]" * 100_000, r"^f.json: nested more than 64 levels deep$"),
    ("[" * 65 + "]" * 65, r"^f.json: nested more than 64 levels deep$"),
    ('{"a": ' + "1" * 5000 + "}", r"^f.json: .*digits"),
    ('{"a": ', r"^f.json: not valid JSON"),
])
def test_loads_refuses_in_one_line(text, match):
    with pytest.raises(InputError, match=match):
        strict_json.loads(text, "f.json", InputError)


def test_loads_takes_what_our_writers_write():
    assert strict_json.loads(b'{"a": [1, 2.5, null, "x"]}', "f.json", InputError) == {"a": [1, 2.5, None, "x"]}
    assert strict_json.loads("[" * 64 + "]" * 64, "f.json", InputError) is not None


@pytest.mark.parametrize("value", [True, "1", None, [], 10**400, math.inf, 1e400, 11.0, -0.5])
def test_number_refuses_what_is_not_a_finite_number_in_range(value):
    with pytest.raises(InputError, match=r"^x: expected a finite number in \[0, 10\], got "):
        strict_json.number(value, "x", InputError, 0, 10)


def test_number_array_names_the_entry_and_reads_null_as_nan():
    a = strict_json.number_array([[1, None], [3, 4]], (2, 2), "f: field 'A'", InputError, nulls=True)
    assert np.isnan(a[0, 1]) and a[1, 0] == 3.0
    with pytest.raises(InputError, match=r"^f: field 'A'\[1\]\[0\]: expected a finite number"):
        strict_json.number_array([[1, 2], ["3", 4]], (2, 2), "f: field 'A'", InputError)
    with pytest.raises(InputError, match=r"^f: field 'A'\[1\]: expected a list of 2"):
        strict_json.number_array([[1, 2], [3]], (2, 2), "f: field 'A'", InputError)
