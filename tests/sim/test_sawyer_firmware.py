"""The controller's command line and its handling of damaged serial bytes."""
from __future__ import annotations

import io
import json
import math
import subprocess
import sys

import pytest

from edge_runtime.robot.link.protocol import make_mavlink
from firmware_sim.__main__ import main as firmware_main
from firmware_sim.devices.can_hub import CanHub
from firmware_sim.robot.controller import LinkFaults, SimulatedRobot


def sawyer_cli(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "firmware_sim", "sawyer", *args], capture_output=True, text=True,
                          timeout=timeout)


@pytest.mark.parametrize("args,words", [
    (["--link", "mavlink"], "--pty or --serial"),
    (["--link", "can"], "--can-port"),
    (["--link", "mavlink", "--pty", "--signing-key", "abc"], "--signing-key"),
    (["--link", "mavlink", "--serial", "/nonexistent/tty"], "/nonexistent/tty"),
    (["--link", "can", "--can-port", "70000"], "--can-port"),
    (["--link", "can", "--can-port", "1", "--can-interface", "nosuchbus"], "not allowed"),
    (["--link", "bluetooth"], "--link"),
])
def test_bad_input_is_one_line_and_exit_2(args, words, capsys):
    try:
        rc = firmware_main(["sawyer", *args])
    except SystemExit as e:  # argparse
        rc = e.code
    err = capsys.readouterr().err
    assert rc == 2
    assert len(err.strip().splitlines()) == 1 and words in err and "Traceback" not in err


@pytest.mark.slow
def test_a_controller_nobody_talks_to_trips_its_watchdog_and_reports_it(tmp_path):
    with CanHub(port=0) as hub:
        out = tmp_path / "sawyer.json"
        r = sawyer_cli("--link", "can", "--can-port", str(hub.port), "--duration", "0.6", "--rate-hz", "50",
                       "--json", str(out))
    assert r.returncode == 0, r.stderr
    assert r.stdout.splitlines()[0] == f"socketcand:127.0.0.1:{hub.port}:vcan0"
    summary = json.loads(out.read_text())
    assert summary["watchdog"] is True and summary["mode"] == "stopped"
    assert summary["counters"]["watchdog_trips"] == 1 and summary["counters"]["commands"] == 0
    assert 20 <= summary["counters"]["states_sent"] <= 40  # 50 Hz for 0.6 s


@pytest.mark.slow
def test_damaged_mavlink_bytes_are_counted_and_ignored():
    with SimulatedRobot("mavlink") as sim:
        sim.step(0.05)
        buf = io.BytesIO()
        mav = make_mavlink(buf, 1, 191, sim.controller.port.mav.signing.secret_key, link_id=3)
        mav.command_long_send(1, 1, 193, 0, 1, 0, 0, 0, 0, 0, 500.0)  # a genuine, signed resume ...
        packet = bytearray(buf.getvalue())
        packet[12] ^= 0xFF  # ... with one payload byte flipped on the line
        sim.link.stream.write(bytes(packet) + b"\x00garbage\xfd")
        sim.step(0.05)
        counters = sim.controller.all_counters()
        assert counters["crc_errors"] >= 1 and counters["integrity_errors"] >= 1
        assert sim.link.state.mode == "stopped" and sim.controller.last_seq == 0
        sim.step(0.3)  # the stray start byte swallows no heartbeat: the parser rescans behind it
        assert sim.controller.counters["watchdog_trips"] == 0
        ok = sim.link.resume()
        sim.step(0.05)
        assert sim.link.result(ok) == "ok" and sim.link.state.mode == "run"


@pytest.mark.parametrize("kind", ["can", "mavlink"])
def test_a_damaged_command_is_never_executed(kind):
    """Over a link that corrupts or drops 30% of the traffic, the controller only ever adopts
    tones the runtime asked for, and the errors are counted on both ends."""
    with SimulatedRobot(kind, faults=LinkFaults(drop=0.1, corrupt=0.2, seed=4)) as sim:
        sim.step(0.05)
        sent = set()
        adopted = set()
        for i in range(150):
            hz = 1000.0 + 7 * i
            sim.link.set_alarm("red", hz, 60.0)
            sent.add(hz)
            sim.step(0.02)
            adopted.add(sim.controller.tone_hz)
        adopted.discard(0.0)
        assert adopted and adopted <= sent
        assert len(adopted) > 40  # most commands do get through
        assert sim.faults.stats["corrupted"] > 50 and sim.faults.stats["dropped"] > 20
        assert sim.controller.all_counters()["integrity_errors"] > 10
        assert sim.link.stats.integrity_errors > 10


def _signed_from(sim, sysid: int) -> tuple:
    """(pymavlink sender as system ``sysid`` with the link's key, its byte buffer)."""
    buf = io.BytesIO()
    return make_mavlink(buf, sysid, 191, sim.controller.port.mav.signing.secret_key, link_id=3), buf


def test_a_pause_continue_whose_param1_is_not_0_or_1_is_refused_not_executed_as_resume():
    with SimulatedRobot("mavlink") as sim:
        sim.step(0.05)
        mav, buf = _signed_from(sim, 1)
        mav.command_long_send(1, 1, 193, 0, math.nan, 0, 0, 0, 0, 0, 700.0)  # a stop? a resume? neither
        mav.command_long_send(1, 1, 193, 0, 1, 0, 0, 0, 0, 0, math.inf)      # a resume with no sequence number
        sim.link.stream.write(buf.getvalue())
        sim.step(0.05)
        assert sim.controller.mode == "stopped"
        assert sim.controller.counters["malformed"] == 2


def test_a_zero_quaternion_is_an_invalid_move_not_an_assertion():
    with SimulatedRobot("mavlink") as sim:
        sim.link.resume()
        sim.step(0.05)
        mav, buf = _signed_from(sim, 1)
        mav.set_attitude_target_send(9, 1, 1, 0, [0.0, 0.0, 0.0, 0.0], 0, 0, 0, 0)
        mav.set_position_target_local_ned_send(9, 1, 1, 1, 0b111111111000, 0.6, -0.3, -0.2, 0, 0, 0, 0, 0, 0, 0, 0)
        sim.link.stream.write(buf.getvalue())
        sim.step(0.05)
        assert (sim.controller.last_seq, sim.controller.last_result) == (9, "invalid")
        assert sim.controller.counters["malformed"] == 1


def test_commands_from_a_foreign_system_id_are_refused_when_one_is_configured():
    with SimulatedRobot("mavlink") as sim:
        sim.controller.port.runtime_sysid = 1
        sim.step(0.05)
        mav, buf = _signed_from(sim, 7)
        mav.command_long_send(1, 1, 193, 0, 1, 0, 0, 0, 0, 0, 800.0)  # resume, from system 7
        sim.link.stream.write(buf.getvalue())
        sim.step(0.05)
        assert sim.controller.mode == "stopped" and sim.controller.port.counters["foreign_system"] == 1
        sim.link.resume()
        sim.step(0.05)
        assert sim.controller.mode == "run"


def test_a_short_can_frame_is_counted_and_the_controller_keeps_running():
    import can
    import e2e.p01 as p01

    from edge_runtime.canbus.e2e import e2e_data_id

    with SimulatedRobot("can") as sim:
        sim.step(0.05)
        msg = sim.link.codec.db.get_message_by_name("ROBOT_MODE_CMD")
        data = bytearray(3)
        p01.e2e_p01_protect(data, e2e_data_id(msg), length=len(data), increment_counter=False)
        sim.link.bus.send(can.Message(arbitration_id=msg.frame_id, data=bytes(data), is_extended_id=False))
        sim.step(0.05)
        assert sim.controller.port.codec.checker.counts.get("wrong_crc", 0) == 0  # refused before the E2E check
        assert sim.controller.all_counters()["integrity_errors"] == 1
        ok = sim.link.resume()
        sim.step(0.05)
        assert sim.link.result(ok) == "ok"


@pytest.mark.parametrize("kind", ["can", "mavlink"])
def test_a_speed_override_is_acknowledged_and_slows_the_hand(kind):
    with SimulatedRobot(kind) as sim:
        sim.step(0.05)
        seq = sim.link.set_speed(0.2)
        sim.step(0.05)
        assert sim.link.result(seq) == "ok" and sim.controller.arm.speed_limit_mps == pytest.approx(0.2, abs=1e-3)
        assert sim.link.state.last_command == "speed"
        sim.link.resume()
        sim.step(0.05)
        sim.link.move_to((0.3, 0.2, 0.6), 0.0, 0.0)
        fastest = 0.0
        for _ in range(150):
            sim.step(0.01)
            fastest = max(fastest, sim.controller.snapshot().ee_speed_mps)
        assert 0.1 < fastest <= 0.2 * 1.01
        seq = sim.link.set_speed(0.6)                          # back to full speed, in any mode
        sim.step(0.05)
        assert sim.link.result(seq) == "ok" and sim.controller.arm.speed_limit_mps == pytest.approx(0.6)


def test_a_malformed_mavlink_speed_override_is_refused():
    from edge_runtime.robot.link.protocol import MAV_CMD_SPEED

    with SimulatedRobot("mavlink") as sim:
        sim.step(0.05)
        sim.link._command_long(MAV_CMD_SPEED, 901, 0.0, 0.1, 50.0)  # airspeed and a throttle: not ours
        sim.step(0.05)
        assert sim.link.result(901) == "invalid" and sim.controller.arm.speed_limit_mps == pytest.approx(0.6)
