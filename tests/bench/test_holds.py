"""bench.holds: the issue-16 "what already holds" measurements, each small, in simulated time
(the figures are stream or simulated time, never wall-clock: a loaded machine cannot move them)."""
from __future__ import annotations

import numpy as np
import pytest

from bench import holds


@pytest.mark.parametrize("kind", ["can", "mavlink"])
def test_the_arm_stops_200_to_220_ms_after_its_link_or_pose_stream_is_lost(kind):
    rng = np.random.default_rng(3)
    link = holds.arm_stop_trial(kind, "link", rng)
    assert link["stopped"] and link["watchdog"] and link["speed_at_loss_mps"] > 0
    assert 200 <= link["stop_ms"] <= 220 and link["rest_ms"] > link["stop_ms"]
    assert link["stop_after_loss_ms"] <= link["stop_ms"]  # the last frame went out before the cut
    pose = holds.arm_stop_trial(kind, "pose", rng)
    assert pose["stopped"] and not pose["watchdog"]  # the runtime's own stop, not the arm's watchdog
    assert 200 <= pose["stop_ms"] <= 220


def test_no_unsigned_forged_or_replayed_command_is_executed_and_a_signed_one_is():
    r = holds.forged(30, seed=1)
    assert r["accepted"] == 0 and r["state_unchanged"]
    assert r["refused_and_counted"] == r["by_kind"] == {"unsigned": 10, "forged": 10, "replayed": 10}
    assert r["control_signed_with_the_arm_key"] == {"accepted": 1, "light": "red"}


def test_every_tampered_model_is_refused_and_the_untouched_copy_loads():
    from edge_runtime.core.manifest import ASSETS_DIR, load_manifest

    r = holds.tampered()
    cases = 3 * len(load_manifest(ASSETS_DIR)["models"])  # every shipped model (step models too), three ways
    assert r["cases"] == cases and r["refused"] == cases and r["untouched_copy_loads"]
    assert {row["tampering"] for row in r["rows"]} == {"one byte flipped", "truncated to half",
                                                       "swapped for another shipped model"}
    assert r["model_and_hash_replaced"].startswith("LOADED")  # what only a signature could refuse
    pytest.importorskip("cryptography")
    assert r["model_and_hash_replaced_on_a_box_with_a_public_key"].startswith("refused: the manifest's signature")


def test_memory_is_sampled_every_period_of_stream_time():
    r = holds.wearable_memory(0.1, seed=5, drive_minutes=3, every_h=0.025)
    assert [s["hour"] for s in r["samples"]] == [0.03, 0.05, 0.07, 0.1]  # 0.025 h steps, rounded
    assert r["decisions"] > 0 and r["growth"]["from_hour"] == 0.03 and r["growth"]["to_hour"] == 0.1
    assert all(s["rss_mb"] > 0 and s["objects"] > 0 for s in r["samples"])
