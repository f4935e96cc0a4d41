"""Session 23 (perf23): the robot frame's cheaper forms pinned to the forms they replaced, to the bit, on random
inputs: the COCO -> H36M sums without einsum, the head fit's window rows and the loop's small helpers. The
tracker's, sizes', following's and the lifter's shortcuts for the usual frame (every keypoint finite and scored 1,
every joint seen, as the bench's workers give them) are pinned with the earlier sessions' references, on clean
frames too (tests/robot/test_perception_batch_s18.py, tests/robot/test_tracking_fast.py)."""
from collections import deque
from types import SimpleNamespace

import numpy as np
import pytest

from edge_runtime.robot import hazard as hz
from edge_runtime.robot import keypoints as kpm
from edge_runtime.robot import loop as loopmod


def same(a, b):
    """Equal to the bit (NaN where NaN, the sign of zero too)."""
    a, b = np.asarray(a, np.float64), np.asarray(b, np.float64)
    return a.shape == b.shape and a.tobytes() == b.tobytes()


def test_weighted_sums_are_einsums():
    """numpy's einsum sums a row's products one after the other from +0.0; the few nonzero weights summed so
    are its sums to the bit (zeros of both signs, huge and tiny values, overflow, every batch shape)."""
    rng = np.random.default_rng(2301)
    tables = [(kpm.W_EARS, kpm._SOURCES_EARS), (kpm.W_EYES[kpm.HEAD:kpm.HEAD + 1], kpm._SOURCES_EYES_HEAD),
              (kpm.W_EYES, kpm._sources(kpm.W_EYES))]
    for case in range(6000):
        w, (_, sources, weights) = tables[case % 3]
        shape = [(17, 2), (1, 17, 2), (2, 17, 2), (5, 17, 2), (2, 3, 17, 2)][case % 5]
        f = rng.normal(0, 1, shape) * rng.choice([1e-310, 1e-3, 1.0, 1e3, 1e300]) + rng.choice([0.0, 640.0])
        if case % 3 == 0:
            f[rng.random(shape) < 0.3] = 0.0
        if case % 4 == 0:
            f[rng.random(shape) < 0.3] = -0.0
        with np.errstate(over="ignore", invalid="ignore"):
            assert same(kpm._weighted_sums(f, sources, weights), np.einsum("hc,...cd->...hd", w, f)), case


def fits(p: hz.TrackerParams, heads, times):
    """Each update's estimate of a tracker that fits from its window rows and of one that reads its deques."""
    rows, deques = hz.HeadTracker(p, 0.5), hz.HeadTracker(p, 0.5)
    deques._end = -1  # the rows given up: the fit reads the deques, as before session 23
    for t, head in zip(times, heads):
        yield rows.update(t, head), deques.update(t, head)


@pytest.mark.parametrize("window_s", [0.5, 3.0, 10.0])
def test_the_head_fit_from_rows_is_the_fit_from_the_deques(window_s):
    """The rows are written on, moved to the front and grown (a 10 s window holds 300 samples at 30 Hz) through
    resets, jumps, gaps and times that repeat: every estimate the same to the bit."""
    rng = np.random.default_rng(2303 + int(window_s))
    p = hz.TrackerParams(window_s=window_s, min_span_s=float(rng.choice([0.0, 0.3])))
    t, head, times, heads = 0.0, np.zeros(3), [], []
    for _ in range(1500):
        t += float(rng.choice([1 / 30] * 8 + [0.0, 0.2, window_s + 0.1]))
        head = head + rng.normal(0, rng.choice([0.005, 0.02, 2.0], p=[0.8, 0.15, 0.05]), 3)
        times.append(t)
        heads.append(head.copy())
    n = 0
    for a, b in fits(p, heads, times):
        n += 1
        for f in ("position_m", "velocity_mps", "predicted_m"):
            assert same(getattr(a, f), getattr(b, f)), (n, f)
    assert n == 1500


def test_a_head_of_another_shape_gives_up_the_rows():
    """A head that is not 3 numbers (only a first one gets past the jump test's arithmetic) leaves the fit to
    the deques, as before the rows."""
    tracker = hz.HeadTracker(hz.TrackerParams(min_span_s=0.0), 0.5)
    head = np.zeros((1, 3))
    est = tracker.update(0.0, head)
    assert tracker._end == -1 and est.position_m is tracker._x[-1]
    with pytest.raises(ValueError):
        tracker.update(1 / 30, np.zeros(3))  # the jump test's dot refuses the shapes, as before


def test_the_loops_small_helpers_are_numpys():
    rng = np.random.default_rng(2309)
    edge = [0.0, -0.0, 1e-310, 1e300, np.inf, -np.inf, np.nan]
    for case in range(3000):
        v = rng.normal(0, rng.choice([1e-3, 1.0, 1e3]), 3)
        if case % 3 == 0:
            v[rng.random(3) < 0.4] = rng.choice(edge)
        with np.errstate(over="ignore", invalid="ignore"):
            assert same(loopmod._norm3(v), np.linalg.norm(v)), case
        arrays = [rng.normal(size=(17, 3)) for _ in range(int(rng.integers(1, 4)))]
        assert same(loopmod._stacked(arrays), np.stack(arrays))
    with pytest.raises(ValueError):
        loopmod._stacked([np.zeros((17, 3)), np.zeros((16, 3))])
    for sizes in ([25], [25, 25], [25, 31, 4]):
        people = [(np.zeros((n, 3)), np.zeros(n)) for n in sizes]
        assert np.array_equal(hz._gathered(people)[2], np.cumsum([0] + sizes[:-1]))


def test_the_retraction_starts_capsules_are_kept():
    """However many arm states go through arm_capsules' small memory, the backfire check measures from the same
    capsules of where the retraction began (so its remembered separations hold), of the same numbers."""
    loop = SimpleNamespace(_q0_capsules=None)
    start = loopmod.RobotLoop._start_capsules
    q0 = np.array([0.1, -0.6, 0.0, 1.2, 0.0, 0.5, 0.0])
    caps = start(loop, q0)
    for k in range(40):
        hz.arm_capsules(q0 + 0.001 * (k + 1))
    assert start(loop, q0) is caps
    fresh = hz.arm_capsules(q0.copy())
    assert fresh is not caps and all(same(a, b) for a, b in zip(fresh, caps))
    assert start(loop, q0.copy()) is not caps  # another retraction's start


def test_the_task_moves_are_made_once_per_waypoint():
    from edge_runtime.robot.loop import LoopParams, Motion, MotionKind

    p = LoopParams()
    loop = SimpleNamespace(params=p, _waypoint=0, _sent_motion=None, _last_effector=None, _task_motions={},
                           _task_motions_of=None)
    loop._task_target = lambda params: loopmod.RobotLoop._task_target(loop, params)
    for k, target in enumerate(p.task_waypoints_m):
        loop._waypoint = k
        got = loopmod.RobotLoop._task_motion(loop)
        assert got == Motion(MotionKind.MOVE, loopmod._vec3(target), p.task_pitch_rad, p.task_yaw_rad)
        assert loopmod.RobotLoop._task_motion(loop) is got
    # reached: the next waypoint's move
    loop._waypoint = 0
    loop._sent_motion = loopmod.RobotLoop._task_motion(loop)
    loop._last_effector = np.array(p.task_waypoints_m[0], float)
    nxt = loopmod.RobotLoop._task_motion(loop)
    assert loop._waypoint == 1 and nxt.position_m == loopmod._vec3(p.task_waypoints_m[1])


def test_the_head_rows_keep_no_stale_sample_after_a_reset():
    p = hz.TrackerParams(min_span_s=0.0, min_samples=2)
    tracker = hz.HeadTracker(p, 0.5)
    for k in range(70):  # past the first rows' end
        tracker.update(k / 30, np.array([0.01 * k, 0.0, 0.0]))
    tracker.update(70 / 30, np.array([5.0, 0.0, 0.0]))  # a jump: a new track
    est = tracker.update(71 / 30, np.array([5.01, 0.0, 0.0]))
    assert len(tracker._t) == 2 and tracker.resets == 1
    assert same(tracker._t_rows[tracker._end - 2:tracker._end], np.array(list(deque(tracker._t))))
    assert abs(est.velocity_mps[0] - 0.3) < 1e-6
