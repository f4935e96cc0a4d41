"""models/stream_net.py and models/stream_train.py: the streaming classifier's labels, windows, training and
checkpoints (the full training is ``python -m models stream-train``, reports/wearable/stream_s22)."""
import numpy as np
import pytest
import torch

from edge_runtime.wearable.labels import CLASSES, OTHER
from models import __main__ as cli
from models import stream_train
from models.stream_net import MIN_STEPS, StreamNet, to25, windows
from models.stream_train import IGNORE, fit_stream, load_stream_checkpoint, step_labels, stream_set

I_OTHER = CLASSES.index(OTHER)


def test_step_labels_ignore_the_onset_and_the_return_and_mark_steps_near_other_motions():
    events = [{"label": "Phone", "start_s": 10.0, "end_s": 20.0}, {"label": OTHER, "start_s": 40.0, "end_s": 42.0}]
    y, near = step_labels(1500, events)  # 60 s of 25 Hz steps; step j ends at (4 j + 3) / 100 s
    t = (np.arange(1500) * 4 + 3) / 100

    def at(s):
        return int(np.argmin(np.abs(t - s)))

    assert y[at(9.9)] == I_OTHER and y[at(10.1)] == IGNORE and y[at(10.4)] == CLASSES.index("Phone")
    assert y[at(19.9)] == CLASSES.index("Phone") and y[at(20.5)] == IGNORE and y[at(21.1)] == I_OTHER
    assert near[at(37.1)] and near[at(44.9)] and not near[at(36.9)] and not near[at(45.1)]
    assert y[at(41.0)] == I_OTHER  # an Other motion is learnt as Other


def test_to25_averages_4_frames_and_windows_end_at_their_step():
    acc = np.arange(40 * 3, dtype=np.float32).reshape(40, 3)
    x25 = to25(acc)
    assert x25.shape == (10, 3) and x25.dtype == np.float32
    np.testing.assert_array_equal(x25[1], acc[4:8].mean(0))
    w = windows(x25, np.array([2, 9]), 4)
    assert w.shape == (2, 3, 4)
    np.testing.assert_array_equal(w[1], x25[6:10].T)
    np.testing.assert_array_equal(w[0], x25[[0, 0, 1, 2]].T)  # before a whole window: the first step repeated


def _recordings():
    rng = np.random.default_rng(0)
    recs = []
    for _ in range(2):
        acc = rng.normal(0, 0.3, (6000, 3)).astype(np.float32) + np.float32([0, 0, 9.81])
        acc[2000:3000, 0] += 5.0
        acc[4000:4300, 1] += 5.0
        recs.append((acc, [{"label": "Drink", "start_s": 20.0, "end_s": 30.0},
                           {"label": OTHER, "start_s": 40.0, "end_s": 43.0}]))
    return recs


def _data_of_kinds(first: str, second: str):
    """_recordings()' stream set, the first recording's Other motion of kind ``first``, the second's ``second``."""
    recs = _recordings()
    recs[0][1][1]["kind"], recs[1][1][1]["kind"] = first, second
    return stream_set(recs)


def test_training_is_deterministic_for_a_seed(monkeypatch):
    monkeypatch.setattr(stream_train, "SAMPLES", 512)
    data = stream_set(_recordings())
    assert len(data.distraction) and len(data.near_other) and len(data.far_other)
    a, last = fit_stream(data, width=8, epochs=2, seed=3, log=lambda s: None)
    b, _ = fit_stream(data, width=8, epochs=2, seed=3, log=lambda s: None)
    c, _ = fit_stream(data, width=8, epochs=2, seed=4, log=lambda s: None)
    assert all(torch.equal(x, y) for x, y in zip(a.state_dict().values(), b.state_dict().values()))
    assert not all(torch.equal(x, y) for x, y in zip(a.state_dict().values(), c.state_dict().values()))
    assert set(last) == {"loss", "train_accuracy_augmented"} and not a.training


def test_the_net_takes_any_window_of_at_least_min_steps():
    net = StreamNet(width=8).eval()
    with torch.no_grad():
        assert net(torch.zeros(2, 3, MIN_STEPS)).shape == (2, 6) and net(torch.zeros(1, 3, 100)).shape == (1, 6)
    assert sum(p.numel() for p in StreamNet(width=64).parameters()) == 71_142  # session 21's m64


def test_a_checkpoint_round_trips_and_the_prototypes_loads(tmp_path):
    from models.train import save_checkpoint

    net = StreamNet(width=8).eval()
    save_checkpoint(tmp_path / "m", net, arch="stream", classes=CLASSES, seed=0, epochs=1, metrics={}, data={})
    back, meta = load_stream_checkpoint(tmp_path / "m")
    assert meta["width"] == 8 and meta["classes"] == list(CLASSES)
    assert all(torch.equal(x, y) for x, y in zip(net.state_dict().values(), back.state_dict().values()))
    torch.save({"state": net.state_dict(), "width": 8, "epochs": 1, "seed": 0}, tmp_path / "proto.pt")
    assert load_stream_checkpoint(tmp_path / "proto.pt")[1]["width"] == 8


def test_stream_train_refuses_bad_arguments_in_one_line(tmp_path, capsys):
    assert cli.main(["stream-train", "--out", str(tmp_path), "--epochs", "0"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--epochs" in err[0]


def test_a_missing_checkpoint_is_a_data_error(tmp_path):
    from models.dataset import DataError

    with pytest.raises(DataError, match="checkpoint not found"):
        load_stream_checkpoint(tmp_path / "none")


def test_hard_masks_mark_the_hard_other_motions_and_the_return_after_a_distraction():
    events = [{"label": "Phone", "start_s": 10.0, "end_s": 20.0},
              {"label": OTHER, "start_s": 40.0, "end_s": 42.0, "kind": "grab_from_seat"},
              {"label": OTHER, "start_s": 50.0, "end_s": 52.0, "kind": "scratch_head"}]
    near_hard, returns = stream_train.hard_masks(1500, events)
    t = (np.arange(1500) * 4 + 3) / 100

    def at(s):
        return int(np.argmin(np.abs(t - s)))

    assert near_hard[at(37.1)] and near_hard[at(44.9)] and not near_hard[at(36.9)]
    assert not near_hard[at(51.0)]  # an Other motion of another kind is not a hard one
    assert not returns[at(20.9)] and returns[at(21.1)] and returns[at(23.9)] and not returns[at(24.1)]


def test_hard_sampling_draws_each_pool_by_its_share_and_s21_keeps_the_prototypes_draw(monkeypatch):
    monkeypatch.setattr(stream_train, "SAMPLES", 800)
    data = _data_of_kinds("shift_gear", "shift_gear")
    assert len(data.near_hard) and len(data.returns)
    ends = stream_train.epoch_ends(data, "hard", np.random.default_rng(0))
    assert len(ends) == 800
    assert np.isin(ends, data.distraction).sum() == 400
    assert np.isin(ends, data.returns).sum() >= 100 and np.isin(ends, data.near_hard).sum() >= 100  # also drawn by
    # the near-Other and elsewhere pools, which hold them
    assert (data.y[ends] == I_OTHER).sum() == 400 and (data.y[data.returns] == I_OTHER).all()
    rng = np.random.default_rng(0)
    old = np.concatenate([rng.choice(data.distraction, 400), rng.choice(data.near_other, 200),
                          rng.choice(data.far_other, 200)])
    rng.shuffle(old)
    np.testing.assert_array_equal(stream_train.epoch_ends(data, "s21", np.random.default_rng(0)), old)
    with pytest.raises(ValueError, match="sampling"):
        stream_train.epoch_ends(data, "neither", np.random.default_rng(0))


def test_hard2_sampling_draws_near_each_hard_kind_by_its_weight():
    data = _data_of_kinds("grab_from_seat", "touch_arm")  # weights 27 and 3
    grab, arm = data.near_kind["grab_from_seat"], data.near_kind["touch_arm"]
    assert len(grab) and len(arm) and not len(data.near_kind["hand_to_lap"])  # no motion of that kind
    assert (data.y[grab] == I_OTHER).all() and not np.isin(grab, arm).any()
    draws = stream_train.kind_draws(data.near_kind, 1000)
    assert [(len(pool), n) for pool, n in draws] == [(len(grab), 900), (len(arm), 100)]  # 27 : 3, absent kinds
    # give their share to the present ones
    with pytest.raises(ValueError, match="hard2"):
        stream_train.kind_draws({k: np.array([], int) for k in data.near_kind}, 10)


def test_hard2_epoch_holds_the_shares_of_its_pools(monkeypatch):
    monkeypatch.setattr(stream_train, "SAMPLES", 1000)
    data = _data_of_kinds("grab_from_seat", "grab_from_seat")
    ends = stream_train.epoch_ends(data, "hard2", np.random.default_rng(0))
    assert len(ends) == 1000 and np.isin(ends, data.distraction).sum() == 500 and (data.y[ends] == I_OTHER).sum() == 500
    # near the hard kind: its own 200 plus what the near-Other (75) and elsewhere (100) draws land there
    assert 200 <= np.isin(ends, data.near_kind["grab_from_seat"]).sum() <= 375


def test_the_training_command_names_every_cohort_seed_and_a_non_default_sampling():
    meta = {"width": 64, "epochs": 24, "seed": 0,
            "data": {"subjects": 20, "cohort_seed": [0, 1], "minutes_per_trial": 15.0, "sampling": "hard"}}
    assert stream_train.training_command(meta).endswith("--cohort-seed 0,1 --minutes 15 --sampling hard")
    meta["data"].update(cohort_seed=0, sampling="s21")
    assert stream_train.training_command(meta).endswith("--cohort-seed 0 --minutes 15")


@pytest.mark.parametrize("args, field", [(["--cohort-seed", "0,x"], "--cohort-seed"),
                                         (["--cohort-seed", "0,0"], "--cohort-seed"),
                                         (["--sampling", "most"], "--sampling")])
def test_stream_train_refuses_bad_cohort_seeds_and_samplings_in_one_line(tmp_path, capsys, args, field):
    assert cli.main(["stream-train", "--out", str(tmp_path), *args]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and field in err[0]
