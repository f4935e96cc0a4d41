"""Session 22 (issue 12): does the product's training reproduce session 21's prototype draw for draw? (run once,
13:45-13:46 UTC, before the full retraining; it printed "sim vs cache: True True True True" and "weights identical:
True")

    PYTHONPATH=. OMP_NUM_THREADS=1 nice -n 10 python reports/wearable/stream_s22/check_train.py

1. the product's cohort (``models.stream_train.cohort_recordings``: simulated again) against the prototype's cache
   (/work/s9-runs/stream21/cohort_seed0.npz): the same 25 Hz steps, labels and window ends;
2. one short epoch (2,560 windows) of the prototype's ``train.main`` and of ``models.stream_train.fit_stream`` with
   the same seed: the same weights.
"""
import sys
import time
from pathlib import Path

import numpy as np
import torch

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "stream_s21"))
import train as proto  # noqa: E402
from data import DEFAULT_DIR, load_streams  # noqa: E402

from models import stream_train as st  # noqa: E402

t = time.time()
recs = load_streams(DEFAULT_DIR / "cohort_seed0")
cached = st.stream_set([(r["acc_mps2"], r["events"]) for r in recs])
sim = st.stream_set(st.cohort_recordings(20, 0, 15.0))
print("sim vs cache:", np.array_equal(sim.x25, cached.x25), np.array_equal(sim.y, cached.y),
      np.array_equal(sim.distraction, cached.distraction), np.array_equal(sim.near_other, cached.near_other), time.time()-t, flush=True)
proto.SAMPLES = st.SAMPLES = 2560
proto.main(["/tmp/s22_proto.pt", "--width", "64", "--epochs", "1"])
m, _ = st.fit_stream(sim, width=64, epochs=1, seed=0)
ck = torch.load("/tmp/s22_proto.pt", weights_only=False)
print("weights identical:", all(torch.equal(ck["state"][k], v) for k, v in m.state_dict().items()))
