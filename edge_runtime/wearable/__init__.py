"""The wearable distraction product: IMU source -> loop -> detector -> classifier (capture in, probabilities out) -> alerts on CAN; ``command`` runs it.

The wearable's numpy work is small matrix products on one thread (a capture's resampling, a few
captures at a time in a replay), so OpenBLAS's thread pool only costs CPU: starting its threads
at import (numpy's import: 0.13-0.15 s of CPU with them on this 2-core machine, 0.08-0.09 s
without) and, when a product is large enough to be split, their waiting for each other (the
replay's products, (66, 298) x (298, 3) per capture, took 1.8 times the CPU with two threads).
So the pool is limited to one thread here, before numpy loads (OpenBLAS reads the variable once,
at load), unless the environment sets it. Nothing changes in a process that imported numpy
before this package (a test run, an evaluation); the products' results do not depend on it.
"""
import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
