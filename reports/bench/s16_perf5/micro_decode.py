"""Real (not profiled) cost of decoding and assembling the arm's state frames, of check_state and of the encoders, in
one process. Run from a tree: cd TREE && OMP_NUM_THREADS=1 nice -n 10 /work/main/.venv/bin/python PATH/micro_decode.py"""
import sys
import timeit

sys.path.insert(0, '.')
from dataclasses import replace

import numpy as np

from edge_runtime.robot.link.protocol import CanStateAssembler, RobotCanCodec, blank_state, check_state

tx = RobotCanCodec()
rx = RobotCanCodec()
st = replace(blank_state(1.0), joint_positions_rad=np.linspace(-1, 1, 7), ee_position_m=np.array([.4, .3, .5]),
             mode="run", light="green", last_command="move", last_result="ok", last_seq=5, robot_time_s=12.3)
frames = [tx.state_frames(replace(st, robot_time_s=st.robot_time_s + 0.01 * i)) for i in range(200)]
flat = [m for fs in frames for m in fs]
asm = CanStateAssembler()
def dec():
    for m in flat:
        s, n, sig = rx.decode(m)
        asm.feed(n, sig, 0.0)
rx.checker._last.clear()
N = 5
t = timeit.timeit(dec, number=N) / N / len(flat) * 1e6
print(f"decode+feed per frame {t:.2f} us")
t = timeit.timeit(lambda: check_state(st), number=20000) / 20000 * 1e6
print(f"check_state {t:.2f} us")
t = timeit.timeit(lambda: tx.target_frames(7, np.array([.4, .3, .5]) + np.random.rand(3) * 1e-3, 0.1, 0.2, False), number=3000) / 3000 * 1e6
print(f"target_frames {t:.2f} us")
t = timeit.timeit(lambda: tx.speed_frame(7, np.random.rand()), number=3000) / 3000 * 1e6
print(f"speed_frame {t:.2f} us")
t = timeit.timeit(lambda: tx.alarm_frame(7, "red", 2000.0, 80.0), number=3000) / 3000 * 1e6
print(f"alarm_frame (cached) {t:.2f} us")
