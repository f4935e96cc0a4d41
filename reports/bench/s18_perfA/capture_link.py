"""Capture what the runtime's CAN link receives (per poll: every frame's id and bytes) and the arguments of
every frame it encodes, during the bench's robot scenario (simulated clock) -> pickle, for micro_link.py.
    cd TREE && PYTHONPATH=. python reports/bench/s18_perfA/capture_link.py SECONDS OUT.pkl"""
from __future__ import annotations

import pickle
import sys
from pathlib import Path

sys.path.insert(0, str(Path.cwd()))
import bench.arm_echo as ae  # noqa: E402
import bench.robot_cycle as rc  # noqa: E402
import edge_runtime.robot.link.can as canlink  # noqa: E402
import edge_runtime.robot.link.protocol as proto  # noqa: E402

CAP: dict = {"polls": [], "encodes": []}
_CUR: list = []
receive, recv, encode = canlink.CanRobotLink._receive, ae.StampedBus.recv, proto.RobotCanCodec.encode


def receive_w(self, now):
    del _CUR[:]
    out = receive(self, now)
    CAP["polls"].append((now, list(_CUR)))
    return out


def recv_w(self, timeout=None):
    msg = recv(self, timeout)
    if msg is not None:
        _CUR.append((msg.arbitration_id, bytes(msg.data), msg.is_extended_id))
    return msg


def encode_w(self, name, **signals):
    if self is LINK_CODEC[0]:  # the runtime's codec only (not the arm echo's)
        CAP["encodes"].append((name, signals))
    return encode(self, name, **signals)


LINK_CODEC: list = []
init = canlink.CanRobotLink.__init__


def init_w(self, *a, **k):
    init(self, *a, **k)
    LINK_CODEC.append(self.codec)


canlink.CanRobotLink._receive, ae.StampedBus.recv, proto.RobotCanCodec.encode = receive_w, recv_w, encode_w
if hasattr(proto.RobotCanCodec, "_command"):  # a tree whose command frames skip the payload cache
    command = proto.RobotCanCodec._command

    def command_w(self, name, **signals):
        if self is LINK_CODEC[0]:
            CAP["encodes"].append((name, signals))
        return command(self, name, **signals)

    proto.RobotCanCodec._command = command_w
canlink.CanRobotLink.__init__ = init_w
from edge_runtime.core.manifest import ASSETS_DIR, load_manifest  # noqa: E402

lifter = rc.lifter_entry(load_manifest(ASSETS_DIR)["models"])
cfg = rc.RobotConfig("/work/notes/perf/workers.npz", float(sys.argv[1]), "", lifter["precision"], rc._arm_posture(),
                     simulated=True)
rc.run_cycle(cfg)
pickle.dump(CAP, open(sys.argv[2], "wb"))
print({k: len(v) for k, v in CAP.items()}, sum(len(f) for _, f in CAP["polls"]), "frames received")
