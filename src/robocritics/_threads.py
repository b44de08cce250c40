"""One BLAS/OpenMP thread per checking process: the environment numpy must start with.

A process that checks programs runs one at a time, and on this project's machines OpenBLAS's thread pool
only costs: numpy's multi-threaded matmul on long trajectories takes 5-8x the CPU of the single-threaded one,
and merely starting the pool (one spinning thread per core, at ``import numpy``) costs 50-80 ms of CPU, a
fifth of a cold ``robocritics check`` (``benchmarks/bench_pipeline.py``). OpenBLAS reads these variables
once, when numpy loads it, so they must be in ``os.environ`` before the first ``import numpy``.

This module imports nothing heavy: the command line calls :func:`single_threaded_blas` first thing.
"""

from __future__ import annotations

import os
import sys
from collections.abc import MutableMapping

__all__ = ["SINGLE_THREADED_ENV", "single_threaded_blas"]

#: Environment a checking process starts with: one BLAS/OpenMP thread.
SINGLE_THREADED_ENV = {
    "OMP_NUM_THREADS": "1",
    "OPENBLAS_NUM_THREADS": "1",
    "MKL_NUM_THREADS": "1",
    "VECLIB_MAXIMUM_THREADS": "1",
    "NUMEXPR_NUM_THREADS": "1",
}


def single_threaded_blas(environ: MutableMapping[str, str] | None = None) -> bool:
    """Set :data:`SINGLE_THREADED_ENV` in ``environ`` (default ``os.environ``) where the user has not set a value.

    Only while numpy is not loaded yet (afterwards the variables would no longer change this process, only
    the processes it starts): returns whether it set them. A value the user exported is kept.
    """
    if "numpy" in sys.modules:
        return False
    environ = os.environ if environ is None else environ
    for key, value in SINGLE_THREADED_ENV.items():
        environ.setdefault(key, value)
    return True
