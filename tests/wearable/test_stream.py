"""The streaming step model in the runtime (issues 12 and 15): one run per sub-window, the LSTM state kept
per capture. Its fp32 decisions are the one-shot fp32 model's on the same sub-windows; a capture's state is
its own; the live loop (one sample at a time, a step as each sub-window arrives) decides what the replay's
batched steps decide; a bad or missing step entry is one line naming the file and field."""
import json
import shutil
import subprocess
import sys

import numpy as np
import pytest
from support import REPO_ROOT
from support.drive import drive_captures

from edge_runtime.core.manifest import ASSETS_DIR, ManifestError, ModelIntegrityError, load_manifest
from edge_runtime.wearable.classifier import (
    STEP_OUTPUTS,
    Engine,
    bound_step,
    fast_run,
    needed_frames,
    preprocess,
    step_inputs,
)
from edge_runtime.wearable.loop import AlertPolicy, WearableLoop
from edge_runtime.wearable.sources import SAMPLE_RATE_HZ, ImuBlock

pytestmark = pytest.mark.skipif(not any(e["arch"] == "convlstm_step" for e in load_manifest(ASSETS_DIR)["models"]),
                                reason="no shipped step model")


@pytest.fixture(scope="module")
def captures():
    return drive_captures()


@pytest.mark.parametrize("precision", ["fp32", "int8"])
def test_the_engine_decides_by_the_step_model_of_its_precision(precision):
    eng = Engine.from_manifest(ASSETS_DIR, precision)
    assert eng.streaming and eng.step_model.source.endswith(f"convlstm_step.{precision}.onnx")
    assert not Engine.from_manifest(ASSETS_DIR, precision, stream=False).streaming


def test_fp32_steps_give_the_one_shot_fp32_decision_after_every_s(captures):
    """The conv stack reads each sub-window alone and the LSTM is causal: S steps from the zero state are the
    whole model on the first S sub-windows, to float tolerance."""
    step = Engine.from_manifest(ASSETS_DIR, "fp32")
    one_shot = Engine.from_manifest(ASSETS_DIR, "fp32", stream=False)
    x = preprocess(captures)
    probs = step.step_model.run([x[:, s] for s in range(6)])
    for s in range(1, 7):
        np.testing.assert_allclose(probs[s - 1], one_shot.classify(np.ascontiguousarray(x[:, :s])), atol=2e-6)


def test_a_sub_window_is_read_as_it_arrived(captures):
    """Sub-window s comes from the first needed_frames(s) frames alone (later frames change nothing), and
    from sub-window 2 on it is the whole capture's preprocessing; sub-window 1's first frames carry the
    mean known when it arrived."""
    subs = step_inputs(captures[:8], 6)
    full = preprocess(captures[:8])
    for s in range(1, 7):
        later = captures[:8].copy()
        later[:, needed_frames(s):] += 5.0  # what comes after sub-window s arrived
        np.testing.assert_array_equal(step_inputs(later, s)[s - 1], subs[s - 1])
        if s > 1:
            np.testing.assert_allclose(subs[s - 1], full[:, s - 1], atol=1e-3)


@pytest.mark.parametrize("precision", ["fp32", "int8"])
def test_advancing_a_capture_gives_its_prefix_decisions_and_two_captures_keep_their_own_state(captures, precision):
    eng = Engine.from_manifest(ASSETS_DIR, precision)
    a, b = captures[0], captures[1]
    sa, sb = eng.new_stream(), eng.new_stream()
    for s in range(1, 7):  # interleaved: a step of one capture never moves the other's state
        pa = eng.advance(sa, a[:needed_frames(s)], s)
        pb = eng.advance(sb, b[:needed_frames(s)], s)
        np.testing.assert_array_equal(pa, eng.classify_prefix(a[:needed_frames(s)], s))
        np.testing.assert_array_equal(pb, eng.classify_prefix(b[:needed_frames(s)], s))
    assert sa.done == sb.done == 6 and not np.array_equal(sa.h, sb.h)
    jump = eng.new_stream()  # a decision after S = 4 runs the steps it has not yet run, once each
    np.testing.assert_array_equal(eng.advance(jump, a, 4), eng.classify_prefix(a[:needed_frames(4)], 4))
    assert jump.done == 4 and sorted(jump.probs) == [1, 2, 3, 4]


class _PublicOnly:
    """A session as an onnxruntime without the private ``_sess`` would give it: only the public calls."""

    def __init__(self, session):
        self.run = session.run
        self.io_binding = session.io_binding


class _Inner:
    def __init__(self, run):
        self.run = run


class _ChangedPrivate(_PublicOnly):
    """A session whose private run takes other arguments, or gives other results, than this code expects."""

    def __init__(self, session, inner):
        super().__init__(session)
        self._sess = _Inner(inner)


@pytest.mark.parametrize("precision", ["fp32", "int8"])
def test_the_step_call_takes_a_private_path_only_when_it_gives_what_the_public_run_gives(captures, precision):
    """StepModel.step runs a single capture through an IOBinding and a batch through ``_sess.run`` when this
    onnxruntime has them and they agree with ``session.run``; otherwise (another onnxruntime) the public run,
    with the same results, bit for bit."""
    model = Engine.from_manifest(ASSETS_DIR, precision).step_model
    session = model.session
    subs = [np.ascontiguousarray(x) for x in step_inputs(captures[:4], 6)]
    if hasattr(session, "_sess"):
        assert model._run == session._sess.run and model._step_one is not None
    fast = [model.run([x[k:k + 1] for x in subs]) for k in range(4)] + [model.run(subs)]
    h, c = model.zero_state(4)
    feed = {"imu": subs[0], "h": h, "c": c}
    public = _PublicOnly(session)
    assert fast_run(public, STEP_OUTPUTS, feed, model._run_options) == session.run
    assert bound_step(public, {k: v[:1] for k, v in feed.items()}, ((1, 6), (1, 100), (1, 100)),
                      model._run_options) is None

    def other_signature(feed, outputs):
        raise TypeError("incompatible function arguments")

    def other_results(outputs, feed, options):
        return [np.zeros_like(a) for a in session.run(outputs, feed, options)]

    for inner in (other_signature, other_results):
        assert fast_run(_ChangedPrivate(session, inner), STEP_OUTPUTS, feed, model._run_options) == session.run
    model._run, model._step_one = session.run, None  # what an onnxruntime without the private calls gets
    slow = [model.run([x[k:k + 1] for x in subs]) for k in range(4)] + [model.run(subs)]
    for a, b in zip(fast, slow):
        for pa, pb in zip(a, b):
            np.testing.assert_array_equal(pa, pb)


class Spy:
    """The shipped int8 engine, counting the steps each capture's stream runs."""

    def __init__(self):
        self.engine = Engine.from_manifest(ASSETS_DIR, "int8")
        self.streams = []

    def __getattr__(self, name):
        return getattr(self.engine, name)

    def new_stream(self):
        s = self.engine.new_stream()
        self.streams.append(s)
        return s

    def advance(self, stream, data, steps):
        assert data is not None and steps >= stream.done
        return self.engine.advance(stream, data, steps)


def _feed(loop, acc, block):
    out = []
    for i in range(0, len(acc), block):
        out += loop.feed(ImuBlock(i / SAMPLE_RATE_HZ, acc[i:i + block], continuous=i > 0))
    return [{k: v for k, v in d.to_json().items() if k not in ("compute_us", "latency_ms")} for d in out]


def test_the_live_loop_steps_each_capture_and_decides_what_the_batched_replay_decides():
    """One sample at a time, the loop opens a stream per capture and runs a step as each sub-window arrives;
    the replay (whole blocks) batches every capture's steps instead: the same decisions."""
    from firmware_sim.devices.wrist import simulate_drive

    acc = np.ascontiguousarray(simulate_drive(4.0, seed=3).acc_mps2, dtype=np.float32)
    spy = Spy()
    live = _feed(WearableLoop(spy, policy=AlertPolicy()), acc, 1)
    replay = _feed(WearableLoop(Engine.from_manifest(ASSETS_DIR, "int8"), policy=AlertPolicy()), acc, len(acc))
    assert len(live) > 5 and live == replay
    assert len(spy.streams) >= 5 and len({id(s) for s in spy.streams}) == len(spy.streams)  # one per capture
    assert all(s.done == 6 for s in spy.streams[:-1])  # every decided capture ran its 6 steps once


def _assets_with(tmp_path, change):
    d = tmp_path / "assets"
    shutil.copytree(ASSETS_DIR, d)
    m = json.loads((d / "manifest.json").read_text())
    change(m, d)
    (d / "manifest.json").write_text(json.dumps(m))
    return d


def _entry(m, name):
    return next(e for e in m["models"] if e["name"] == name)


@pytest.mark.parametrize("change, error, words", [
    (lambda m, d: _entry(m, "convlstm-int8").update(step_model="convlstm-step-int9"), ManifestError,
     ("convlstm-step-int9",)),
    (lambda m, d: _entry(m, "convlstm-int8").update(step_model=7), ManifestError, ("step_model",)),
    (lambda m, d: m.update(models=[e for e in m["models"] if e["name"] != "convlstm-step-int8"]), ManifestError,
     ("convlstm-step-int8",)),
    (lambda m, d: (d / "convlstm_step.int8.onnx").write_bytes(b"\0" * 64), ModelIntegrityError,
     ("convlstm_step.int8.onnx", "sha256")),
    (lambda m, d: _entry(m, "convlstm-step-int8").update(classes=["Phone", "Other"]), ModelIntegrityError,
     ("classes",)),
], ids=["unknown name", "not a string", "entry missing", "file tampered", "other classes"])
def test_a_bad_or_missing_step_entry_is_refused_in_one_line(tmp_path, change, error, words):
    d = _assets_with(tmp_path, change)
    with pytest.raises(error) as e:
        Engine.from_manifest(d, "int8")
    assert "\n" not in str(e.value) and all(w in str(e.value) for w in words)


@pytest.mark.slow
def test_the_wearable_command_refuses_a_missing_step_model_in_one_line(tmp_path):
    d = _assets_with(tmp_path, lambda m, d: (d / "convlstm_step.int8.onnx").unlink())
    csv = tmp_path / "rec.csv"
    csv.write_text("t,ax,ay,az\n" + "\n".join(f"{i / 100:.2f},0.0,0.0,9.81" for i in range(300)) + "\n")
    r = subprocess.run([sys.executable, "-m", "edge_runtime", "wearable", "--replay", str(csv), "--assets", str(d)],
                       capture_output=True, text=True, cwd=REPO_ROOT, timeout=120)
    err = r.stderr.strip()
    assert r.returncode == 2 and "Traceback" not in err and len(err.splitlines()) == 1
    assert "convlstm_step.int8.onnx" in err
