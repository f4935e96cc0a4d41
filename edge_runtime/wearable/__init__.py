"""The wearable distraction product: IMU source -> loop -> detector -> classifier (capture in, probabilities out) -> alerts on CAN; ``command`` runs it."""
import os


def limit_blas_threads() -> None:
    """OpenBLAS on one thread in this process (and its children), unless the environment says otherwise.

    The wearable's numpy work is small matrix products on one thread (a capture's resampling, a few
    captures at a time in a replay), so OpenBLAS's thread pool only costs CPU: starting its threads
    at import (numpy's import: 0.13-0.15 s of CPU with them on this 2-core machine, 0.08-0.09 s
    without) and, when a product is large enough to be split, their waiting for each other (the
    replay's products, (66, 298) x (298, 3) per capture, took 1.8 times the CPU with two threads).
    OpenBLAS reads the variable once, when numpy loads: the wearable command's entry
    (``edge_runtime.__main__``) and the bench's wearable worker call this first. A function, not an
    import side effect, so that a process that merely imports a wearable module (the bench's parent,
    an evaluation) keeps its own setting and passes none on. The products' results do not depend on it.
    """
    os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
