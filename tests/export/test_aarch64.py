"""export/aarch64.py's own logic (the emulated run itself is `make aarch64-check`, not a test)."""
import base64
import hashlib
import zipfile

import pytest

from export import aarch64
from export.aarch64 import (
    CAN_MEASURED,
    CONFIDENCE_TOL,
    WHEEL_DATE,
    _record_line,
    class_agreement,
    compare_can,
    compare_decisions,
    markdown,
    write_wheel,
)


def _d(t, label="Phone", conf=0.9, alerted=True, seq=0, status=None):
    return {"t_trigger_s": t, "t_alert_s": t + 6, "label": label, "status": status or ("alert" if alerted
                                                                                           else "not_alerted"),
            "alerted": alerted, "alert_seq": seq if alerted else None, "confidence": conf}


def test_same_decisions_within_the_confidence_tolerance_agree():
    x86 = [_d(1.0), _d(9.0, "Other", 0.6, False)]
    arm = [_d(1.0, conf=0.9 + CONFIDENCE_TOL / 2), _d(9.0, "Other", 0.6, False)]
    r = compare_decisions(x86, arm)
    assert r["ok"] and r["same_sequence"] and r["alerts_x86"] == r["alerts_aarch64"] == 1


def test_another_class_status_or_alert_seq_a_missing_decision_or_a_confidence_drift_disagree():
    x86 = [_d(1.0), _d(9.0, seq=1)]
    assert not compare_decisions(x86, [_d(1.0), _d(9.0, "Texting", seq=1)])["ok"]
    assert not compare_decisions(x86, [_d(1.0), _d(9.0, seq=2)])["ok"]
    assert not compare_decisions(x86, [_d(1.0), _d(9.0, seq=1, status="preliminary")])["ok"]
    assert not compare_decisions(x86, [_d(1.0)])["ok"]
    drift = compare_decisions(x86, [_d(1.0, conf=0.9 + 2 * CONFIDENCE_TOL), _d(9.0, seq=1)])
    assert drift["same_sequence"] and not drift["ok"]


def test_wheel_record_lines_are_pip_s_format():
    data = b"abc"
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    assert _record_line("e2e/p01.abi3.so", data) == f"e2e/p01.abi3.so,sha256={digest},3"


def test_a_wheel_of_the_same_files_is_the_same_bytes_with_no_build_time_in_it(tmp_path):
    files = {"e2e/p01.abi3.so": b"\x7fELF", "e2e/__init__.py": b"", "x-1.dist-info/METADATA": b"Name: x\n"}
    a = write_wheel(tmp_path / "a.whl", files, "x-1.dist-info")
    b = write_wheel(tmp_path / "b.whl", dict(reversed(files.items())), "x-1.dist-info")
    assert a.read_bytes() == b.read_bytes()
    with zipfile.ZipFile(a) as z:
        assert {i.date_time for i in z.infolist()} == {WHEEL_DATE}
        assert z.namelist()[-1] == "x-1.dist-info/RECORD"
        record = z.read("x-1.dist-info/RECORD").decode().splitlines()
    assert _record_line("e2e/p01.abi3.so", b"\x7fELF") in record and "x-1.dist-info/RECORD,," in record


def test_class_agreement_takes_the_first_or_final_decision_of_each_capture_both_runs_decided():
    int8 = [_d(1.0, status="preliminary"), _d(1.0, "Drink", status="revised"), _d(9.0, "Drink"), _d(20.0)]
    fp32 = [_d(1.0, "Drink"), _d(9.0, "Other"), _d(30.0)]
    assert class_agreement(int8, fp32, "last") == {"captures": 2, "same_class": 1, "agreement": 0.5}
    assert class_agreement(int8, fp32, "first") == {"captures": 2, "same_class": 0, "agreement": 0.0}
    assert class_agreement([], fp32)["agreement"] is None


@pytest.fixture(scope="module")
def vehicle():
    from edge_runtime.canbus.e2e import E2EProtector
    from edge_runtime.wearable.alerts import load_vehicle_dbc

    db = load_vehicle_dbc()
    alert = next(m for m in db.messages if "TimeSinceTrigger" in [s.name for s in m.signals])

    def frames(*alerts):
        """Each alert (TimeSinceTrigger, Class) as a protected frame at 0.1 s steps."""
        p = E2EProtector()
        out = []
        for i, (since_ms, cls) in enumerate(alerts):
            m = p.protect(alert, {"Status": 0, "Class": cls, "Confidence": 0.5, "TimeSinceTrigger": since_ms,
                                  "AlertSeq": i})
            m.timestamp = 0.1 * i
            out.append(m)
        return out

    return db, frames


def test_can_frames_may_differ_only_in_the_measured_time_since_trigger(vehicle):
    db, frames = vehicle
    x86 = frames((6001, 0), (6050, 1))
    r = compare_can(x86, frames((6001, 0), (6093, 1)), db)
    assert r["ok"] and r["identical"] == 1 and r["differ_only_in_" + "_".join(CAN_MEASURED)] == 1
    assert r["e2e_errors_x86"] == r["e2e_errors_aarch64"] == 0


def test_can_frames_with_another_class_a_missing_frame_or_a_bad_crc_disagree(vehicle):
    db, frames = vehicle
    x86 = frames((6001, 0), (6050, 1))
    other = compare_can(x86, frames((6001, 0), (6050, 2)), db)
    assert not other["ok"] and other["first_other_difference"]["frame"] == 1
    assert not compare_can(x86, frames((6001, 0)), db)["ok"]
    bad = frames((6001, 0), (6050, 1))
    bad[1].data[0] ^= 0xFF  # the CRC byte: a frame no receiver would take
    r = compare_can(x86, bad, db)
    assert not r["ok"] and r["e2e_errors_aarch64"] == 1 and r["first_other_difference"] is None


def _report(ok_replay: bool) -> dict:
    rep = {"decisions": compare_decisions([_d(1.0)], [_d(1.0)] if ok_replay else [_d(1.0, "Drink")]),
           "can": {"frames_x86": 3, "frames_aarch64": 3, "identical": 3, "differ_only_in_" + "_".join(CAN_MEASURED): 0,
                   "first_other_difference": None, "e2e_errors_x86": 0, "e2e_errors_aarch64": 0, "ok": True},
           "compute_us_median": {"x86_64": 40.0, "aarch64": 30000.0}, "wall_s": {"x86_64": 0.3, "aarch64": 9.0}}
    rep["ok"] = rep["decisions"]["ok"]
    return {"command": "python -m export.aarch64 --work W", "machine": "x86_64", "emulator": "qemu 7.2",
            "proot": "proot 5.1.0", "root": {"suite": "bookworm"}, "ok": ok_replay,
            "e2e_wheel": {"name": "w.whl", "sha256": "ab", "sdist_sha256": "cd", "in_bundle": True},
            "onnxruntime": {"x86_64": "1.32.0", "aarch64": "1.22.1"},
            "install_wall_s": {"aarch64_emulated": 100.0, "x86_64": 10.0}, "drive": {"minutes": 5, "seed": 1},
            "replays": {"int8_early": rep},
            "int8_fp32_class_agreement_aarch64": {"early": {"last": class_agreement([_d(1.0)], [_d(1.0)])}},
            "models": {"convlstm-int8": {"loaded": True, "max_abs": 1e-7, "argmax_agree": 1.0, "ok": True}},
            "onnxruntime_also_aarch64": {"1.22.1": {"ok": True, "models": {}},
                                         "1.32.0": {"ok": False, "error": "exit 255: terminated with signal 11"}},
            "model_p50_us_batch1": {"x86_64": {"convlstm-int8": 40.0}, "aarch64_emulated": {"convlstm-int8": 3e4}},
            "e2e_crc": {"x86_64": {"calculate_crc8": 1}, "aarch64": {"calculate_crc8": 1}, "ok": True}}


def test_the_markdown_report_says_which_replay_disagrees_and_that_emulated_time_is_no_speed_claim():
    assert "**DISAGREE**" not in markdown(_report(True))
    md = markdown(_report(False))
    row = next(line for line in md.splitlines() if line.startswith("| int8_early |"))
    assert "**DISAGREE**" in md and row.endswith("**NO** |")
    assert "NOT a speed claim" in md and "1/1 (100.0 %)" in md
    assert "- onnxruntime 1.32.0: **fails**: exit 255: terminated with signal 11" in md
    assert "- onnxruntime 1.22.1: every model within tolerance: **yes**" in md


def test_missing_tools_are_one_line_naming_the_debian_packages(monkeypatch, tmp_path, capsys):
    monkeypatch.setattr(aarch64.shutil, "which", lambda prog: None if prog in ("proot", "mmdebstrap") else prog)
    assert aarch64.main(["--work", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.endswith("apt-get install mmdebstrap proot")
    assert aarch64.main(["--work", str(tmp_path), "--e2e-wheel", str(tmp_path / "w")]) == 2
    assert capsys.readouterr().err.strip().endswith("apt-get install mmdebstrap")
    assert not any(tmp_path.iterdir())


@pytest.mark.parametrize("args, named", [(["--minutes", "0"], "--minutes"), (["--onnxruntime", "latest"], "--onnxruntime"),
                                         (["--report-dir", "FILE"], "--report-dir"), (["--work", "FILE"], "--work")])
def test_bad_arguments_are_refused_in_one_line_before_any_work(tmp_path, capsys, args, named):
    (tmp_path / "FILE").write_text("")
    args = [str(tmp_path / "FILE") if a == "FILE" else a for a in args]
    assert aarch64.main(["--work", str(tmp_path / "w"), *args] if "--work" not in args else args) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and named in err and not (tmp_path / "w").exists()


def test_the_committed_aarch64_report_is_of_the_pinned_onnxruntime_and_agrees():
    """The pin (and the tested versions the bundle's install notes give) changes only with a new make aarch64-check run."""
    import json

    from support import REPO_ROOT

    from export.bundle import ONNXRUNTIME_PINS, ONNXRUNTIME_TESTED

    report = json.loads((REPO_ROOT / "reports" / "box" / "aarch64.json").read_text())
    pinned = ONNXRUNTIME_PINS["aarch64"].split("==")[1]
    assert report["ok"] and report["onnxruntime"]["aarch64"] == pinned
    assert set(report["onnxruntime_also_aarch64"]) == set(aarch64.ONNXRUNTIME_ALSO) - {pinned}
    assert all(v in ONNXRUNTIME_TESTED["aarch64"] for v in [pinned, *report["onnxruntime_also_aarch64"]])
