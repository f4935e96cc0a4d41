"""edge_runtime.core.onnx's private fast paths (fast_run): taken only where they give exactly what session.run gives."""
from __future__ import annotations

import numpy as np
import pytest

from edge_runtime.core.manifest import ASSETS_DIR
from edge_runtime.core.onnx import fast_run, same_arrays, session_from_manifest


@pytest.fixture(scope="module")
def lifter():
    session, _, _ = session_from_manifest(ASSETS_DIR, "int8", arch="lifter")
    return session, [o.name for o in session.get_outputs()]


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
