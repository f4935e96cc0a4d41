"""wearable/recording.py: the IMU recording --record writes and --replay reads beside CSV."""
import json
import struct

import numpy as np
import pytest

from edge_runtime import __main__ as table
from edge_runtime.errors import InputError
from edge_runtime.wearable import recording
from edge_runtime.wearable.recording import HEADER, MAGIC, RECORD, RecordingWriter, open_replay, read_recording
from edge_runtime.wearable.sources import ImuBlock, ReplayStats


def _csv(path, acc, t0=0.0):
    rows = "\n".join(f"{t0 + i / 100:.2f},{a:.4f},{b:.4f},{c:.4f}" for i, (a, b, c) in enumerate(acc))
    path.write_text("t,ax,ay,az\n" + rows + "\n")
    return path


def _decisions(path):
    out = []
    for line in path.read_text().splitlines():
        d = json.loads(line)
        d.pop("compute_us")  # wall-clock time
        out.append(d)
    return out


@pytest.mark.parametrize("decision, at_least", [("early", 3), ("stream", 2)])  # the capture path, the shipped decider
def test_a_csv_recorded_and_replayed_decides_as_the_csv(tmp_path, decision, at_least):
    from firmware_sim.devices.wrist import simulate_drive

    acc = simulate_drive(2.0, seed=5).acc_mps2
    acc[5000:5020] = np.nan  # bad samples are recorded as bad samples
    csv = _csv(tmp_path / "d.csv", acc)
    lines = csv.read_text().splitlines()
    csv.write_text("\n".join(lines[:8001] + lines[8301:]) + "\n")  # a 3-s gap
    imu = tmp_path / "d.imu"
    assert table.main(["wearable", "--replay", str(csv), "--decision", decision,
                       "--alerts", str(tmp_path / "csv.jsonl"), "--record", str(imu), "--quiet"]) == 0
    assert table.main(["wearable", "--replay", str(imu), "--decision", decision,
                       "--alerts", str(tmp_path / "imu.jsonl"), "--quiet"]) == 0
    via_csv = _decisions(tmp_path / "csv.jsonl")
    assert len(via_csv) >= at_least and via_csv == _decisions(tmp_path / "imu.jsonl")
    stats = ReplayStats()
    blocks = list(open_replay(imu, stats))
    assert stats.gaps == 1 and stats.rows == sum(len(b.acc_mps2) for b in blocks) == len(lines) - 1 - 300
    assert [b.continuous for b in blocks].count(False) == 1
    assert int(np.isnan(np.concatenate([b.acc_mps2 for b in blocks])).any(axis=1).sum()) == 20


def test_the_writer_gathers_samples_into_records_and_splits_at_gaps(tmp_path):
    w = RecordingWriter(tmp_path / "r.imu")
    acc = np.arange(3 * 5000, dtype=np.float32).reshape(-1, 3) / 1000
    for i in range(5000):  # a live source: one sample at a time
        w.write(ImuBlock(10.0 + i / 100, acc[i : i + 1], i > 0))
    w.write(ImuBlock(100.0, acc[:5], continuous=False))
    w.close()
    blocks = list(read_recording(tmp_path / "r.imu"))
    assert [(round(b.t0_s, 2), len(b.acc_mps2), b.continuous) for b in blocks] == [
        (10.0, recording.RECORD_ROWS, True), (10.0 + recording.RECORD_ROWS / 100, 5000 - recording.RECORD_ROWS, True),
        (100.0, 5, False)]
    assert np.array_equal(np.concatenate([b.acc_mps2 for b in blocks[:2]]), acc)


def _file(tmp_path, header=None, records=()):
    data = header if header is not None else HEADER.pack(MAGIC, 1, 0, 100)
    for t0, n, reserved, body in records:
        data += RECORD.pack(t0, n, reserved) + (body if body is not None else np.zeros((n, 3), "<f4").tobytes())
    path = tmp_path / "bad.imu"
    path.write_bytes(data)
    return path


@pytest.mark.parametrize("header, records, match", [
    (MAGIC[:5], (), r"5 bytes; an IMU recording's header is 16"),
    (HEADER.pack(MAGIC, 2, 0, 100), (), r"version 2\.0; this box reads 1\.0"),
    (HEADER.pack(MAGIC, 1, 0, 50), (), r"recorded at 50 Hz"),
    (None, [(0.0, 0, 0, b"")], r"byte 16: record of 0 samples"),
    (None, [(0.0, 1 << 30, 0, b"")], r"byte 16: record of 1073741824 samples"),
    (None, [(0.0, 4, 7, None)], r"byte 16: .*reserved field 7"),
    (None, [(float("nan"), 4, 0, None)], r"byte 16: start time nan is not a time"),
    (None, [(0.0, 4, 0, None), (0.01, 4, 0, None)], r"byte 80: record starts at 0\.010 s, before the previous"),
    (None, [(0.0, 4, 0, b"\0" * 20)], r"byte 32: truncated record \(20 of 48 bytes"),
])
def test_a_malformed_recording_is_one_input_error_naming_the_byte(tmp_path, header, records, match):
    path = _file(tmp_path, header, records)
    with pytest.raises(InputError, match=match):
        list(read_recording(path))


def test_a_truncated_record_header_ends_the_replay_with_an_error_and_the_command_exits_2(tmp_path, capsys):
    path = _file(tmp_path, records=[(0.0, 4, 0, None)])
    path.write_bytes(path.read_bytes() + struct.pack("<d", 1.0))
    assert table.main(["wearable", "--replay", str(path), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert "byte 80: truncated record header (8 of 16 bytes)" in err and "Traceback" not in err


def test_a_file_without_the_magic_is_read_as_csv(tmp_path):
    csv = _csv(tmp_path / "x.csv", np.tile([0.0, 0.0, 9.81], (300, 1)))
    assert not recording.is_recording(csv) and recording.is_recording(_file(tmp_path))
    assert sum(len(b.acc_mps2) for b in open_replay(csv)) == 300


def test_a_record_path_that_cannot_be_written_is_one_line_and_exit_2(tmp_path, capsys):
    csv = _csv(tmp_path / "x.csv", np.tile([0.0, 0.0, 9.81], (300, 1)))
    assert table.main(["wearable", "--replay", str(csv), "--record", str(tmp_path / "no" / "such" / "r.imu"),
                       "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--record" in err and "cannot write" in err and "Traceback" not in err


def test_replay_joins_records_that_continue_one_another_and_counts_each_block_as_it_goes_out(tmp_path):
    w = RecordingWriter(tmp_path / "r.imu", record_rows=1000)
    acc = np.tile(np.float32([0.0, 0.0, 9.81]), (5500, 1))
    acc[2500, 0] = 156.9  # at full scale: saturated, its record goes alone
    w.write(ImuBlock(0.0, acc))
    w.write(ImuBlock(100.0, acc[:700], continuous=False))
    w.close()
    stats = ReplayStats()
    blocks = open_replay(tmp_path / "r.imu", stats)
    seen = []
    for b in blocks:
        seen.append((round(b.t0_s, 2), len(b.acc_mps2), b.continuous, stats.saturated, stats.gaps, stats.rows))
    assert seen == [(0.0, 2000, True, 0, 0, 2000), (20.0, 1000, True, 1, 0, 3000), (30.0, 2500, True, 1, 0, 5500),
                      (100.0, 700, False, 1, 1, 6200)]
    assert [len(b.acc_mps2) for b in read_recording(tmp_path / "r.imu")] == [1000] * 5 + [500, 700]  # as written
    few = RecordingWriter(tmp_path / "s.imu", record_rows=4)
    few.write(ImuBlock(0.0, acc[:10]))
    few.close()
    assert [len(b.acc_mps2) for b in recording.read_recording(tmp_path / "s.imu", join_rows=8)] == [8, 2]
