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
