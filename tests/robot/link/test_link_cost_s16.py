"""The CAN link's per-frame cost (session 16, perf5) without a changed result: the decoder (range checks
made once per message, decoded frames remembered by their bytes), the state assembler (one RobotState per
completed state instead of a ``replace`` per frame) and ``check_state`` (plain floats instead of numpy)
pinned to the forms they replaced, on random and edge inputs, byte for byte and bit for bit."""
from __future__ import annotations

import math
from dataclasses import fields, replace

import numpy as np

from edge_runtime.canbus.e2e import E2EChecker
from edge_runtime.robot.link.protocol import (
    DECODED_CACHE,
    MAX_JOINT_RAD,
    N_JOINTS,
    POSITION_LIMIT_M,
    CanStateAssembler,
    RobotCanCodec,
    blank_state,
    check_state,
)


# -- the forms replaced, as they were on main 4507d39 ------------------------------------------------
def _old_in_range(signal, value) -> bool:
    if signal.choices:
        return not isinstance(value, (int, float))
    lo, hi = signal.minimum, signal.maximum
    slack = abs(signal.scale) / 2
    return (lo is None or value >= lo - slack) and (hi is None or value <= hi + slack)


def _old_decode(checker: E2EChecker, by_id: dict, msg):
    res = checker.check(msg)
    if not res.valid:
        return res.status, "", None
    message = by_id[msg.arbitration_id]
    sig = message.decode(bytes(msg.data), decode_choices=True)
    if not all(_old_in_range(s, sig[s.name]) for s in message.signals):
        return "out_of_range", message.name, None
    return res.status, message.name, sig


class _OldAssembler:
    def __init__(self):
        self._s = blank_state()
        self._joints = np.zeros(N_JOINTS)

    def feed(self, name, sig, t_s):
        s = self._s
        if name == "ROBOT_EE_POSITION":
            self._s = replace(s, ee_position_m=np.array([sig["X"], sig["Y"], sig["Z"]]) / 1000.0)
        elif name == "ROBOT_EE_ORIENT":
            self._s = replace(s, pitch_rad=sig["Pitch"], yaw_rad=sig["Yaw"], ee_speed_mps=sig["Speed"] / 1000.0)
        elif name.startswith("ROBOT_JOINTS_"):
            for k, v in sig.items():
                if k.startswith("J") and k[1:].isdigit():
                    self._joints[int(k[1:])] = v
        elif name == "ROBOT_ALARM_STATE":
            self._s = replace(s, light=str(sig["Light"]), tone_hz=float(sig["ToneFreq"]),
                              tone_db=float(sig["ToneLevel"]))
        elif name == "ROBOT_COUNTERS":
            self._s = replace(s, counters={"watchdog_trips": sig["WatchdogTrips"], "rx_valid": sig["RxValid"],
                                           "integrity_errors": sig["IntegrityErrors"], "refused": sig["Refused"]})
        elif name == "ROBOT_STATUS":
            self._s = replace(s, t_s=t_s, joint_positions_rad=self._joints.copy(), mode=str(sig["Mode"]),
                              watchdog=bool(sig["Watchdog"]), moving=bool(sig["Moving"]),
                              at_target=bool(sig["AtTarget"]), last_command=str(sig["LastCommand"]),
                              last_result=str(sig["LastResult"]), last_seq=int(sig["LastSeq"]),
                              robot_time_s=sig["RobotTime"] / 1000.0)
            return self._s
        return None


def _old_check_state(st):
    p = np.asarray(st.ee_position_m, dtype=float)
    q = np.asarray(st.joint_positions_rad, dtype=float)
    if p.shape != (3,) or not np.isfinite(p).all() or np.abs(p).max() > POSITION_LIMIT_M:
        return "ee_position_m"
    if q.shape != (N_JOINTS,) or not np.isfinite(q).all() or np.abs(q).max() > MAX_JOINT_RAD:
        return "joint_positions_rad"
    return check_state(replace(st, ee_position_m=np.zeros(3), joint_positions_rad=np.zeros(N_JOINTS)))


def _same(a, b) -> bool:
    """Bit for bit: equal values of the same types; arrays with the same dtype, shape and bytes."""
    if isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        return (type(a) is type(b) and a.dtype == b.dtype and a.shape == b.shape and a.tobytes() == b.tobytes())
    if isinstance(a, dict) and isinstance(b, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k]) for k in a)
    if isinstance(a, float) and isinstance(b, float) and math.isnan(a):
        return math.isnan(b)
    return type(a) is type(b) and a == b and str(a) == str(b)


def _frames(rng, n_cycles: int):
    """The robot's frames (valid E2E) with random bytes, so that some signals are outside the DBC's
    ranges or unnamed, interleaved with repeats of earlier frames and corrupted ones."""
    tx = RobotCanCodec()
    db = tx.db
    msgs = [m for m in db.messages if m.name.startswith("ROBOT_") and m.senders != ["Runtime"]]
    out, seen = [], []
    for _ in range(n_cycles):
        if rng.random() < 0.6:  # a real state, some of its values repeated from the last
            st = replace(blank_state(), ee_position_m=rng.uniform(-1, 1, 3).round(int(rng.integers(1, 4))),
                         joint_positions_rad=rng.uniform(-3, 3, N_JOINTS).round(1), pitch_rad=float(rng.uniform(-1, 1)),
                         yaw_rad=float(rng.uniform(-3, 3)), ee_speed_mps=float(rng.uniform(0, 2)),
                         tone_db=float(rng.uniform(0, 100)),
                         mode=str(rng.choice(["stopped", "run", "retract"])), light=str(rng.choice(["off", "red"])),
                         tone_hz=float(rng.integers(0, 3000)), last_seq=int(rng.integers(0, 65536)),
                         robot_time_s=float(rng.uniform(0, 60)))
            out += tx.state_frames(st) + [tx.counters_frame({"rx_valid": int(rng.integers(0, 9))})]
            continue
        for m in msgs:
            data = bytearray(rng.integers(0, 256, m.length, dtype=np.uint8).tobytes())
            signals = m.decode(bytes(data), decode_choices=False)
            signals = {k: v for k, v in signals.items() if k not in ("E2E_CRC", "AliveCounter")}
            try:
                frame = tx._e2e.protect(m, signals)
            except Exception:  # noqa: BLE001 - a raw value cantools will not encode: send its bytes re-protected
                frame = tx._e2e.protect(m, {s.name: (s.minimum or 0) for s in m.signals
                                             if s.name not in ("E2E_CRC", "AliveCounter")})
            out.append(frame)
            seen.append(frame)
            if rng.random() < 0.3:
                out.append(seen[int(rng.integers(len(seen)))])  # a repeat: same bytes, a counter out of order
            if rng.random() < 0.05:
                bad = frame.__copy__()
                bad.data = bytearray(frame.data)
                bad.data[-1] ^= 0x10
                out.append(bad)
    return out


def test_decode_and_assembly_match_the_old_ones_frame_for_frame():
    rng = np.random.default_rng(5)
    new = RobotCanCodec()
    old_checker = E2EChecker(db=new.db)
    by_id = {m.frame_id: m for m in new.db.messages}
    new_asm, old_asm = CanStateAssembler(), _OldAssembler()
    statuses, n_states = set(), 0
    frames = _frames(rng, 400) + _frames(rng, 40) * 3  # more frames than the cache holds; then repeats
    assert len(frames) > DECODED_CACHE
    for i, msg in enumerate(frames):
        want = _old_decode(old_checker, by_id, msg)
        got = new.decode(msg)
        assert got[:2] == want[:2] and _same(got[2], want[2]), (i, got, want)
        statuses.add(got[0])
        if got[2] is not None:
            got[2]["X"] = "a caller may change its copy"  # the remembered decoding is not changed by it
            s_new = new_asm.feed(got[1], want[2], i * 0.01)
            s_old = old_asm.feed(want[1], want[2], i * 0.01)
            assert (s_new is None) == (s_old is None)
            if s_new is not None:
                n_states += 1
                for f in fields(s_old):
                    assert _same(getattr(s_new, f.name), getattr(s_old, f.name)), f.name
    assert {"ok", "out_of_range", "wrong_crc", "repeated"} <= statuses and n_states > 50
    assert new.checker.counts == old_checker.counts


def test_check_state_matches_the_numpy_form_on_edge_values():
    rng = np.random.default_rng(7)
    edge = [0.0, -0.0, math.nan, math.inf, -math.inf, POSITION_LIMIT_M, -POSITION_LIMIT_M, MAX_JOINT_RAD,
            -MAX_JOINT_RAD, np.nextafter(POSITION_LIMIT_M, 9), np.nextafter(MAX_JOINT_RAD, 9), 1e300, 5e-324]
    base = replace(blank_state(1.0), ee_position_m=np.array([0.4, 0.3, 0.5]),
                   joint_positions_rad=np.linspace(-1.0, 1.0, N_JOINTS))
    cases = []
    for _ in range(3000):
        p = rng.uniform(-4, 4, 3)
        q = rng.uniform(-7, 7, N_JOINTS)
        for a in (p, q):
            for _k in range(int(rng.integers(0, 3))):
                a[rng.integers(a.size)] = edge[rng.integers(len(edge))]
        cases.append(replace(base, ee_position_m=p, joint_positions_rad=q))
    cases += [replace(base, ee_position_m=np.zeros(4)), replace(base, joint_positions_rad=np.zeros(6)),
              replace(base, ee_position_m=[0.1, 0.2, 0.3]), replace(base, joint_positions_rad=np.zeros((7, 1))),
              replace(base, ee_position_m=np.array([1, 2, 3], dtype=np.int64)),
              replace(base, ee_position_m=np.array([0.1, 0.2, 0.3], dtype=np.float32))]
    results = set()
    for st in cases:
        want = _old_check_state(st)
        assert check_state(st) == want, st
        results.add(want)
    assert {None, "ee_position_m", "joint_positions_rad"} <= results
