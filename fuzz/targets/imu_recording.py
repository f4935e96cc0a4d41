"""An IMU recording (``--replay FILE.imu``, written by ``--record``) -> its reader -> the wearable loop -> the model.

Seeds: the stretches of a simulated drive of :func:`fuzz.seeds.event_starts` (each holds a
detector trigger, so mutated samples reach a capture), written by the runtime's own
RecordingWriter in records of a few hundred samples (so mutations hit record headers too). The
model is the range probe: a non-finite value or one beyond the sensor range reaching it is a
silent acceptance.
"""
from __future__ import annotations

import functools
import struct

import numpy as np
from hypothesis import strategies as st

from edge_runtime.errors import InputError
from edge_runtime.wearable.recording import RecordingWriter, read_recording
from edge_runtime.wearable.sources import ImuBlock
from fuzz.mutate import GENERIC_TOKENS, mutated
from fuzz.probe import through_loop
from fuzz.scratch import scratch_file
from fuzz.seeds import drive, event_starts, recording

NAME = "imu_recording"
DOCUMENTED = (InputError,)
SEED_RECORD_ROWS = 300
"""Samples per record of the seeds: four records per seed."""
TOKENS = GENERIC_TOKENS + tuple(struct.pack("<f", v) for v in (np.nan, np.inf, -np.inf, 3.4e38, 156.9, 157.0, -1e-45)) \
    + tuple(struct.pack("<d", v) for v in (np.nan, -1.0, 1e11, 0.005)) \
    + tuple(struct.pack("<I", v) for v in (0, 1, 65536, 65537, 2**32 - 1))


@functools.lru_cache(maxsize=None)
def seeds() -> tuple[bytes, ...]:
    _, acc = drive()
    rate = recording().sample_rate_hz
    out = []
    for s in event_starts():
        path = scratch_file("seed.imu", b"")
        w = RecordingWriter(path, record_rows=SEED_RECORD_ROWS)
        w.write(ImuBlock(s / rate, acc[s : s + 1200]))
        w.close()
        out.append(path.read_bytes())
    return tuple(out)


def strategy() -> st.SearchStrategy[bytes]:
    return mutated(list(seeds()), TOKENS)


def run(data: bytes) -> None:
    through_loop(read_recording(scratch_file("imu.imu", data)))
