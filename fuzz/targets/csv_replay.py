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


def strategy() -> st.SearchStrategy[bytes]:
    return mutated(list(drive_csvs()), TOKENS)


def run(data: bytes) -> None:
    through_loop(read_imu_csv(scratch_file("imu.csv", data)))
