"""edge_runtime.robot.camera_source: OpenCV capture -> stand-in 2D pose ONNX model -> people.

The stand-in pose model has the documented contract: image (1, 3, 96, 128) RGB in
[0, 1] -> keypoints (1, 2, 17, 3). Person 0's keypoints sit at fixed input pixels
and their score is the RED value of the input's centre pixel (so the test sees
whether the image reached the model as RGB in [0, 1]); person 1 has score 0
(padding).
"""
import time

import numpy as np
import pytest
from support.camera import IN_H, IN_W, KP_INPUT_PX, make_heatmap_model, make_pose_model, write_video

from edge_runtime.core.manifest import ModelIntegrityError
from edge_runtime.robot.camera_source import (
    BadImageError,
    CameraError,
    CameraFrame,
    CameraKeypointSource,
    CameraSourceParams,
    CameraStatus,
    PoseModel,
    letterbox,
)


@pytest.fixture(scope="module")
def pose_model_path(tmp_path_factory):
    return make_pose_model(tmp_path_factory.mktemp("pose") / "pose.onnx")




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
