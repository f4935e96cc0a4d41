"""prof_cycle (reports/bench/s15_perf/prof_cycle.py) with the robot link's own pieces timed too: the
receive side (bus.recv, the codec's decode, the state assembler, check_state) and the send side (the
target check, the codec's frames, the bus's send). Same command line as prof_cycle; the extra stages
are in the JSON (see table_link.py). Run from a tree:
    OMP_NUM_THREADS=1 nice -n 10 env PYTHONPATH=. python reports/bench/s18_perfA/prof_link.py --seconds 60 --out X.json
"""
from __future__ import annotations

import sys
from pathlib import Path

sys.path.insert(0, str(Path.cwd() / "reports/bench/s15_perf"))

import prof_cycle as pc  # noqa: E402

import bench.arm_echo as ae  # noqa: E402
import edge_runtime.robot.link.base as base  # noqa: E402
import edge_runtime.robot.link.can as canlink  # noqa: E402
import edge_runtime.robot.link.protocol as proto  # noqa: E402

LINK_STAGES = ["recv", "decode", "feed", "check_state", "receive", "check_target", "enc_target", "enc_mode",
               "enc_speed", "enc_alarm", "enc_heartbeat", "bus_send"]


def instrument_link():
    pc._wrap(ae.StampedBus, "recv", "recv")               # python-can's recv on the bench's virtual bus
    pc._wrap(ae.StampedBus, "send", "bus_send")           # python-can's send (the virtual bus's deepcopy)
    # E2E check + cantools decode + range check (a tree whose link reads the shared decoding: decode_shared)
    pc._wrap(proto.RobotCanCodec, "decode_shared" if hasattr(proto.RobotCanCodec, "decode_shared") else "decode",
             "decode")
    pc._wrap(proto.CanStateAssembler, "feed", "feed")
    pc._wrap(base, "check_state", "check_state")
    pc._wrap(canlink.CanRobotLink, "_receive", "receive")
    pc._wrap(base, "check_target", "check_target")
    pc._wrap(proto.RobotCanCodec, "target_frames", "enc_target")
    pc._wrap(proto.RobotCanCodec, "mode_frame", "enc_mode")
    pc._wrap(proto.RobotCanCodec, "speed_frame", "enc_speed")
    pc._wrap(proto.RobotCanCodec, "alarm_frame", "enc_alarm")
    pc._wrap(proto.RobotCanCodec, "heartbeat_frame", "enc_heartbeat")


if __name__ == "__main__":
    instrument_link()
    pc.main()
