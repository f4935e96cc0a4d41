"""Session 18 (perfA): the CAN link's receive path without a changed result. The E2E check reads the frame's
buffer in place and returns one shared, frozen result per plain status: pinned to session 17's copying form
(status, lost frames, reason and counts, frame for frame) on valid, repeated, lost, corrupted, mis-shaped and
unknown frames. The link's assembler reads the codec's remembered decodings without changing them, and makes
its state with RobotState.from_fields, the constructor's object. The robot loop takes a state report once: it
follows every new one and keeps what it had while the report is unchanged or unusable."""
from __future__ import annotations

import dataclasses
from dataclasses import replace

import can
import e2e.p01 as p01
import numpy as np
import pytest
from support.robot import FakeLink

from edge_runtime.canbus.e2e import COUNTER_MAX, E2EChecker, E2EResult, frame_fault
from edge_runtime.robot.link.protocol import RobotCanCodec, RobotState, blank_state
from edge_runtime.robot.loop import RobotLoop


class _Session17Checker(E2EChecker):
    """E2EChecker._check as session 17 left it: a copy of the frame's bytes and a new result per frame."""

    def _check(self, msg):
        message = self._messages.get(msg.arbitration_id)
        if message is None:
            return E2EResult("unknown_id")
        fault = frame_fault(msg, message)
        if fault is not None:
            return E2EResult("bad_frame", reason=fault)
        data = bytearray(msg.data)
        if not p01.e2e_p01_check(data, self._ids[msg.arbitration_id], length=len(data)):
            return E2EResult("wrong_crc")
        counter = data[1] & 0x0F
        if counter > COUNTER_MAX:
            return E2EResult("wrong_crc")
        last = self._last.get(msg.arbitration_id)
        self._last[msg.arbitration_id] = counter
        if last is None:
            return E2EResult("initial")
        delta = (counter - last) % (COUNTER_MAX + 1)
        if delta == 0:
            return E2EResult("repeated")
        if delta == 1:
            return E2EResult("ok")
        return E2EResult("lost", lost=delta - 1)


def _frames(rng, n: int):
    """The arm's state frames (valid E2E), with repeats, skipped counters, flipped bits, a counter of 15,
    error, remote, extended and short frames, and unknown identifiers mixed in."""
    tx = RobotCanCodec()
    out = []
    for k in range(n):
        st = replace(blank_state(), ee_position_m=rng.uniform(-1, 1, 3), robot_time_s=k * 0.01)
        frames = tx.state_frames(st)
        for f in frames:
            r = rng.random()
            if r < 0.05:
                out.append(f)  # sent twice: a repeated counter
            elif r < 0.10:
                tx._e2e.skip(f.arbitration_id, int(rng.integers(1, 14)))  # frames lost before the next
            elif r < 0.15:
                bad = can.Message(arbitration_id=f.arbitration_id, data=bytearray(f.data), is_extended_id=False)
                bad.data[int(rng.integers(8))] ^= 1 << int(rng.integers(8))
                f = bad
            elif r < 0.17:
                bad = can.Message(arbitration_id=f.arbitration_id, data=bytearray(f.data), is_extended_id=False)
                bad.data[1] |= 0x0F  # counter 15: never valid
                f = bad
            elif r < 0.19:
                f = can.Message(arbitration_id=f.arbitration_id, data=bytearray(f.data), **{
                    "is_extended_id": False, **[{"is_error_frame": True}, {"is_remote_frame": True},
                                                {"is_extended_id": True}, {}][int(rng.integers(4))]})
                if not (f.is_error_frame or f.is_remote_frame or f.is_extended_id):
                    f.data = f.data[:5]
            elif r < 0.20:
                f = can.Message(arbitration_id=0x7FF, data=bytearray(8), is_extended_id=False)
            elif r < 0.21:  # the same frame with its data as bytes (python-can makes a bytearray; a caller may not)
                f = can.Message(arbitration_id=f.arbitration_id, data=bytearray(f.data), is_extended_id=False)
                f.data = bytes(f.data)
            out.append(f)
    return out


def test_check_matches_session17s_frame_for_frame():
    rng = np.random.default_rng(18)
    db = RobotCanCodec().db
    new, old = E2EChecker(db=db), _Session17Checker(db=db)
    seen = set()
    for i, msg in enumerate(_frames(rng, 600)):
        data = bytes(msg.data)
        got, want = new.check(msg), old.check(msg)
        assert (got.status, got.lost, got.reason, got.valid) == (want.status, want.lost, want.reason, want.valid), i
        assert bytes(msg.data) == data  # the check reads the frame, never changes it
        seen.add(got.status)
    assert seen == {"ok", "initial", "repeated", "lost", "wrong_crc", "bad_frame", "unknown_id"}
    assert new.counts == old.counts and new.errors == old.errors


def test_a_shared_result_cannot_be_changed():
    checker = E2EChecker(db=RobotCanCodec().db)
    res = checker.check(can.Message(arbitration_id=0x7FF, data=bytearray(8), is_extended_id=False))
    assert res.status == "unknown_id"
    with pytest.raises(dataclasses.FrozenInstanceError):
        res.status = "ok"


def test_the_loop_follows_each_new_state_report_and_keeps_the_last_usable_one():
    link = FakeLink(start=(0.4, 0.2, 0.6))
    loop = RobotLoop(link, clock=lambda: 0.0)
    loop.tick()
    assert loop.effector_m().tolist() == [0.4, 0.2, 0.6]
    link._state = replace(link._state, ee_position_m=np.array([0.5, 0.1, 0.7]), yaw_rad=0.25)
    loop.tick()
    loop.tick()  # the same report again
    assert loop.effector_m().tolist() == [0.5, 0.1, 0.7] and loop._last_yaw == 0.25
    link._state = replace(link._state, ee_position_m=np.array([np.nan, 0.1, 0.7]), yaw_rad=np.inf,
                          joint_positions_rad=np.full(7, np.nan))
    loop.tick()
    assert loop.effector_m().tolist() == [0.5, 0.1, 0.7]  # a non-finite position is not taken
    assert loop._last_yaw is None and loop._last_q is None  # nor a non-finite yaw or joint angles
    link._state = replace(link._state, ee_position_m=np.array([0.3, 0.3, 0.3]), yaw_rad=-1.0,
                          joint_positions_rad=np.zeros(7))
    loop.tick()
    assert loop.effector_m().tolist() == [0.3, 0.3, 0.3] and loop._last_yaw == -1.0
    assert loop._last_q.tolist() == [0.0] * 7


class _ListBus:
    def __init__(self, frames):
        self.rx = list(frames)

    def recv(self, timeout=None):
        return self.rx.pop(0) if self.rx else None

    def send(self, msg, timeout=None):
        pass


def test_the_link_reads_the_shared_decodings_without_changing_them():
    from edge_runtime.robot.link.base import LinkConfig
    from edge_runtime.robot.link.can import CanRobotLink

    rng = np.random.default_rng(4)
    tx = RobotCanCodec()
    frames = [f for k in range(60) for f in tx.state_frames(
        replace(blank_state(), ee_position_m=rng.uniform(-1, 1, 3).round(1), robot_time_s=k * 0.01))]
    t = [0.0]
    link = CanRobotLink(bus=_ListBus(frames), config=LinkConfig(heartbeat_period_s=None), clock=lambda: t[0])
    assert link.poll() is not None and link.stats.states == 60 and link.stats.integrity_errors == 0
    codec = link.codec
    for (frame_id, data), (name, sig) in codec._decoded.items():
        message = codec._by_id[frame_id]
        assert name == message.name and sig == message.decode(data, decode_choices=True)
        status, got_name, got = codec.decode(can.Message(arbitration_id=frame_id, data=bytearray(data),
                                                         is_extended_id=False))
        assert got_name == name and got == sig and got is not sig  # decode() hands out a copy


def test_from_fields_makes_the_state_the_constructor_makes():
    rng = np.random.default_rng(13)
    for _ in range(50):
        f = vars(replace(blank_state(float(rng.uniform(0, 9))), ee_position_m=rng.uniform(-1, 1, 3),
                         joint_positions_rad=rng.uniform(-3, 3, 7), mode=str(rng.choice(["run", "stopped"])),
                         last_seq=int(rng.integers(65536)), counters={"rx_valid": int(rng.integers(9))})).copy()
        made, want = RobotState.from_fields(f), RobotState(**f)
        assert type(made) is RobotState and list(vars(made).items()) == list(vars(want).items())
        assert repr(made) == repr(want)
        with pytest.raises(dataclasses.FrozenInstanceError):
            made.mode = "run"


def test_command_frames_skip_the_payload_cache_with_the_same_bytes():
    rng = np.random.default_rng(19)
    new, old = RobotCanCodec(), RobotCanCodec()
    old._command = old.encode  # session 17: every frame through the payload cache
    hb = new.heartbeat_frame("running", 1.0)
    for seq in range(1, 400):
        p = rng.uniform(-1, 1, 3).round(int(rng.integers(1, 4)))  # positions that repeat, as waypoints do
        cases = [("target_frames", seq, p, float(rng.uniform(-1.5, 1.5)), float(rng.uniform(-3, 3)),
                  bool(rng.random() < 0.5)),
                 ("mode_frame", seq, str(rng.choice(["stop", "resume"]))),
                 ("alarm_frame", seq, str(rng.choice(["off", "red"])), float(rng.integers(0, 3000)),
                  float(rng.uniform(0, 100))),
                 ("speed_frame", seq % 20, float(rng.uniform(0, 1.5)))]
        for name, *args in cases:
            got, want = getattr(new, name)(*args), getattr(old, name)(*args)
            for g, w in zip(got if isinstance(got, list) else [got], want if isinstance(want, list) else [want]):
                assert (g.arbitration_id, bytes(g.data), g.is_extended_id) == \
                       (w.arbitration_id, bytes(w.data), w.is_extended_id), (name, args)
    assert list(new._e2e._payloads) == [(hb.arbitration_id, ("State", "running"), ("Uptime_s", 1))]
    with pytest.raises(Exception, match="SpeedLimit"):  # cantools' strict check still refuses what it refused
        new._command("ROBOT_SPEED_CMD", Seq=1, SpeedLimit=1e9)
