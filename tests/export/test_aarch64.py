"""export/aarch64.py's own logic (the emulated run itself is `make aarch64-check`, not a test)."""
import base64
import hashlib

from export.aarch64 import CONFIDENCE_TOL, _record_line, compare_decisions


def _d(t, label="Phone", conf=0.9, alerted=True, seq=0):
    return {"t_trigger_s": t, "t_alert_s": t + 6, "label": label, "status": "alert" if alerted else "not_alerted",
            "alerted": alerted, "alert_seq": seq if alerted else None, "confidence": conf}


def test_same_decisions_within_the_confidence_tolerance_agree():
    x86 = [_d(1.0), _d(9.0, "Other", 0.6, False)]
    arm = [_d(1.0, conf=0.9 + CONFIDENCE_TOL / 2), _d(9.0, "Other", 0.6, False)]
    r = compare_decisions(x86, arm)
    assert r["ok"] and r["same_sequence"] and r["alerts_x86"] == r["alerts_aarch64"] == 1


def test_another_class_a_missing_decision_or_a_confidence_drift_disagree():
    x86 = [_d(1.0), _d(9.0)]
    assert not compare_decisions(x86, [_d(1.0), _d(9.0, "Texting")])["ok"]
    assert not compare_decisions(x86, [_d(1.0)])["ok"]
    drift = compare_decisions(x86, [_d(1.0, conf=0.9 + 2 * CONFIDENCE_TOL), _d(9.0)])
    assert drift["same_sequence"] and not drift["ok"]


def test_wheel_record_lines_are_pip_s_format():
    data = b"abc"
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    assert _record_line("e2e/p01.abi3.so", data) == f"e2e/p01.abi3.so,sha256={digest},3"


def test_label_agreement_counts_the_captures_both_runs_classified():
    from export.aarch64 import label_agreement

    r = label_agreement([_d(1.0), _d(9.0, "Drink"), _d(20.0)], [_d(1.0), _d(9.0, "Other"), _d(30.0)])
    assert r == {"captures": 2, "same_class": 1, "agreement": 0.5}
