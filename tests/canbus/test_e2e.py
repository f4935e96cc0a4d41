"""canbus/e2e.py: AUTOSAR E2E Profile 1 on a DBC message, sender and receiver."""
import can
import e2e.p01 as p01

from edge_runtime.canbus.dbc import load_dbc
from edge_runtime.canbus.e2e import E2EChecker, E2EProtector
from edge_runtime.core.manifest import ASSETS_DIR

SIGNALS = {"Status": "alert", "Class": "Phone", "Confidence": 0.87, "TimeSinceTrigger": 753, "AlertSeq": 0}


def test_e2e_counter_crc_repeat_loss():
    db = load_dbc(ASSETS_DIR / "vehicle_alerts.dbc")
    alert = db.get_message_by_name("DISTRACTION_ALERT")
    protector, chk = E2EProtector(), E2EChecker(db)
    msgs = [protector.protect(alert, SIGNALS) for _ in range(20)]
    counters = [m.data[1] & 0x0F for m in msgs]
    assert counters[:16] == list(range(15)) + [0]  # Profile 1: 0..14 then wraps
    assert chk.check(msgs[0]).status == "initial"
    assert [chk.check(m).status for m in msgs[1:16]] == ["ok"] * 15
    assert chk.check(msgs[15]).status == "repeated"
    res = chk.check(msgs[18])
    assert (res.status, res.lost) == ("lost", 2)
    bad = can.Message(arbitration_id=0x3A0, data=bytearray(msgs[19].data), is_extended_id=False)
    bad.data[5] ^= 0x10
    assert chk.check(bad).status == "wrong_crc"
    # masquerading: a valid alert payload under the status ID fails (different data ID)
    fake = can.Message(arbitration_id=0x3A1, data=msgs[19].data, is_extended_id=False)
    assert chk.check(fake).status == "wrong_crc"
    assert chk.errors == 1 + 2 + 2


def test_frames_the_dbc_does_not_describe_are_refused_before_the_crc():
    db = load_dbc(ASSETS_DIR / "vehicle_alerts.dbc")
    alert = db.get_message_by_name("DISTRACTION_ALERT")
    chk = E2EChecker(db)
    good = E2EProtector().protect(alert, SIGNALS)

    def variant(**kw):
        fields = dict(arbitration_id=good.arbitration_id, data=bytes(good.data), is_extended_id=False)
        return can.Message(**{**fields, **kw}, check=False)

    # a 2-byte frame whose CRC is valid for its 2 bytes: the check alone would pass it
    short = bytearray(2)
    short[1] = 1
    p01.e2e_p01_protect(short, 0x3A0, length=2, increment_counter=False)
    cases = {
        "2 data bytes, the DBC says 8": variant(data=bytes(short)),
        "extended identifier": variant(is_extended_id=True),
        "remote frame": variant(is_remote_frame=True),
        "error frame": variant(is_error_frame=True),
    }
    for reason, msg in cases.items():
        res = chk.check(msg)
        assert (res.status, res.reason, res.valid) == ("bad_frame", reason, False)
    assert chk.check(good).status == "initial" and chk.errors == 4


def _reference_protect(message, signals, counter):
    """What protect() computed before its payload cache: cantools with the counter, then the CRC."""
    from edge_runtime.canbus.e2e import e2e_data_id

    data = bytearray(message.encode(dict(signals, E2E_CRC=0, AliveCounter=counter), strict=True))
    p01.e2e_p01_protect(data, e2e_data_id(message), length=len(data), increment_counter=False)
    return bytes(data)


def _random_signals(message, rng):
    out = {}
    for s in message.signals:
        if s.name in ("E2E_CRC", "AliveCounter"):
            continue
        if s.choices:
            out[s.name] = str(list(s.choices.values())[int(rng.integers(len(s.choices)))])
        else:
            lo, hi = s.minimum if s.minimum is not None else 0, s.maximum if s.maximum is not None else 1
            v = lo + (hi - lo) * float(rng.random())
            out[s.name] = v if s.is_float or s.scale != 1 else int(round(v))
    return out


def test_cached_payloads_give_cantools_bytes_for_every_message_counter_and_repeat():
    import cantools
    import numpy as np
    import pytest

    rng = np.random.default_rng(0)
    for dbc in ("vehicle_alerts.dbc", "robot_link.dbc"):
        db = load_dbc(ASSETS_DIR / dbc)
        protector = E2EProtector()
        for message in db.messages:
            sets = [_random_signals(message, rng) for _ in range(3)]
            for k in range(40):  # each set again and again: cached after its first frame
                signals = sets[k % 3]
                counter = protector._counters.get(message.frame_id, 0)
                got = bytes(protector.protect(message, signals).data)
                assert got == _reference_protect(message, signals, counter), (dbc, message.name, k)
        bad = dict(_random_signals(db.messages[0], rng))
        bad[next(iter(bad))] = 1e12  # out of the DBC's range: refused every time, never cached
        for _ in range(2):
            with pytest.raises(cantools.database.EncodeError):
                protector.protect(db.messages[0], bad)
