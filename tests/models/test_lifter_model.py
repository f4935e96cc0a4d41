"""The pose lifter model (models/lifter.py), its ONNX/int8 export and the manifest merge (export/lifter_assets.py)."""
import copy
import json
import shutil

import numpy as np
import pytest
import torch
from support import REPO_ROOT

from export import lifter_assets as la
from export.quantize import build_variant, integer_kernel_drift
from models.lifter import (
    LifterConfig,
    LifterNet,
    TemporalModel,
    TemporalModelOptimized1f,
    build_from_manifest,
    condition_input,
    count_parameters,
)
from models.pose_data import DataConfig, build_splits, flip, held_joints

REPO = REPO_ROOT


@pytest.fixture(scope="module")
def tiny_data():
    return build_splits(DataConfig(train_subjects=2, test_subjects=1, seconds_per_subject=12, train_cameras=2,
                                   test_cameras=1, views=1, seed=3))


def _warmed(model: LifterNet, x: torch.Tensor) -> LifterNet:
    """BatchNorm statistics from a few training-mode passes, then eval mode."""
    model.train()
    with torch.no_grad():
        for _ in range(5):
            model(x)
    return model.eval()


@pytest.mark.parametrize("channels,expected", [(1024, 8_555_571), (256, 566_067)])
def test_parameter_counts_match_videopose3d(channels, expected):
    for cls in (TemporalModel, TemporalModelOptimized1f):
        assert count_parameters(cls(17, 2, 17, (3, 3, 3), channels=channels)) == expected
    net = LifterNet(LifterConfig(channels=channels))
    assert net.parameter_counts()["pose"] == expected
    assert net.parameter_counts()["total"] == expected + count_parameters(net.trajectory)
    assert LifterConfig().receptive_field == 27 and net.pose.receptive_field() == 27


def test_causal_mode_uses_only_past_frames():
    torch.manual_seed(0)
    causal = TemporalModel(17, 2, 17, (3, 3, 3), causal=True, channels=32).eval()
    centred = TemporalModel(17, 2, 17, (3, 3, 3), causal=False, channels=32)
    centred.load_state_dict(causal.state_dict())
    centred.eval()
    x = torch.randn(1, 60, 17, 2)
    with torch.no_grad():
        base_c, base_n = causal(x), centred(x)
        assert base_c.shape == (1, 34, 17, 3)
        t = 36                                     # the frame described: causal output t-26, centred output t-13
        future = x.clone()
        future[:, t + 1:] += 1.0                   # change only frames after t
        assert torch.allclose(causal(future)[:, t - 26], base_c[:, t - 26])
        assert not torch.allclose(centred(future)[:, t - 13], base_n[:, t - 13])   # the centred model looks ahead
        now = x.clone()
        now[:, t] += 1.0
        assert not torch.allclose(causal(now)[:, t - 26], base_c[:, t - 26])


def test_strided_and_dilated_variants_agree_on_a_window():
    torch.manual_seed(1)
    net = _warmed(LifterNet(LifterConfig(channels=64, trajectory_channels=32), strided=True), torch.randn(16, 27, 17, 2))
    x = torch.randn(5, 27, 17, 2) * 0.3
    with torch.no_grad():
        p1, r1 = net(x)
        p2, r2 = net.as_variant(strided=False).eval()(x)
    assert p1.shape == (5, 1, 17, 3) and r1.shape == (5, 1, 3)
    assert torch.allclose(p1, p2, atol=1e-5) and torch.allclose(r1, r2, atol=1e-5)
    assert torch.all(p1[:, :, 0] == 0)                     # root-relative: joint 0 is exactly 0
    c = condition_input(x)
    assert torch.equal(c[:, :, 0], x[:, :, 0]) and torch.allclose(c[:, :, 5] / 4.0, x[:, :, 5] - x[:, :, 0], atol=1e-6)
    assert build_from_manifest({"name": "x", "config": net.config.to_dict()}).parameter_counts() == net.parameter_counts()


def test_flip_augmentation_is_an_exact_mirror():
    rng = np.random.default_rng(0)
    k, p, r = rng.normal(size=(4, 17, 2)), rng.normal(size=(4, 17, 3)), rng.normal(size=(4, 3))
    k2, p2, r2 = flip(*flip(k, p, r))
    assert np.allclose(k2, k) and np.allclose(p2, p) and np.allclose(r2, r)
    fk, fp, _ = flip(k, p, r)
    assert np.allclose(fk[:, 4, 0], -k[:, 1, 0]) and np.allclose(fp[:, 14], p[:, 11] * [-1, 1, 1])


def test_missing_joints_are_held_and_frames_marked_invalid_like_the_runtime():
    det = np.zeros((10, 17, 3))
    det[..., 0] = np.arange(10)[:, None]
    det[2:4, 5, :2] = np.nan                       # 2 frames missing: held, still valid
    det[5:10, 7, :2] = np.nan                      # 5 frames: invalid after the 3rd
    px, valid = held_joints(det, hold_frames=3)
    assert px[3, 5, 0] == 1 and px[9, 7, 0] == 4
    assert valid.tolist() == [True] * 8 + [False, False]


def test_onnx_parity_and_int8_error_on_a_tiny_model(tmp_path, tiny_data):
    torch.manual_seed(2)
    train = tiny_data["train"]
    idx = np.flatnonzero(train.valid)
    x = train.windows(idx[::7]).astype(np.float32)
    net = _warmed(LifterNet(LifterConfig(channels=32, trajectory_channels=16)), torch.from_numpy(x))
    fp32 = la.export_onnx(net, tmp_path / "l.onnx")
    par = la.check_parity(net, fp32, x[:64])
    assert par["ok"] and par["max_abs_pose_m"] < 1e-4
    pose32, root32 = la.onnx_runner(fp32)(x)
    for cand in la.CANDIDATES:
        q = build_variant(fp32, tmp_path / f"l.{cand.name}.onnx", cand, x[:200], describe=False)
        pose8, root8 = la.onnx_runner(q)(x)
        err = np.linalg.norm(pose8 - pose32, axis=-1).mean()
        spread = np.linalg.norm(pose32 - pose32.mean(0), axis=-1).mean()
        assert err < 0.1 * spread, cand.name                   # int8 tracks fp32 closely ...
        assert np.abs(root8 - root32).max() < 0.1 * max(1.0, np.abs(root32).max())
        assert not np.allclose(pose8, pose32)                  # ... but is not the fp32 graph
        assert integer_kernel_drift(q, {"keypoints_2d": x[:64]}) < 1e-4  # and no CPU saturates it
    assert la.choose_int8(100.0, {"a": 101.0, "b": 100.5, "c": 130.0}, {"a": 50, "b": 40, "c": 10}) == "b"
    assert la.choose_int8(100.0, {"c": 130.0, "d": 120.0}, {"c": 10, "d": 90}) == "d"


def _lifter_entry(name: str, precision: str) -> dict:
    return {"name": name, "file": f"{name}.onnx", "sha256": "0" * 64, "precision": precision, "arch": "lifter",
            "parameters": {"pose": 1}, "inputs": [{"name": "keypoints_2d"}], "outputs": [{"name": "pose_3d"}],
            "classes": []}


def test_manifest_merge_keeps_the_convlstm_entries(tmp_path):
    src = json.loads((REPO / "edge_runtime" / "assets" / "manifest.json").read_text())
    others = [e for e in src["models"] if e["arch"] != "lifter"]
    assert others, "the shipped manifest should list the ConvLSTM"
    (tmp_path / "manifest.json").write_text(json.dumps({**src, "models": copy.deepcopy(others)}))
    la.merge_manifest(tmp_path, [_lifter_entry("lifter-fp32", "fp32"), _lifter_entry("lifter-int8", "int8")], "t")
    la.merge_manifest(tmp_path, [_lifter_entry("lifter-fp32", "fp32"), _lifter_entry("lifter-int8", "int8")], "t")
    got = json.loads((tmp_path / "manifest.json").read_text())
    assert [e for e in got["models"] if e["arch"] != "lifter"] == others       # untouched, in order
    assert sorted(e["name"] for e in got["models"] if e["arch"] == "lifter") == ["lifter-fp32", "lifter-int8"]
    assert got["created_by"] == src["created_by"]
    (tmp_path / "manifest.json").write_text("{not json")
    with pytest.raises(la.LifterExportError, match="unreadable manifest"):
        la.merge_manifest(tmp_path, [_lifter_entry("lifter-fp32", "fp32")], "t")
    fresh = tmp_path / "fresh"
    la.merge_manifest(fresh, [_lifter_entry("lifter-fp32", "fp32")], "t")
    assert [e["name"] for e in json.loads((fresh / "manifest.json").read_text())["models"]] == ["lifter-fp32"]
    shutil.rmtree(fresh)


def test_dataset_splits_are_disjoint_and_round_trip(tmp_path, tiny_data):
    from models.pose_data import PoseSet

    tr, ts, te = tiny_data["train"], tiny_data["test_subjects"], tiny_data["test"]
    assert not set(tr.subject) & set(te.subject) and set(ts.subject) == set(te.subject)
    assert not set(tr.camera) & set(te.camera) and set(ts.camera) <= set(range(tr.meta["config"]["train_cameras"]))
    assert np.allclose(tr.pose3d[:, 0], 0) and (tr.root3d[tr.valid, 2] > 0).all()
    w = tr.windows(np.array([tr.seq_start[0], tr.seq_start[0] + 30]))
    assert np.array_equal(w[0, 0], w[0, -1])                     # start padding repeats the first frame
    assert np.array_equal(w[1, -1], tr.kp2d[tr.seq_start[0] + 30])
    tr.save(tmp_path / "t.npz")
    back = PoseSet.load(tmp_path / "t.npz")
    assert np.array_equal(back.kp2d, tr.kp2d) and back.meta["split"] == "train"


def test_ground_plane_root_recovers_the_pelvis_from_exact_keypoints():
    from models.lifter_train import ground_plane_root, score

    ps = build_splits(DataConfig(train_subjects=1, test_subjects=1, seconds_per_subject=12, train_cameras=1,
                                 test_cameras=1, views=1, noise_scale=0.0, seed=4))["test"]
    idx = np.flatnonzero(ps.valid)
    est = ground_plane_root(ps, idx, ps.pose3d[idx])
    err = np.linalg.norm(est - ps.root3d[idx], axis=-1)
    assert np.median(err) < 0.05                      # only the ankle-height assumption is off
    m = score(ps, idx, ps.pose3d[idx], ps.root3d[idx])
    assert m["mpjpe_mm"] == 0 and m["root_error_mm"] == 0 and m["p_mpjpe_mm"] < 1e-3
    ps.meta.pop("extrinsics")
    assert ground_plane_root(ps, idx, ps.pose3d[idx]) is None


def test_varied_splits_hold_out_motion_types_cameras_and_people():
    from firmware_sim.scenarios.recording import MOTIONS
    from models.pose_data import VariedConfig, build_varied_splits, summary

    cfg = VariedConfig(train_scenes=3, val_scenes=1, test_scenes=1, seconds_per_scene=20, train_cameras=3,
                       eval_cameras=1, holdout_motions=("reach",), seed=3)
    sp = build_varied_splits(cfg)
    names = sp["train"].meta["activity_names"]
    assert names == list(MOTIONS) and "reach" not in sp["train"].meta["train_motions"]
    assert names.index("reach") not in set(sp["train"].activity)
    assert {names[i] for i in set(sp["train"].activity)} <= set(MOTIONS) - {"reach"}
    cams = {k: set(v.camera) for k, v in sp.items()}
    people = {k: set(v.subject) for k, v in sp.items()}
    for a, b in (("train", "val"), ("train", "test"), ("val", "test")):
        assert not cams[a] & cams[b] and not people[a] & people[b]
    for ps in sp.values():
        v = ps.valid
        assert v.mean() > 0.3 and np.isfinite(ps.kp2d[v]).all() and np.allclose(ps.pose3d[:, 0], 0)
        assert (ps.root3d[v, 2] > 0.3).all()
    assert sum(summary(sp["test"])["activities"].values()) == sp["test"].valid.sum()
    with pytest.raises(ValueError, match="holdout_motions"):
        build_varied_splits(VariedConfig(holdout_motions=("juggle",)))


def test_random_limbs_change_training_people_only_and_choices_skip_held_out_types():
    import dataclasses

    from models.pose_data import VariedConfig, build_varied_splits, trained_types_only

    cfg = VariedConfig(train_scenes=2, val_scenes=1, test_scenes=1, seconds_per_scene=15, train_cameras=2,
                       eval_cameras=1, seed=4)
    plain = build_varied_splits(cfg)
    aug = build_varied_splits(dataclasses.replace(cfg, random_limbs_share=1.0))
    # validation and test are the same scenes with the augmentation or without (it draws from its own generator)
    for split in ("val", "test"):
        for f in ("kp2d", "pose3d", "root3d", "valid", "activity", "subject", "camera"):
            assert np.array_equal(getattr(plain[split], f), getattr(aug[split], f)), (split, f)
    # training people move differently: their poses and keypoints, not their motion-type labels
    assert np.array_equal(plain["train"].activity, aug["train"].activity)
    assert np.abs(plain["train"].pose3d - aug["train"].pose3d).max() > 0.3
    assert aug["train"].meta["config"]["random_limbs_share"] == 1.0
    with pytest.raises(ValueError, match="random_limbs_share"):
        VariedConfig(random_limbs_share=1.5)
    # choices are scored on validation's trained motion types: carry and reach never count
    val = plain["val"]
    names = val.meta["activity_names"]
    held = np.isin(val.activity, [names.index("carry"), names.index("reach")])
    assert (val.valid & held).any()
    chosen, what = la.choice_set(plain)
    assert not (chosen.valid & held).any() and np.array_equal(chosen.valid, val.valid & ~held)
    assert what == "val, trained motion types only (not carry, reach)"
    assert np.array_equal(trained_types_only(val).kp2d, val.kp2d)


def test_varied_inputs_are_the_runtimes_canonical_keypoints():
    # a perfect detector: the model input, un-normalised, is the true joints projected by the canonical
    # camera (the lens undistorted away), except where COCO -> H36M mapping builds a joint (head, spine...)
    from firmware_sim.devices import camera as cam_sim
    from firmware_sim.scenarios.recording import random_camera
    from models.pose_data import VariedConfig, _scene_sequences

    rng = np.random.default_rng(0)
    camera = random_camera(rng)
    d = _scene_sequences(camera, rng, VariedConfig(seconds_per_scene=5), 1, cam_sim.PERFECT, ("walk",), ("walk",))[0]
    v = d["valid"]
    j = np.asarray(d["pose3d"], float) + d["root3d"][:, None]          # camera frame already
    canon = cam_sim.CANONICAL
    px = j[..., :2] / j[..., 2:] * canon.fx_px + (canon.cx_px, canon.cy_px)
    want = cam_sim.to_model_input(px)
    limbs = [1, 2, 3, 4, 5, 6, 11, 12, 13, 14, 15, 16]
    assert v.sum() > 100
    assert np.abs(d["kp2d"][v][:, limbs] - want[v][:, limbs]).max() < 2e-3
