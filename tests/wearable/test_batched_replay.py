"""The replay's batched classification (``WearableLoop._classify_ahead``) decides exactly what the
live path decides one sample at a time, whatever the block sizes, bad samples and time gaps, and
whichever way its guess of the captures needing early steps goes wrong.

The stand-in model answers a repeatable pseudo-random class per capture and step (a hash of the
frames it is given), so decisions of every status happen and a batched row that was not what a
single call would give, or a step decided out of order, changes the decisions."""
import hashlib
import itertools

import numpy as np
import pytest

from edge_runtime.wearable.classifier import needed_frames
from edge_runtime.wearable.labels import CLASSES
from edge_runtime.wearable.loop import AlertPolicy, WearableLoop
from edge_runtime.wearable.sources import SAMPLE_RATE_HZ, ImuBlock


class _Early:
    min_confidence_by_steps: dict = {}
    temperature_by_steps: dict = {}


class HashModel:
    """Probabilities from a hash of the frames: the capture's first frames pick a class most of the
    time (a distraction the steps agree on), the whole prefix sometimes another (a revision)."""
    classes = CLASSES
    early_steps = (1, 2, 3, 4, 5, 6)
    early = _Early()

    def classify_prefix(self, x, steps):
        x = np.ascontiguousarray(x, np.float32)
        assert len(x) == needed_frames(steps)
        base = int.from_bytes(hashlib.sha1(x[:148].tobytes()).digest()[:4], "little")
        h = int.from_bytes(hashlib.sha1(x.tobytes() + bytes([steps])).digest()[:4], "little")
        top = 0.3 + (h >> 8) % 1000 / 1000 * 0.69  # confident or not, against every threshold
        p = np.full(len(CLASSES), (1.0 - top) / (len(CLASSES) - 1))
        p[base % len(CLASSES) if h % 5 else h % len(CLASSES)] = top
        return p.astype(np.float32)

    def classify_capture(self, x):
        return self.classify_prefix(x, 6)


class BatchedHashModel(HashModel):
    """The same answers, asked for many captures at once."""

    def classify_capture_groups(self, groups):
        return [{s: np.stack([self.classify_prefix(c[:needed_frames(s)], s) for c in captures]) for s in steps}
                for captures, steps in groups]


def _drive(seed, minutes):
    """A simulated drive cut into segments by time gaps, with runs of NaN samples: (t0_s, acc, continuous)."""
    from firmware_sim.devices.wrist import simulate_drive
    rng = np.random.default_rng(seed)
    acc = np.ascontiguousarray(simulate_drive(minutes, seed=seed).acc_mps2, dtype=np.float32).copy()
    for start in rng.integers(0, len(acc) - 50, 2):
        acc[start:start + rng.integers(1, 40)] = np.nan
    cuts = sorted(rng.integers(1, len(acc) - 1, 2).tolist())
    segments, t0_s = [], 0.0
    for a, b in itertools.pairwise([0, *cuts, len(acc)]):
        segments.append((t0_s, acc[a:b], a == 0))
        t0_s += (b - a) / SAMPLE_RATE_HZ + 3.0  # a 3 s hole in the data between segments
    return rng, segments


def _decisions(loop, segments, block_sizes=None, rng=None):
    """Feed the segments whole, or in blocks of sizes drawn from ``block_sizes`` (1 = the live path)."""
    out = []
    for t0_s, acc, continuous in segments:
        i = 0
        while i < len(acc):
            n = len(acc) if block_sizes is None else int(rng.choice(block_sizes))
            out += loop.feed(ImuBlock(t0_s + i / SAMPLE_RATE_HZ, acc[i:i + n], continuous=continuous or i > 0))
            i += n
    return [{k: v for k, v in d.to_json().items() if k not in ("compute_us", "latency_ms")} for d in out]


@pytest.mark.parametrize("policy", [
    AlertPolicy(decision="early"),
    AlertPolicy(decision="early", event_hold_s=60.0, event_ends_on_other=False),
    AlertPolicy(decision="full_window", event_hold_s=20.0),
    AlertPolicy(decision="early", earliest_alert_step=1, min_confidence_by_steps=(0.6,) * 5 + (-1.0,),
                event_hold_s=15.0),
], ids=["early_defaults", "long_events", "full_window", "eager"])
def test_batched_replay_decides_what_the_live_path_decides(policy):
    rng, segments = _drive(seed=3, minutes=15)
    live = _decisions(WearableLoop(HashModel(), policy=policy), segments, block_sizes=(1,), rng=rng)
    whole = _decisions(WearableLoop(BatchedHashModel(), policy=policy), segments)
    blocks = _decisions(WearableLoop(BatchedHashModel(), policy=policy), segments, (1, 7, 300, 2500, 9000), rng)
    statuses = {d["status"] for d in live}
    assert len(live) > 50 and "continued" in statuses and len(statuses) >= 4  # events open, continue and end
    assert whole == live and blocks == live
