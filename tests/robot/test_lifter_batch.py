"""The shipped lifters (int8 and fp32) batched: PeopleLifter sends every person's window of a frame in one
onnxruntime call (session 16), and each person's output must be the same to the bit as his own batch-1 call on
this CPU. Realistic windows: the bench's two simulated workers seen by the box's camera (bench.robot_scenario),
with a third person walking behind, joints hidden now and then and people coming and going."""
from dataclasses import replace
from types import SimpleNamespace

import numpy as np
import pytest
from support.lifter import onnx_calls

from bench.robot_cycle import _box, box_camera, lifter_entry
from bench.robot_scenario import prepare_workers
from edge_runtime.core.manifest import ASSETS_DIR, load_manifest
from edge_runtime.robot import lifter as lm
from edge_runtime.robot.lifter import PeopleLifter, StreamingLifter

pytestmark = pytest.mark.skipif(not (ASSETS_DIR / "manifest.json").exists(), reason="no shipped lifter")

SECONDS = 8.0


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """(camera, keypoint format, (T, 3, 17, 3) keypoints of three people, (T, 3) who is in the frame)."""
    camera, fmt = box_camera(_box())
    entry = lifter_entry(load_manifest(ASSETS_DIR)["models"])
    kp = np.load(prepare_workers(tmp_path_factory.mktemp("batch") / "w.npz", SECONDS, entry, 1, camera,
                                 fmt))["keypoints_px"]
    behind = kp[:, :1].copy()  # a third person: the first worker's motion, smaller and off to the side
    behind[..., :2] = behind[..., :2] * 0.6 + (0.3 * camera.width_px, 0.25 * camera.height_px)
    people = np.concatenate([kp, behind], axis=1)
    rng = np.random.default_rng(1610)
    t = np.arange(len(people))
    people[t % 23 < 2, 0, 9, 2] = 0.1  # a wrist hidden now and then
    people[(t > 60) & (t < 70), 1, 15, 2] = 0.0  # an ankle hidden for longer than the lifter holds it
    people[rng.random(len(people)) < 0.03, 2, :, 2] = 0.0  # a frame of nobody seen
    here = np.ones(people.shape[:2], bool)
    here[(t > 100) & (t < 112), 1] = False  # gone for a while (bridged)
    here[t < 40, 2] = False  # comes in later
    here[t > 200, 2] = False  # and leaves
    return camera, fmt, people, here


@pytest.mark.parametrize("precision", ["int8", "fp32"])
def test_batched_people_equal_their_batch_one_calls(scene, precision, monkeypatch):
    camera, fmt, people, here = scene
    params = replace(_box().lifter, precision=precision, threads=1)
    template = StreamingLifter.from_manifest(ASSETS_DIR, params, camera=camera, keypoint_format=fmt)
    batched, single = PeopleLifter(template), PeopleLifter(template)
    sizes = onnx_calls(batched.template, monkeypatch)  # before the sibling below takes the template's call: both lifters' calls are counted
    single.template = template.sibling()
    single.template._batches = False  # one call per person, on the same session
    windows = []
    for k in range(len(people)):
        frame = [SimpleNamespace(id=i, keypoints=people[k, i]) for i in np.flatnonzero(here[k])]
        got, want = batched.push(k / 30, frame), single.push(k / 30, frame)
        assert [i for i, _ in got] == [i for i, _ in want]
        for (pid, g), (_, w) in zip(got, want):
            assert (g.valid, g.reason, g.warming_up) == (w.valid, w.reason, w.warming_up), (k, pid)
            for name in ("joints_cam_m", "root_cam_m", "joints_model_cam_m", "observed", "held", "missing"):
                a, b = getattr(g, name), getattr(w, name)
                assert (a is None and b is None) or np.asarray(a).tobytes() == np.asarray(b).tobytes(), (k, pid, name)
            if g.valid:
                windows.append(batched.lifters[pid].window().copy())
    assert max(sizes) == 3 and sizes.count(2) > 10  # frames of three and of two people went in one call
    assert sum(sizes) == batched.stats.inferences
    # the windows straight through the session, in batches of every size up to 6, against batch 1
    session, outs = template.session, template._outputs
    w = np.stack(windows[::5])
    ref = [session.run(outs, {lm.INPUT_NAME: w[i:i + 1]}) for i in range(len(w))]
    for n in (2, 3, 4, 5, 6):
        for s in range(0, len(w) - n + 1, n):
            pose, root = session.run(outs, {lm.INPUT_NAME: w[s:s + n]})
            for i in range(n):
                assert pose[i].tobytes() == ref[s + i][0][0].tobytes(), (n, s, i)
                assert root[i].tobytes() == ref[s + i][1][0].tobytes(), (n, s, i)


def test_shipped_lifters_take_any_batch():
    for precision in ("int8", "fp32"):
        lifter = StreamingLifter.from_manifest(ASSETS_DIR, replace(_box().lifter, precision=precision, threads=1))
        assert lifter._batches
