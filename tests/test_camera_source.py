"""edge_runtime.camera_source: OpenCV capture -> stand-in 2D pose ONNX model -> people.

The stand-in pose model has the documented contract: image (1, 3, 96, 128) RGB in
[0, 1] -> keypoints (1, 2, 17, 3). Person 0's keypoints sit at fixed input pixels
and their score is the RED value of the input's centre pixel (so the test sees
whether the image reached the model as RGB in [0, 1]); person 1 has score 0
(padding).
"""
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from edge_runtime.camera_source import (BadImageError, CameraError, CameraFrame, CameraKeypointSource,
                                        CameraSourceParams, CameraStatus, PoseModel, letterbox)
from edge_runtime.manifest import ModelIntegrityError

IN_H, IN_W = 96, 128
KP_INPUT_PX = np.stack([np.linspace(10, 118, 17), np.linspace(20, 76, 17)], axis=1)  # inside the letterboxed image


def _save(model, path: Path) -> Path:
    import onnx

    model.ir_version = 8
    onnx.checker.check_model(model)
    onnx.save(model, path)
    return path


def make_pose_model(path: Path) -> Path:
    from onnx import TensorProto, helper, numpy_helper

    xy = np.zeros((1, 2, 17, 2), np.float32)
    xy[0, 0] = KP_INPUT_PX
    weight = np.zeros((1, 2, 17, 1), np.float32)
    weight[0, 0] = 1.0
    inits = [numpy_helper.from_array(a, n) for a, n in (
        (xy, "xy"), (weight, "weight"), (np.array([0, 0, IN_H // 2, IN_W // 2], np.int64), "starts"),
        (np.array([1, 1, IN_H // 2 + 1, IN_W // 2 + 1], np.int64), "ends"))]
    nodes = [helper.make_node("Slice", ["image", "starts", "ends"], ["red"]),
             helper.make_node("Mul", ["red", "weight"], ["score"]),
             helper.make_node("Concat", ["xy", "score"], ["keypoints"], axis=3)]
    graph = helper.make_graph(nodes, "pose_standin",
                              [helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 3, IN_H, IN_W])],
                              [helper.make_tensor_value_info("keypoints", TensorProto.FLOAT, [1, 2, 17, 3])], inits)
    return _save(helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)]), path)


def make_heatmap_model(path: Path, peaks_hw) -> Path:
    from onnx import TensorProto, helper, numpy_helper

    hm = np.zeros((1, 17, 24, 32), np.float32)
    for j, (r, c) in enumerate(peaks_hw):
        hm[0, j, r, c] = 0.7
    nodes = [helper.make_node("ReduceMean", ["image"], ["m"], keepdims=1),
             helper.make_node("Mul", ["m", "zero"], ["z"]),
             helper.make_node("Add", ["hm", "z"], ["heatmaps"])]
    graph = helper.make_graph(nodes, "heatmap_standin",
                              [helper.make_tensor_value_info("image", TensorProto.FLOAT, [1, 3, IN_H, IN_W])],
                              [helper.make_tensor_value_info("heatmaps", TensorProto.FLOAT, [1, 17, 24, 32])],
                              [numpy_helper.from_array(hm, "hm"), numpy_helper.from_array(np.zeros(1, np.float32), "zero")])
    return _save(helper.make_model(graph, opset_imports=[helper.make_opsetid("", 17)]), path)


@pytest.fixture(scope="module")
def pose_model_path(tmp_path_factory):
    return make_pose_model(tmp_path_factory.mktemp("pose") / "pose.onnx")


def write_video(path: Path, n: int = 8, size=(160, 80), bgr=(0, 0, 255), fps: float = 25.0) -> Path:
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"MJPG"), fps, size)
    assert w.isOpened()
    for _ in range(n):
        w.write(np.full((size[1], size[0], 3), bgr, np.uint8))
    w.release()
    return path


def _expected_image_px(w: int, h: int) -> np.ndarray:
    s = min(IN_W / w, IN_H / h)
    off = np.array([(IN_W - round(w * s)) // 2, (IN_H - round(h * s)) // 2])
    return (KP_INPUT_PX - off) / s


def test_video_file_through_pose_model(tmp_path, pose_model_path):
    video = write_video(tmp_path / "red.avi", n=8, size=(160, 80), bgr=(0, 0, 255), fps=25)
    model = PoseModel(pose_model_path)
    assert model.input_hw == (IN_H, IN_W) and model.output_kind == "keypoints"
    with CameraKeypointSource(str(video), model) as src:
        items = list(src.frames())
    frames = [i for i in items if isinstance(i, CameraFrame)]
    assert len(frames) == 8 and isinstance(items[-1], CameraStatus) and items[-1].state == "ended"
    assert [f.index for f in frames] == list(range(8))
    np.testing.assert_allclose([f.t_s for f in frames], np.arange(8) / 25, atol=1e-9)
    for f in frames:
        assert len(f.people) == 1  # the zero-score person is padding
        kp = f.people[0].keypoints
        assert kp[:, 2].min() > 0.9  # red reached the model as R close to 1
        np.testing.assert_allclose(kp[:, :2], _expected_image_px(160, 80), atol=1e-4)
    assert src.stats.frames == 8 and src.stats.bad_images == 0


def test_blue_video_scores_low_so_channels_are_rgb(tmp_path, pose_model_path):
    video = write_video(tmp_path / "blue.avi", n=2, bgr=(255, 0, 0))
    with CameraKeypointSource(str(video), PoseModel(pose_model_path)) as src:
        frames = [i for i in src.frames() if isinstance(i, CameraFrame)]
    assert frames and all(f.people == [] for f in frames)  # red ~ 0: below min_person_score


def test_heatmap_contract(tmp_path):
    peaks = [(j % 24, (3 * j) % 32) for j in range(17)]
    model = PoseModel(make_heatmap_model(tmp_path / "hm.onnx", peaks))
    assert model.output_kind == "heatmaps"
    img = np.zeros((IN_H, IN_W, 3), np.uint8)  # same size as the input: no letterbox scaling
    (person,) = model.detect(img)
    want = np.array([[(c + 0.5) * IN_W / 32, (r + 0.5) * IN_H / 24] for r, c in peaks])
    np.testing.assert_allclose(person.keypoints[:, :2], want, atol=1e-6)
    np.testing.assert_allclose(person.keypoints[:, 2], 0.7, atol=1e-6)


class FakeCapture:
    """A live camera: frames from a list (None, empty arrays ...), then ``stall_s`` of silence."""

    def __init__(self, images, stall_s: float = 0.0):
        self.images = list(images)
        self.stall_s = stall_s
        self.released = False

    def read(self):
        if self.images:
            time.sleep(0.005)
            img = self.images.pop(0)
            return (img is not None), img
        if self.stall_s > 0:
            time.sleep(self.stall_s)
            self.stall_s = 0
            return True, np.full((40, 60, 3), (0, 0, 255), np.uint8)
        time.sleep(0.02)
        return False, None

    def release(self):
        self.released = True


def test_zero_size_and_bad_images_are_skipped_and_counted(pose_model_path):
    red = np.full((40, 60, 3), (0, 0, 255), np.uint8)
    images = [red, np.zeros((0, 0, 3), np.uint8), red, np.zeros((10, 10, 3), np.float32),
              np.zeros((5, 5, 7), np.uint8), red]
    cap = FakeCapture(images)
    params = CameraSourceParams(stall_timeout_s=0.2, give_up_s=0.4)
    src = CameraKeypointSource(cap, PoseModel(pose_model_path), params, live=False)
    items = list(src.frames())
    src.close()
    frames = [i for i in items if isinstance(i, CameraFrame)]
    assert [f.index for f in frames] == [0, 2, 5] and src.stats.bad_images == 3
    assert cap.released and items[-1].state == "ended"
    with pytest.raises(BadImageError, match="zero-size"):
        PoseModel(pose_model_path).detect(np.zeros((0, 4, 3), np.uint8))
    with pytest.raises(BadImageError, match="no image"):
        letterbox(None, IN_H, IN_W)


def test_stalled_camera_is_reported_then_recovers_then_disconnects(pose_model_path):
    red = np.full((40, 60, 3), (0, 0, 255), np.uint8)
    cap = FakeCapture([red, red], stall_s=0.5)
    params = CameraSourceParams(stall_timeout_s=0.15, give_up_s=0.6)
    src = CameraKeypointSource(cap, PoseModel(pose_model_path), params, live=True)
    items = []
    for item in src.frames():
        items.append(item)
    src.close()
    states = [i.state for i in items if isinstance(i, CameraStatus)]
    assert states == ["stalled", "ok", "stalled", "disconnected"]
    assert src.stats.stalls == 2 and src.stats.frames == 3 and src.stats.read_failures > 0
    frames = [i for i in items if isinstance(i, CameraFrame)]
    assert frames[2].t_s - frames[1].t_s >= 0.4  # live timestamps follow the clock


def test_missing_or_broken_sources_and_models(tmp_path, pose_model_path):
    with pytest.raises(CameraError, match="nope.avi: video file not found"):
        CameraKeypointSource(str(tmp_path / "nope.avi"), PoseModel(pose_model_path))
    junk = tmp_path / "junk.avi"
    junk.write_bytes(b"not a video at all")
    with pytest.raises(CameraError, match="junk.avi: OpenCV cannot open"):
        CameraKeypointSource(str(junk), PoseModel(pose_model_path))
    with pytest.raises(ModelIntegrityError, match="missing.onnx: pose model file not found"):
        PoseModel(tmp_path / "missing.onnx")
    broken = tmp_path / "broken.onnx"
    broken.write_bytes(pose_model_path.read_bytes()[:200])
    with pytest.raises(ModelIntegrityError, match="broken.onnx: onnxruntime cannot load"):
        PoseModel(broken)
