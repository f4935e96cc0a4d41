"""edge_runtime.robot.link.protocol: the wire contract both ends share."""
from __future__ import annotations

import math
from dataclasses import replace

import can
import e2e.p01 as p01
import numpy as np
import pytest

from edge_runtime.canbus.e2e import e2e_data_id
from edge_runtime.robot.link.protocol import (
    CanStateAssembler,
    RobotCanCodec,
    blank_state,
    check_alarm,
    check_speed,
    check_state,
    check_target,
    mav_to_robot,
    next_seq,
    pack_status,
    robot_to_mav,
    tool_pitch_yaw,
    tool_quaternion,
    unpack_status,
    wrap_angle,
)
from firmware_sim.robot.controller import SimulatedRobot


def test_codec_round_trips_a_state_through_the_dbc_with_e2e():
    tx, rx = RobotCanCodec(), RobotCanCodec()
    with SimulatedRobot("can") as sim:
        st = sim.controller.snapshot()
    asm = CanStateAssembler()
    got = None
    for frame in tx.state_frames(st):
        status, name, sig = rx.decode(frame)
        assert sig is not None, status
        got = asm.feed(name, sig, 1.0) or got
    assert got is not None
    assert np.allclose(got.ee_position_m, st.ee_position_m, atol=1e-4)
    assert np.allclose(got.joint_positions_rad, st.joint_positions_rad, atol=2e-4)
    assert got.mode == st.mode and got.light == st.light
    corrupted = tx.state_frames(st)[0]
    corrupted.data[3] ^= 0x40
    assert rx.decode(corrupted)[2] is None and rx.checker.counts["wrong_crc"] == 1


def test_mavlink_frame_and_status_conventions():
    p = np.array([0.3, -0.2, 0.9])
    assert np.allclose(mav_to_robot(*robot_to_mav(p)), p)
    assert robot_to_mav((0, 0, 1))[0] == 1 and robot_to_mav((0, 1, 0))[2] == -1  # forward is x, up is -z
    assert tool_pitch_yaw(tool_quaternion(-0.7, 2.9)) == pytest.approx((-0.7, 2.9))
    st = dict(mode="retract", watchdog=True, moving=True, at_target=False, last_result="refused",
              last_command="move", last_seq=4321)
    assert unpack_status(pack_status(**st)) == st


def test_sequence_numbers_wrap_to_1_and_angles_to_plus_minus_pi():
    assert next_seq(0) == 1 and next_seq(41) == 42 and next_seq(65535) == 1  # 0 means "none"
    assert wrap_angle(-math.pi) == math.pi and wrap_angle(3 * math.pi / 2) == pytest.approx(-math.pi / 2)


def test_targets_and_alarms_are_checked_field_by_field():
    p, pitch, yaw = check_target([0.1, 0.2, 0.3], math.pi / 2 + 1e-12, 2 * math.pi + 0.5)
    assert p.tolist() == [0.1, 0.2, 0.3] and pitch == math.pi / 2 and yaw == pytest.approx(0.5)
    for args, field in ((((0.0, 0.0), 0.0, 0.0), "position_m"), (((4.0, 0.0, 0.0), 0.0, 0.0), "outside"),
                        (((0.0, 0.0, 0.0), 1.7, 0.0), "pitch_rad"), (((0.0, 0.0, 0.0), 0.0, math.inf), "yaw_rad")):
        with pytest.raises(ValueError, match=field):
            check_target(*args)
    assert check_alarm("red", 2000, 70) == ("red", 2000.0, 70.0)
    for args, field in ((("blue", 0.0, 0.0), "light"), (("red", 30000.0, 0.0), "tone_hz"),
                        (("red", 0.0, -1.0), "tone_db")):
        with pytest.raises(ValueError, match=field):
            check_alarm(*args)


def test_a_speed_override_is_checked_and_round_trips_through_the_dbc():
    assert check_speed(0.25) == 0.25 and check_speed(0) == 0.0
    for bad in (-0.01, 1.6, math.nan, math.inf):
        with pytest.raises(ValueError, match="speed limit"):
            check_speed(bad)
    status, name, sig = RobotCanCodec().decode(RobotCanCodec().speed_frame(77, 0.3456))
    assert name == "ROBOT_SPEED_CMD" and sig["Seq"] == 77 and sig["SpeedLimit"] == pytest.approx(345.6)


def test_a_short_frame_with_a_valid_crc_is_refused_before_decoding():
    codec = RobotCanCodec()
    msg = codec.db.get_message_by_name("ROBOT_STATUS")
    data = bytearray(5)
    p01.e2e_p01_protect(data, e2e_data_id(msg), length=len(data), increment_counter=False)
    short = can.Message(arbitration_id=msg.frame_id, data=bytes(data), is_extended_id=False)
    assert codec.decode(short) == ("bad_frame", "", None)
    good = codec.status_frame(blank_state())
    assert codec.decode(can.Message(arbitration_id=good.arbitration_id, data=good.data,
                                    is_extended_id=True))[0] == "bad_frame"
    assert codec.decode(good)[2] is not None


def test_an_unnamed_enum_value_with_a_valid_crc_is_refused():
    codec = RobotCanCodec()
    good = codec.status_frame(blank_state())
    data = bytearray(good.data)
    data[1] = (data[1] & 0x0F) | 0xD0  # Mode 13: not stopped, run or retract
    msg = codec.db.get_message_by_name("ROBOT_STATUS")
    p01.e2e_p01_protect(data, e2e_data_id(msg), length=len(data), increment_counter=False)
    status, _, sig = codec.decode(can.Message(arbitration_id=msg.frame_id, data=bytes(data), is_extended_id=False))
    assert (status, sig) == ("out_of_range", None)


@pytest.mark.parametrize("field, value", [("ee_position_m", np.array([np.nan, 0.0, 0.5])),
                                          ("pitch_rad", float("inf")), ("light", "code nan"),
                                          ("joint_positions_rad", np.full(7, 1e30))])
def test_check_state_names_what_is_not_a_measurement(field, value):
    assert check_state(blank_state()) is None
    assert check_state(replace(blank_state(), **{field: value})) == field
