"""edge_runtime.core.onnx's private fast paths (bound_call, fast_run): taken only where they give exactly what session.run gives."""
from __future__ import annotations

import numpy as np
import pytest

from edge_runtime.core.manifest import ASSETS_DIR
from edge_runtime.core.onnx import bound_call, fast_run, same_arrays, session_from_manifest


@pytest.fixture(scope="module")
def lifter():
    session, _, _ = session_from_manifest(ASSETS_DIR, "int8", arch="lifter")
    return session, [o.name for o in session.get_outputs()]


def _windows(n: int, seed: int = 0) -> list[np.ndarray]:
    rng = np.random.default_rng(seed)
    return [rng.normal(0.0, 0.3, (1, 27, 17, 2)).astype(np.float32) for _ in range(n)]


class _PublicOnly:
    """A session of an onnxruntime without the private calls (or whose private calls changed)."""

    def __init__(self, session, inner=None):
        self._real = session
        if inner is not None:
            self._sess = inner

    def __getattr__(self, name):  # only what __init__ did not set: the public API
        if name == "_sess":
            raise AttributeError(name)
        return getattr(self._real, name)


def test_the_bound_call_gives_what_session_run_gives_bit_for_bit(lifter):
    session, outputs = lifter
    xs = _windows(20)
    call = bound_call(session, {"keypoints_2d": xs[0]}, outputs)
    assert call is not None
    for x in xs:
        got, want = call(x), session.run(outputs, {"keypoints_2d": x})
        assert len(got) == len(want) == 2
        for a, b in zip(got, want):
            np.testing.assert_array_equal(a, b)


def test_the_bound_call_returns_its_own_arrays(lifter):
    """The results are copies: the next call (which rewrites the bound buffers) leaves them as they were."""
    session, outputs = lifter
    x0, x1 = _windows(2, seed=1)
    call = bound_call(session, {"keypoints_2d": x0}, outputs)
    first = call(x0)
    kept = [a.copy() for a in first]
    call(x1)
    for a, b in zip(first, kept):
        np.testing.assert_array_equal(a, b)


def test_the_bound_call_refuses_what_session_run_refuses(lifter):
    """Another shape (which np.copyto would broadcast) or dtype (which it would cast) raises, as session.run does."""
    session, outputs = lifter
    (x,) = _windows(1)
    call = bound_call(session, {"keypoints_2d": x}, outputs)
    with pytest.raises(ValueError, match="shape"):
        call(x[:, :1])
    with pytest.raises(TypeError):
        call(x.astype(np.float64))
    with pytest.raises(ValueError):
        call(x, x)


def test_no_bound_call_without_the_private_run_or_when_it_differs(lifter):
    """An onnxruntime without the private run, or whose private run gives other results, gets None: the caller
    keeps session.run."""
    session, outputs = lifter
    (x,) = _windows(1)
    assert bound_call(_PublicOnly(session), {"keypoints_2d": x}, outputs) is None

    class Zeroing:
        """A private run that leaves the outputs as they were (zeros)."""

        def run_with_iobinding(self, binding, options):
            pass

    assert bound_call(_PublicOnly(session, Zeroing()), {"keypoints_2d": x}, outputs) is None


def test_fast_run_takes_the_private_run_only_where_it_gives_what_session_run_gives(lifter):
    """fast_run at any batch size: the compiled session's run when it agrees with session.run, else session.run."""
    session, outputs = lifter
    rng = np.random.default_rng(2)
    feed = {"keypoints_2d": rng.normal(0.0, 0.3, (3, 27, 17, 2)).astype(np.float32)}
    run = fast_run(session, outputs, feed, None)
    assert run == session._sess.run
    assert same_arrays(run(outputs, feed, None), session.run(outputs, feed))
    assert fast_run(_PublicOnly(session), outputs, feed, None) == session.run

    class Zeros:
        def run(self, outputs, feed, options):
            return [np.zeros_like(a) for a in session.run(outputs, feed, options)]

    assert fast_run(_PublicOnly(session, Zeros()), outputs, feed, None) == session.run
