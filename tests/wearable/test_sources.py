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
    blocks = list(read_imu_csv(_write(tmp_path / "g.csv", t, acc), stats))
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
        ("t,ax,ay,az\n0,1,2,3\n0.01,1,2,3\n1.7e308,1,2,3\n", r":4: field 't' is not a time in seconds"),
        ("t,ax,ay,az\n0,1,2,3\n1000,1,2,3\n2000,1,2,3\n", r"sample rate of 0.001 Hz"),
        ("", r"empty file"),
    ],
)
def test_malformed_csv_names_the_line(tmp_path, body, match):
    p = tmp_path / "bad.csv"
    p.write_text(body)
    with pytest.raises(InputError, match=match):
        read_imu_csv(p)


def test_non_utf8_line_is_named(tmp_path):
    p = tmp_path / "bin.csv"
    p.write_bytes(b"t,ax,ay,az\n0,1,2,3\n0.01,1,\xff2,3\n")
    with pytest.raises(InputError, match=r"bin.csv:3: not UTF-8 text \(byte 8 of the line\)"):
        read_imu_csv(p)


def test_impossible_values_are_counted_and_reach_the_loop_as_nan(tmp_path):
    t = np.arange(10) / 100
    acc = np.tile([0.0, 0.0, 9.81], (10, 1))
    acc[2, 0] = 3.4e38  # finite in float64, inf in float32
    acc[4, 1] = 200.0  # beyond the 16 g range
    acc[6, 2] = 156.9  # at full scale: saturated, kept
    p = _write(tmp_path / "v.csv", t, acc)
    text = p.read_text().splitlines()
    text[9] = "0.0800," + "9" * 400 + ",0,9.81"  # a 400-digit number: inf
    p.write_text("\n".join(text) + "\n")
    stats = ReplayStats()
    (blk,) = read_imu_csv(p, stats)
    bad = np.flatnonzero(np.isnan(blk.acc_mps2).any(1))
    assert list(bad) == [2, 4, 8] and stats.out_of_range == 3 and stats.saturated == 1  # inf is beyond too
    assert np.nanmax(np.abs(blk.acc_mps2)) == pytest.approx(156.9)


def test_the_configured_range_is_used(tmp_path):
    t = np.arange(10) / 100
    acc = np.tile([0.0, 0.0, 9.81], (10, 1))
    acc[3, 0] = 2.5 * 9.81  # inside 16 g, beyond 2 g
    stats = ReplayStats()
    (blk,) = read_imu_csv(_write(tmp_path / "r.csv", t, acc), stats, range_mps2=156.9)
    assert stats.saturated == 0 and stats.out_of_range == 0 and np.isfinite(blk.acc_mps2).all()
    stats = ReplayStats()
    (blk,) = read_imu_csv(_write(tmp_path / "r.csv", t, acc), stats, range_mps2=19.6)
    assert stats.out_of_range == 1 and np.isnan(blk.acc_mps2[3]).all()


def test_a_long_recording_is_streamed_in_chunks_with_the_same_blocks(tmp_path):
    t = np.r_[np.arange(250), np.arange(400, 700)] / 100  # one gap
    acc = np.c_[np.sin(t), np.cos(t), np.full_like(t, 9.81)]
    p = _write(tmp_path / "long.csv", t, acc)
    whole = list(read_imu_csv(p))
    chunked = list(read_imu_csv(p, chunk_rows=64))
    assert [len(b.acc_mps2) for b in whole] == [250, 300] and [b.continuous for b in whole] == [True, False]
    assert [b.continuous for b in chunked].count(False) == 1
    np.testing.assert_array_equal(np.concatenate([b.acc_mps2 for b in chunked]),
                                  np.concatenate([b.acc_mps2 for b in whole]))
    gap_block = next(b for b in chunked if not b.continuous)
    assert gap_block.t0_s == 4.0


PLAIN_LINES = [b"0.00,4.0510,-6.8857,6.0334\n", b"-0.5,.5,5.,007\n", b"123456.789012345,0.1,-0.0,9\n",
               b"1e3,1,2,3\n", b"1,2,3\n", b"1,2,3,4,5\n", b"1,,2,3\n", b"1.2.3,1,2,3\n", b"1-2,1,2,3\n",
               b"-,1,2,3\n", b"\n", b" 1,2,3,4\n", b"1,2,3,4\r\n", b"1234567890123456,1,2,3\n", b"+1,2,3,4\n",
               b"inf,1,2,3\n", b".,1,2,3\n"]


@pytest.mark.parametrize("line", PLAIN_LINES)
def test_the_array_parser_gives_float_or_leaves_the_line_to_the_line_parser(line):
    """Bit for bit what float() makes of each number, or None (then the line parser names a bad line)."""
    from edge_runtime.wearable.sources import _parse_plain_block

    got = _parse_plain_block(line)
    cells = line.rstrip(b"\n").split(b",")
    plain = (len(cells) == 4 and all(c and set(c) <= set(b"0123456789.-") and c.count(b".") <= 1
                                     and b"-" not in c[1:] and any(d in c for d in b"0123456789")
                                     and sum(d in b"0123456789" for d in c) <= 15 for c in cells))
    if not plain:
        assert got is None
        return
    want = np.array([float(c) for c in cells])
    assert got.shape == (1, 4)
    np.testing.assert_array_equal(got[0].view(np.int64), want.view(np.int64))


def test_the_array_parser_equals_float_on_a_whole_drive():
    from edge_runtime.wearable.sources import _parse_plain_block

    rng = np.random.default_rng(0)
    rows = np.c_[np.arange(5000) / 100, rng.normal(0, 30, (5000, 3))]
    text = "".join(f"{t:.2f},{a:.4f},{b:.6f},{c:.1f}\n" for t, a, b, c in rows).encode()
    want = np.array([[float(c) for c in line.split(",")] for line in text.decode().splitlines()])
    np.testing.assert_array_equal(_parse_plain_block(text).view(np.int64), want.view(np.int64))


def test_a_bad_line_after_plain_chunks_is_named_and_a_missing_last_newline_is_fine(tmp_path):
    lines = "".join(f"{i / 100:.2f},1.0000,2.0000,9.8100\n" for i in range(300))
    p = tmp_path / "r.csv"
    p.write_text("t,ax,ay,az\n" + lines + "3.00,1,2,3")  # no newline at the end
    assert sum(len(b.acc_mps2) for b in read_imu_csv(p, chunk_rows=16)) == 301
    p.write_text("t,ax,ay,az\n" + lines + "3.00,1,x,3\n")
    with pytest.raises(InputError, match=r"r\.csv:302: field 'ay' is not a number"):
        list(read_imu_csv(p, chunk_rows=16))


@pytest.mark.parametrize("value, counts", [(None, (0, 0)), (np.nan, (0, 0)), (np.inf, (1, 0)), (200.0, (1, 0)),
                                           (156.9, (0, 1)), (156.9 * (1 - 2e-6), (0, 0))])
def test_a_float32_block_is_screened_as_its_float64_copy(value, counts):
    """A recording's float32 block takes a shortcut when all of it lies well inside the range; the
    result (samples, NaN where refused, counts) is the full check's, whatever one sample holds."""
    from edge_runtime.wearable.sources import screen_samples

    acc = np.random.default_rng(3).normal(0.0, 20.0, (4096, 3)).astype(np.float32)
    if value is not None:
        acc[1234, 1] = value
    got, out_of_range, saturated = screen_samples(acc, 156.9)
    want, want_out, want_sat = screen_samples(acc.astype(np.float64), 156.9)
    np.testing.assert_array_equal(got, want)  # NaN in the same places
    assert (out_of_range, saturated) == (want_out, want_sat)
    assert got.dtype == np.float32 and got is not acc
    assert (out_of_range, saturated) == counts
    assert np.isnan(got).any() == (value is not None and not np.isfinite(value) or value == 200.0)
