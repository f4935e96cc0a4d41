"""A CSV recording (``--replay FILE.csv``) -> the replay reader -> the wearable loop -> the model.

Seeds: stretches of a simulated drive around real distraction events, so that mutated
samples end up in a capture. The model is the range probe: a non-finite value or one
beyond the configured sensor range reaching it is a silent acceptance.
"""
from __future__ import annotations

from hypothesis import strategies as st

from edge_runtime.errors import InputError
from edge_runtime.wearable.sources import read_imu_csv
from fuzz.mutate import GENERIC_TOKENS, mutated
from fuzz.probe import through_loop
from fuzz.scratch import scratch_file
from fuzz.seeds import drive_csvs

NAME = "csv_replay"
DOCUMENTED = (InputError,)
TOKENS = GENERIC_TOKENS + (b",200.5", b"\n0.01,1,2,3", b"9999999999999999999999", b"1e38", b"-160", b"+inf", b"0.00")


VALUES = ("nan", "inf", "-inf", "3.4e38", "-3.5e38", "1.7e308", "1e400", "9" * 400, "200.5", "-156.9", "156.9",
          "156.91", "2000", "1e-320", "-0", "0x10", "1_0", "", " ", "\xff")


def _edit_cells(seed: bytes, edits: list[tuple[int, int, str]]) -> bytes:
    """Cells of the seed's rows replaced (row index, column, text): values that parse, or nearly."""
    lines = seed.split(b"\n")
    for row, col, text in edits:
        i = 1 + row % max(1, len(lines) - 2)  # never the header
        cells = lines[i].split(b",")
        cells[col % len(cells)] = text.encode("utf-8", "surrogateescape") if text != "\xff" else b"\xff"
        lines[i] = b",".join(cells)
    return b"\n".join(lines)


def strategy() -> st.SearchStrategy[bytes]:
    edit = st.tuples(st.integers(0, 2**20), st.integers(0, 3), st.sampled_from(VALUES))
    cells = st.builds(_edit_cells, st.sampled_from(drive_csvs()), st.lists(edit, min_size=1, max_size=12))
    values = st.builds(_edit_cells, st.sampled_from(drive_csvs()),
                       st.lists(st.tuples(st.integers(0, 2**20), st.integers(1, 3), st.sampled_from(VALUES[:13])),
                                min_size=1, max_size=12))
    return st.one_of(mutated(list(drive_csvs()), TOKENS), cells, values, values)


def run(data: bytes) -> None:
    through_loop(read_imu_csv(scratch_file("imu.csv", data)))
