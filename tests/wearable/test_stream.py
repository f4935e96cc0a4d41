"""The streaming step model in the runtime (issues 12 and 15): one run per sub-window, the LSTM state kept
per capture. Its fp32 decisions are the one-shot fp32 model's on the same sub-windows; a capture's state is
its own; the live loop (one sample at a time, a step as each sub-window arrives) decides what the replay's
batched steps decide; a bad or missing step entry is one line naming the file and field."""
import argparse
import hashlib
import json
import shutil
import subprocess
import sys

import numpy as np
import onnx
import pytest
from onnx import TensorProto, helper, numpy_helper
from support import REPO_ROOT
from support.drive import drive_captures

from edge_runtime.core.manifest import ASSETS_DIR, STEP_ARCH, ManifestError, ModelIntegrityError, load_manifest
from edge_runtime.wearable import classifier, command
from edge_runtime.wearable.classifier import (
    STEP_OUTPUTS,
    Engine,
    StepModel,
    bound_step,
    fast_run,
    needed_frames,
    preprocess,
    step_inputs,
)
from edge_runtime.wearable.loop import AlertPolicy, WearableLoop
from edge_runtime.wearable.sources import SAMPLE_RATE_HZ, ImuBlock


@pytest.fixture(scope="module")
def captures():
    return drive_captures()


def test_every_shipped_classifier_entry_names_a_step_model_of_its_precision():
    """The tests below run on the shipped step models: their absence is a failure here, never a silent skip."""
    models = {e["name"]: e for e in load_manifest(ASSETS_DIR)["models"]}
    convlstm = [e for e in models.values() if e["arch"] == "convlstm"]
    assert {e["precision"] for e in convlstm} == {"fp32", "int8"}
    for e in convlstm:
        step = models[e["step_model"]]
        assert step["arch"] == STEP_ARCH and step["precision"] == e["precision"]
        assert step["model_version"] == e["model_version"] and step["classes"] == e["classes"]


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


def test_advance_refuses_too_few_frames_or_another_capture_before_touching_the_state(captures):
    eng = Engine.from_manifest(ASSETS_DIR, "int8")
    a, b = captures[0], captures[1]
    st = eng.new_stream()
    with pytest.raises(ValueError, match="needs 263..700 frames") as e:
        eng.advance(st, a[:needed_frames(2) - 1], 2)
    assert "\n" not in str(e.value) and st.done == 0 and not st.h.any() and not st.probs
    eng.advance(st, a[:needed_frames(2)], 2)
    h = st.h.copy()
    with pytest.raises(ValueError, match="not the capture"):
        eng.advance(st, b[:needed_frames(3)], 3)
    assert st.done == 2 and np.array_equal(st.h, h)
    np.testing.assert_array_equal(eng.advance(st, a[:needed_frames(3)], 3), eng.classify_prefix(a[:needed_frames(3)], 3))


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


class _Wrapped:
    """A real session whose private ``_sess`` is missing (``inner`` None) or an object whose ``run`` is ``inner``;
    every public call goes to the real session."""

    def __init__(self, session, inner=None):
        self._real = session
        if inner is not None:
            self._sess = _Inner(inner)

    def __getattr__(self, name):
        if name == "_sess":
            raise AttributeError(name)
        return getattr(self._real, name)


@pytest.mark.parametrize("private", ["missing", "raises"])
def test_a_step_model_on_an_onnxruntime_whose_private_run_is_missing_or_raises_gives_the_same_results(
        captures, monkeypatch, private):
    """Built as the box builds it (``from_manifest``), on sessions without ``_sess`` or whose ``_sess.run`` raises
    (any exception): the load-time probe falls back to the public ``run``, with the same results bit for bit."""
    shipped = Engine.from_manifest(ASSETS_DIR, "int8")

    def broken(*args):
        raise RuntimeError("a changed private API")

    real_open = classifier.open_session
    monkeypatch.setattr(classifier, "open_session", lambda *a, **k: _Wrapped(real_open(*a, **k),
                                                                             None if private == "missing" else broken))
    eng = Engine.from_manifest(ASSETS_DIR, "int8")
    model = eng.step_model
    assert model._run == model.session._real.run and not model.bound
    subs = step_inputs(captures[:6], 6)
    for got, want in zip(model.run(subs), shipped.step_model.run(subs)):  # a batch
        np.testing.assert_array_equal(got, want)
    for k in range(3):  # one capture at a time: the loop's call
        st, ref = eng.new_stream(), shipped.new_stream()
        np.testing.assert_array_equal(eng.advance(st, captures[k], 6), shipped.advance(ref, captures[k], 6))


def _public_chain(model, subs):
    """(probs, h, c) after each sub-window of one capture by the public ``session.run`` from the zero state."""
    h, c = model.zero_state(1)
    out = []
    for x in subs:
        p, h, c = model.session.run(list(STEP_OUTPUTS), {"imu": x, "h": h, "c": c})
        out.append((p, h, c))
    return out


@pytest.mark.parametrize("precision", ["fp32", "int8"])
def test_a_capture_state_kept_in_the_bound_buffers_is_the_public_runs_however_captures_interleave(captures, precision):
    """The loop's call keeps a capture's state in onnxruntime's buffers between its steps; another capture's step,
    or reading the state, gives it back first: every decision and state is the public ``session.run``'s."""
    model = Engine.from_manifest(ASSETS_DIR, precision).step_model
    assert model.call_path == "iobinding, state kept bound"
    subs = [[np.ascontiguousarray(x[k:k + 1]) for x in step_inputs(captures[:3], 6)] for k in range(3)]
    want = [_public_chain(model, s) for s in subs]
    streams = [classifier.StepStream(*model.zero_state(1)) for _ in range(3)]
    for k, s in [(0, 0), (0, 1), (1, 0), (0, 2), (2, 0), (2, 1), (1, 1), (1, 2), (0, 3), (0, 4), (0, 5), (2, 2)]:
        np.testing.assert_array_equal(model.step_stream(subs[k][s], streams[k]), want[k][s][0])
        if (k, s) == (0, 4):  # read mid-capture: its state, and the next step still the public one's
            np.testing.assert_array_equal(streams[0].h, want[0][4][1])
    for st, (k, s) in zip(streams, [(0, 5), (1, 2), (2, 2)]):
        np.testing.assert_array_equal(st.h, want[k][s][1])
        np.testing.assert_array_equal(st.c, want[k][s][2])


@pytest.mark.parametrize("how", ["copy", "deepcopy"])
def test_a_copy_of_a_resident_stream_is_its_own_and_leaves_the_original_its_state(captures, how):
    """A copy of the stream whose state is in the bound buffers takes the state back first: a shallow copy used to
    share the buffers' claim, so once the copy was read and another capture stepped, the original read that
    capture's state as its own."""
    import copy

    model = Engine.from_manifest(ASSETS_DIR, "int8").step_model
    subs = [[np.ascontiguousarray(x[k:k + 1]) for x in step_inputs(captures[:2], 2)] for k in range(2)]
    want = _public_chain(model, subs[0])
    a, b = (classifier.StepStream(*model.zero_state(1)) for _ in range(2))
    model.step_stream(subs[0][0], a)
    model.step_stream(subs[0][1], a)  # a's state now lives in the buffers
    twin = getattr(copy, how)(a)
    np.testing.assert_array_equal(twin.h, want[1][1])
    model.step_stream(subs[1][0], b)  # another capture's state goes into the buffers
    np.testing.assert_array_equal(a.h, want[1][1])
    np.testing.assert_array_equal(a.c, want[1][2])


def test_a_kept_state_call_that_does_not_give_the_public_results_is_not_used(captures, monkeypatch):
    """The load-time check refuses a state-keeping call whose decisions or states differ from ``session.run``'s
    (here: the state it hands back is off by one float32 step); the capture's steps then copy the state each time."""
    real = classifier.chained_step

    def off(*args):
        call = real(*args)

        def wrong(x, stream):
            p = call(x, stream)
            stream.h = np.nextafter(stream.h, np.float32(np.inf))
            return p

        return wrong

    monkeypatch.setattr(classifier, "chained_step", off)
    eng = Engine.from_manifest(ASSETS_DIR, "int8")
    assert eng.step_model.call_path == "iobinding"
    monkeypatch.undo()
    shipped = Engine.from_manifest(ASSETS_DIR, "int8")
    for k in range(3):
        st, ref = eng.new_stream(), shipped.new_stream()
        np.testing.assert_array_equal(eng.advance(st, captures[k], 6), shipped.advance(ref, captures[k], 6))


class StepSpy:
    """Counts the step model's runs per feed (each capture's step, batch or one: StepModel.step, and
    StepModel.step_stream, the loop's call, once however it reaches onnxruntime)."""

    def __init__(self, monkeypatch):
        self.calls = 0
        self._inner = False
        real, real_stream = StepModel.step, StepModel.step_stream

        def step(model, x, h, c):
            self.calls += not self._inner
            return real(model, x, h, c)

        def step_stream(model, x, stream):
            self.calls += 1
            self._inner = True
            try:
                return real_stream(model, x, stream)
            finally:
                self._inner = False

        monkeypatch.setattr(StepModel, "step", step)
        monkeypatch.setattr(StepModel, "step_stream", step_stream)


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


@pytest.fixture(scope="module")
def drive_acc():
    from firmware_sim.devices.wrist import simulate_drive

    return np.ascontiguousarray(simulate_drive(4.0, seed=3).acc_mps2, dtype=np.float32)


def _steps_per_feed(loop, acc, block, spy):
    per_feed = []
    for i in range(0, len(acc), block):
        spy.calls = 0
        loop.feed(ImuBlock(i / SAMPLE_RATE_HZ, acc[i:i + block], continuous=i > 0))
        per_feed.append(spy.calls)
    return per_feed


@pytest.mark.parametrize("decision", ["early", "full_window"])
@pytest.mark.parametrize("block", [1, 5])
def test_every_feed_runs_only_the_steps_of_the_sub_windows_it_completed(drive_acc, monkeypatch, decision, block):
    """A decision costs one step whatever the policy: the loop runs a capture's step as each of its sub-windows
    arrives (in full_window mode too, and for a capture that only continues an event), never several at once
    when a capture completes. A feed of 1 or 5 samples completes at most one sub-window (they are >= 90 frames
    apart, and a capture starts after the one before it ends), so it runs at most one step."""
    spy = StepSpy(monkeypatch)
    streams = Spy()
    loop = WearableLoop(streams, policy=AlertPolicy(decision=decision))
    per_feed = _steps_per_feed(loop, drive_acc, block, spy)
    assert max(per_feed) == 1 and sum(per_feed) == sum(s.done for s in streams.streams)
    assert len(streams.streams) >= 5 and all(s.done == 6 for s in streams.streams[:-1])
    assert loop.stats.statuses["continued"] >= 1  # the captures that only continue an event are stepped too


def test_a_replay_runs_each_sub_window_of_a_capture_once(drive_acc, monkeypatch):
    """A block's captures go through the step model together: their early decisions read the states the full
    windows' steps pass through, so no sub-window of any capture is run twice (before: once more for the early
    steps of every capture that could open an event)."""
    # its load-time probes ...
    loop = WearableLoop(Engine.from_manifest(ASSETS_DIR, "int8"), policy=AlertPolicy(decision="early"))
    rows = []  # ... are not counted: the rows each step run of the replay carries
    real = StepModel.step
    monkeypatch.setattr(StepModel, "step", lambda model, x, h, c: rows.append(len(x)) or real(model, x, h, c))
    decided = _feed(loop, drive_acc, len(drive_acc))
    assert loop.stats.captures >= 5 and any(d["steps"] < 6 for d in decided)  # early decisions were made
    assert sum(rows) == 6 * loop.stats.captures


@pytest.mark.parametrize("stream", [True, False])
def test_the_live_loop_decides_what_the_batched_replay_decides(drive_acc, monkeypatch, stream):
    """One sample at a time, the loop opens a stream per capture and runs a step as each sub-window arrives
    (``stream = false``: the whole model on each prefix); the replay (whole blocks) batches every capture's
    steps instead: the same decisions."""
    spy = StepSpy(monkeypatch)
    eng = Spy() if stream else Engine.from_manifest(ASSETS_DIR, "int8", stream=False)
    early = AlertPolicy(decision="early")
    live_loop = WearableLoop(eng, policy=early)
    per_feed = _steps_per_feed(live_loop, drive_acc, 1, spy)
    live_loop = WearableLoop(eng, policy=early)
    live = _feed(live_loop, drive_acc, 1)
    replay = _feed(WearableLoop(Engine.from_manifest(ASSETS_DIR, "int8", stream=stream), policy=early),
                   drive_acc, len(drive_acc))
    assert len(live) > 5 and live == replay
    if stream:
        assert max(per_feed) == 1  # the live loop's steps are never bunched
        assert len({id(s) for s in eng.streams}) == len(eng.streams)  # one state per capture
    else:
        assert sum(per_feed) == 0  # no step model runs


def test_model_stream_reaches_the_engine_through_the_command(tmp_path):
    """``[model] stream`` of the box config decides the engine the wearable command loads (the capture path's)."""
    p = argparse.ArgumentParser()
    command.add_arguments(p)
    engines = {}
    for stream in ("true", "false"):
        box = tmp_path / f"box_{stream}.toml"
        box.write_text(f'[alerts]\ndecision = "early"\n[model]\nstream = {stream}\n')
        engines[stream] = command._load_classifier(command.effective_config(
            p.parse_args(["--replay", "x.csv", "--config", str(box)])))
    assert engines["true"].streaming and not engines["false"].streaming


def _assets_with(tmp_path, change):
    d = tmp_path / "assets"
    shutil.copytree(ASSETS_DIR, d)
    m = json.loads((d / "manifest.json").read_text())
    change(m, d)
    (d / "manifest.json").write_text(json.dumps(m))
    return d


def _entry(m, name):
    return next(e for e in m["models"] if e["name"] == name)


def _toy_step_graph(hidden: int, c_hidden: int | None = None) -> bytes:
    """A graph with the step model's contract (imu (N, 33, 3), h, c (N, hidden) in; probs (N, 6), h_out, c_out
    out) that decides by the sub-window's mean alone: a step model that is not the shipped model's (with
    ``c_hidden``, a c state of another size than h's)."""
    c_hidden = hidden if c_hidden is None else c_hidden
    w = numpy_helper.from_array(np.random.default_rng(1).normal(0.0, 1.0, (3, 6)).astype(np.float32), "w")
    nodes = [helper.make_node("ReduceMean", ["imu"], ["m"], axes=[1], keepdims=0),
             helper.make_node("MatMul", ["m", "w"], ["z"]), helper.make_node("Softmax", ["z"], ["probs"], axis=1),
             helper.make_node("Identity", ["h"], ["h_out"]), helper.make_node("Identity", ["c"], ["c_out"])]
    t = lambda name, *dims: helper.make_tensor_value_info(name, TensorProto.FLOAT, ["N", *dims])  # noqa: E731
    graph = helper.make_graph(nodes, "toy_step", [t("imu", 33, 3), t("h", hidden), t("c", c_hidden)],
                              [t("probs", 6), t("h_out", hidden), t("c_out", c_hidden)], [w])
    model = helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)])
    onnx.checker.check_model(model)
    return model.SerializeToString()


def _step_file(hidden: int, c_hidden: int | None = None):
    """Replace the int8 step model's file (and its manifest hash and size) with a toy graph of state ``hidden``."""
    def change(m, d):
        data = _toy_step_graph(hidden, c_hidden)
        (d / "convlstm_step.int8.onnx").write_bytes(data)
        _entry(m, "convlstm-step-int8").update(sha256=hashlib.sha256(data).hexdigest(), size_bytes=len(data))
    return change


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
    (lambda m, d: _entry(m, "convlstm-int8").update(step_model="convlstm-fp32"), ManifestError,
     ("field 'step_model' of 'convlstm-int8'", "convlstm-fp32", "not a convlstm_step")),
    (lambda m, d: _entry(m, "convlstm-int8").update(step_model="convlstm-step-fp32"), ModelIntegrityError,
     ("field 'step_model' of 'convlstm-int8'", "precision")),
    (lambda m, d: _entry(m, "convlstm-step-int8").update(model_version="9.9.9+other"), ModelIntegrityError,
     ("field 'step_model' of 'convlstm-int8'", "model_version", "9.9.9+other")),
    (_step_file(64), ModelIntegrityError, ("convlstm_step.int8.onnx", "state size 64", "100")),
    (_step_file(100), ModelIntegrityError, ("convlstm_step.int8.onnx", "fixed probe", "not the step model")),
    (_step_file(100, 64), ModelIntegrityError, ("convlstm_step.int8.onnx", "c_out", "expected all (N, 100)")),
], ids=["unknown name", "not a string", "entry missing", "file tampered", "other classes", "names a one-shot entry",
        "other precision", "other model_version", "other state size", "another model, right hash",
        "c of another size than h"])
def test_a_bad_or_missing_step_entry_is_refused_in_one_line(tmp_path, change, error, words):
    d = _assets_with(tmp_path, change)
    with pytest.raises(error) as e:
        Engine.from_manifest(d, "int8")
    assert "\n" not in str(e.value) and all(w in str(e.value) for w in words)


@pytest.mark.slow
@pytest.mark.parametrize("change", [lambda m, d: (d / "convlstm_step.int8.onnx").unlink(), _step_file(100)],
                         ids=["missing", "another model, right hash"])
def test_the_wearable_command_refuses_a_missing_or_foreign_step_model_in_one_line(tmp_path, change):
    d = _assets_with(tmp_path, change)
    csv = tmp_path / "rec.csv"
    csv.write_text("t,ax,ay,az\n" + "\n".join(f"{i / 100:.2f},0.0,0.0,9.81" for i in range(300)) + "\n")
    r = subprocess.run([sys.executable, "-m", "edge_runtime", "wearable", "--replay", str(csv), "--assets", str(d),
                        "--decision", "early"], capture_output=True, text=True, cwd=REPO_ROOT, timeout=120)
    err = r.stderr.strip()
    assert r.returncode == 2 and "Traceback" not in err and len(err.splitlines()) == 1
    assert "convlstm_step.int8.onnx" in err
