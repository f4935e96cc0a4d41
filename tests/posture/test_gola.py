"""GOLA-HRC: descent that converges, capped and decaying steps, clamping with a notice,
a pause when the worker leaves, parameters that name their key, and personalisation."""
import io
import json
import math
from dataclasses import replace

import numpy as np
import pytest

from edge_runtime.posture.cap import CapParams
from edge_runtime.posture.gola import GolaParamError, GolaParams, GolaSession


def run(session: GolaSession, f, noise=0.0, seed=0, limit=200):
    rng = np.random.default_rng(seed)
    for _ in range(limit):
        if session.done:
            break
        p = session.propose()
        session.observe(f(p.height_m, p.pitch_deg) + noise * rng.standard_normal())
    return session


def bowl(h, o, h0=1.25, o0=20.0, kh=3.0, ko=1.0):
    """A convex CAP landscape with its minimum 4 at (h0, o0)."""
    return 4.0 + kh * (h - h0) ** 2 + ko * math.radians(o - o0) ** 2


def test_descent_on_a_convex_function_converges_downhill():
    f = lambda h, o: bowl(h, o, kh=20.0, ko=5.0)  # noqa: E731 - steep enough for eps = 0.3 to matter
    s = run(GolaSession(), f)
    assert s.state == "converged"
    h, o = s.learnt
    # within the CAP tolerance Eq. 9 allows of the minimum (4), and far below the start
    assert f(h, o) - 4.0 < 2 * GolaParams().epsilon
    assert f(1.055, 0.0) - f(h, o) > 1.0
    assert abs(h - 1.25) < 0.15 and abs(o - 20.0) < 15.0


def test_steps_are_capped_by_sp_and_so():
    steep = lambda h, o: 4 + 40 * abs(h - 1.5) + 20 * abs(math.radians(o - 55))  # noqa: E731
    s = run(GolaSession(), steep)
    hist = s.history
    dh = np.abs(np.diff([r["height_m"] for r in hist]))
    do = np.abs(np.diff([r["pitch_deg"] for r in hist]))
    assert dh.max() <= 0.2 + 1e-9 and do.max() <= 30.0 + 1e-9
    assert dh.max() > 0.19 and do.max() > 29.0          # the caps were reached, so they did bind


def test_learning_rates_decay_by_d_alpha_each_iteration():
    params = GolaParams(d_alpha=0.8)
    s = run(GolaSession(params), bowl, limit=7)
    for r in s.history:
        assert r["lp"] == pytest.approx(1.1 * 0.8 ** r["iteration"])
        assert r["lo"] == pytest.approx(1.1 * 0.8 ** r["iteration"])


def test_descent_sign_moves_away_from_a_worse_cap():
    # after the first height probe (+0.15 m) makes CAP worse, the next height move goes down
    s = GolaSession()
    worse_up = lambda h, o: 5.0 + 4.0 * (h - 1.055) + 0.0 * o  # noqa: E731
    run(s, worse_up, limit=4)
    heights = [r["height_m"] for r in s.history]
    assert heights[1] > heights[0] and heights[3] < heights[1]


def test_proposal_beyond_the_safe_range_is_clamped_with_a_notice():
    params = GolaParams(p0_m=1.50, height_max_m=1.60)
    s = GolaSession(params)
    uphill = lambda h, o: 10.0 - 5.0 * h  # noqa: E731 - always better higher
    run(s, uphill, limit=6)
    assert max(r["height_m"] for r in s.history) == pytest.approx(1.60)
    assert s.clamps >= 1
    assert any("clamped" in r.get("notice", "") and "1.600" in r["notice"] for r in s.history)


def test_clamp_names_the_arms_reach():
    params = GolaParams(workpiece_z_m=1.0, reach_m=1.1, height_min_m=0.3, height_max_m=2.5)
    lo, hi = params.height_range_reachable()
    h, _, notice = params.clamp(hi + 0.3, 0.0)
    assert h == pytest.approx(hi) and "reach" in notice


def test_refused_move_goes_back_to_the_previous_pose():
    s = GolaSession()
    s.propose()
    s.observe(6.0)
    p = s.propose()
    held = s.refused("unreachable: no joint solution")
    assert (held.height_m, held.pitch_deg) == (1.055, 0.0) and p.height_m != 1.055
    assert s.refusals == 1 and s.propose() == held


def test_worker_leaving_pauses_the_session_without_learning():
    buf = io.StringIO()
    s = GolaSession(log=buf)
    steep = lambda h, o: bowl(h, o, kh=30.0, ko=10.0)  # noqa: E731 - does not converge in 3 cycles
    run(s, steep, limit=3)
    assert s.state == "running"
    p = s.propose()
    before = (s.iteration, s.rates, s.learnt)
    for _ in range(5):
        assert s.observe(None) == "paused"
        assert s.propose() == p                                  # the robot holds the pose
    assert s.observe(float("nan")) == "paused"
    assert (s.iteration, s.rates, s.learnt) == before
    assert s.pauses == 6
    assert s.observe(steep(p.height_m, p.pitch_deg)) in ("running", "converged")
    lines = [json.loads(x) for x in buf.getvalue().splitlines()]
    assert sum(r["event"] == "paused" for r in lines) == 6
    assert [r["iteration"] for r in lines if r["event"] == "iteration"] == [1, 2, 3, 4]


def test_session_log_has_one_line_per_iteration(tmp_path):
    log = tmp_path / "s.jsonl"
    s = run(GolaSession(log=log), lambda h, o: bowl(h, o, kh=20.0, ko=5.0))
    s.close()
    rows = [json.loads(x) for x in log.read_text().splitlines()]
    assert len(rows) == s.iteration
    assert {"iteration", "height_m", "pitch_deg", "cap", "lp", "lo", "state"} <= set(rows[0])
    assert rows[-1]["state"] == "converged"


@pytest.mark.parametrize("kw,key", [
    (dict(d_alpha=1.5), "d_alpha"), (dict(epsilon=0.0), "epsilon"), (dict(sp_m=-0.2), "sp_m"),
    (dict(height_min_m=1.7), "height_min_m"), (dict(p0_m=2.0), "p0_m"), (dict(lp0=float("nan")), "lp0"),
    (dict(max_iterations=1), "max_iterations"), (dict(pitch_min_deg=70.0), "pitch_min_deg"),
])
def test_impossible_params_name_the_key(kw, key):
    with pytest.raises(GolaParamError, match=rf"\[gola\] {key}:"):
        GolaParams(**kw)


def test_from_dict_refuses_unknown_keys():
    with pytest.raises(GolaParamError, match="d_alfa: unknown key"):
        GolaParams.from_dict({"d_alfa": 0.9})
    assert GolaParams.from_dict({"workpiece_z_m": 0.8}).workpiece_xz_m == (0.0, 0.8)
    with pytest.raises(GolaParamError, match=r"\[gola\] epsilon: must be a finite number"):
        GolaParams.from_dict({"epsilon": "0.3"})


class _OkArm:
    def move_to(self, position_m, pitch_rad, yaw_rad):
        return "ok"


def test_doubling_the_neck_weight_raises_the_end_effector_on_the_simulated_worker():
    from firmware_sim.people.worker import make_cohort
    from firmware_sim.scenarios.gola import run_gola

    still = dict(trunk_sd_deg=0.0, neck_sd_deg=0.0, shoulder_sd_deg=0.0, elbow_sd_deg=0.0, distance_sd_m=0.0)
    heights = {1.0: [], 2.0: []}
    for w in make_cohort(4, 3):
        w = replace(w, style=replace(w.style, **still))
        for nw in heights:
            s, _ = run_gola(w, _OkArm(), np.random.default_rng(0), cap_params=CapParams(neck_weight=nw))
            heights[nw].append(s.learnt[0])
    assert np.mean(heights[2.0]) > np.mean(heights[1.0]) + 0.03
