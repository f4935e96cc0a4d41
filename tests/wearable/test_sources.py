"""Recordings in, 100 Hz blocks out; malformed files name the line."""
import numpy as np
import pytest

from edge_runtime.wearable.sources import InputError, ReplayStats, read_imu_csv


def _write(path, t, acc):
    rows = "\n".join(f"{a:.4f},{b:.5f},{c:.5f},{d:.5f}" for a, (b, c, d) in zip(t, acc))
    path.write_text("t,ax,ay,az\n" + rows + "\n")
    return path


def test_plain_100hz_recording_is_one_block(tmp_path):
    t = np.arange(1000) / 100
    acc = np.c_[np.sin(t), np.cos(t), np.full_like(t, 9.81)]
    (blk,) = read_imu_csv(_write(tmp_path / "r.csv", t, acc))
    assert blk.t0_s == 0.0 and blk.continuous and blk.acc_mps2.shape == (1000, 3)
    np.testing.assert_allclose(blk.acc_mps2, acc, atol=1e-4)


def test_other_constant_rate_is_resampled_with_a_notice(tmp_path):
    t = np.arange(500) / 50.0  # 10 s at 50 Hz
    acc = np.c_[np.sin(2 * np.pi * 0.5 * t), np.zeros_like(t), np.full_like(t, 9.81)]
    stats = ReplayStats()
    (blk,) = read_imu_csv(_write(tmp_path / "r50.csv", t, acc), stats)
    assert len(blk.acc_mps2) == 1000 and abs(stats.source_rate_hz - 50) < 0.01
    assert any("resampled to 100 Hz" in n for n in stats.notices)
    t100 = np.arange(1000) / 100.0
    np.testing.assert_allclose(blk.acc_mps2[50:-50, 0], np.sin(2 * np.pi * 0.5 * t100)[50:-50], atol=0.01)


def test_gaps_split_blocks_and_backwards_time_is_dropped(tmp_path):
    t = np.r_[np.arange(300), np.arange(299, 400), np.arange(600, 900)] / 100.0  # duplicate at 2.99, gap 4.0 -> 6.0
    acc = np.tile([0.0, 0.0, 9.81], (len(t), 1))
    stats = ReplayStats()
    blocks = read_imu_csv(_write(tmp_path / "g.csv", t, acc), stats)
    assert [len(b.acc_mps2) for b in blocks] == [400, 300]
    assert [b.continuous for b in blocks] == [True, False] and blocks[1].t0_s == 6.0
    assert stats.dropped_non_monotonic == 1 and stats.gaps == 1


@pytest.mark.parametrize(
    "body, match",
    [
        ("t,x,y,z\n0,1,2,3\n", r":1: header"),
        ("t,ax,ay,az\n0,1,2,3\n0.01,1,2\n", r":3: expected 4 fields"),
        ("t,ax,ay,az\n0,1,2,3\n0.01,1,abc,3\n", r":3: field 'ay' is not a number"),
        ("t,ax,ay,az\n0,1,2,3\nnan,1,2,3\n", r":3: field 't'"),
        ("", r"empty file"),
    ],
)
def test_malformed_csv_names_the_line(tmp_path, body, match):
    p = tmp_path / "bad.csv"
    p.write_text(body)
    with pytest.raises(InputError, match=match):
        read_imu_csv(p)
