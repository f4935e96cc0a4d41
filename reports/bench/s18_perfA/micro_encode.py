"""What a command frame's encode costs, warm: cantools' strict encode against its non-strict one and its check
alone, the codec's whole frames, and the E2E and python-can pieces (best of 5 x N calls; the machine is shared).
    cd TREE && OMP_NUM_THREADS=1 nice -n 10 env PYTHONPATH=. python reports/bench/s18_perfA/micro_encode.py"""
from __future__ import annotations

import time

import can
import e2e.p01 as p01
import numpy as np

from edge_runtime.robot.link.protocol import RobotCanCodec

N = 20000


def best_us(fn, n: int = N) -> float:
    runs = []
    for _ in range(5):
        c0 = time.thread_time()
        for _ in range(n):
            fn()
        runs.append((time.thread_time() - c0) / n * 1e6)
    return min(runs)


def main():
    codec = RobotCanCodec()
    pos, orient = codec._by_name["ROBOT_TARGET_POS"], codec._by_name["ROBOT_TARGET_ORIENT"]
    pos_sig = dict(SeqCheck=3, X=123.4, Y=-456.7, Z=789.1, E2E_CRC=0, AliveCounter=0)
    orient_sig = dict(Kind="move", Seq=1234, Pitch=0.3, Yaw=-1.2, E2E_CRC=0, AliveCounter=0)
    seq = [0]

    def next_seq() -> int:  # a new sequence number per call, as every command has: never a payload-cache hit
        seq[0] = seq[0] % 65535 + 1
        return seq[0]

    data = bytearray(8)
    rows = {
        "cantools ROBOT_TARGET_POS encode strict": lambda: pos.encode(pos_sig, strict=True),
        "cantools ROBOT_TARGET_POS encode not strict": lambda: pos.encode(pos_sig, strict=False),
        "cantools ROBOT_TARGET_POS assert_signals_encodable": lambda: pos.assert_signals_encodable(pos_sig, True),
        "cantools ROBOT_TARGET_ORIENT encode strict": lambda: orient.encode(orient_sig, strict=True),
        "cantools ROBOT_TARGET_ORIENT encode not strict": lambda: orient.encode(orient_sig, strict=False),
        "codec.target_frames (2 frames, new seq and position)":
            lambda: codec.target_frames(next_seq(), np.array([0.4, 0.2, 0.7]) + seq[0] * 1e-5, 0.1, 0.2, False),
        "codec.mode_frame resume (new seq)": lambda: codec.mode_frame(next_seq(), "resume"),
        "can.Message(...)": lambda: can.Message(arbitration_id=0x100, data=data, is_extended_id=False),
        "e2e_p01_protect": lambda: p01.e2e_p01_protect(data, 0x123, length=8, increment_counter=False),
        "e2e_p01_check": lambda: p01.e2e_p01_check(data, 0x123, length=8),
    }
    for name, fn in rows.items():
        print(f"{name:55s} {best_us(fn):7.2f} us")


if __name__ == "__main__":
    main()
