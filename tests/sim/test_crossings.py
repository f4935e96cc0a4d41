"""firmware_sim crossings: the tracker's ids through people crossing, and how they are counted."""
import numpy as np

from firmware_sim.scenarios.crossings import crossing, score


def test_people_crossing_the_other_way_keep_their_ids():
    results = [crossing(np.random.default_rng(s)) for s in range(6)]
    res = score(results)
    opposite = res["opposite_only"]
    assert opposite["crossings"] >= 1 and opposite["right_id_kept"] == opposite["people"]
    assert res["people"] == sum(int((r["ids"] >= 0).any(axis=1).sum()) for r in results)


def test_a_swap_is_counted():
    ids = np.array([[0, 0, 1, 1], [1, 1, 0, 0]])
    res = score([{"ids": ids, "people": 2, "overtaking": False}])
    assert res["right_id_kept"] == 0 and res["id_switches"] == 2 and res["never_mixed_fraction"] == 0
    kept = score([{"ids": np.array([[0, -1, 0], [1, 1, 1]]), "people": 2, "overtaking": False}])
    assert kept["right_id_kept_fraction"] == 1.0 and kept["never_mixed_fraction"] == 1.0
