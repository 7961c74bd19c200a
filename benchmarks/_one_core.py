"""One core for NumPy in the benchmarks: BLAS / OpenMP thread pools of one thread.

OpenBLAS, MKL and OpenMP read their thread counts once, when NumPy loads them,
so :func:`pin` must run before the first ``import numpy`` of the process
(``benchmarks/run.py`` and ``bench_kf.py`` call it at their very top).
``NUMBA_NUM_THREADS`` is left alone: it caps ``numba.set_num_threads``, and the
numba rows choose 1 or 2 threads themselves.
"""

from __future__ import annotations

import os
import sys

ONE_CORE_ENV = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")


def pin() -> bool:
    """Set every variable of :data:`ONE_CORE_ENV` to 1.

    Returns
    -------
    bool
        True when it takes effect: NumPy was not imported yet, or it was
        imported with these variables already 1.
    """
    effective = "numpy" not in sys.modules or all(os.environ.get(v) == "1" for v in ONE_CORE_ENV)
    for var in ONE_CORE_ENV:
        os.environ[var] = "1"
    return effective
