"""The one timer of the benchmarks: the median time of repeated calls (wall clock unless told)."""

from __future__ import annotations

import statistics
import time
from typing import Callable


def median_time(fn: Callable[[], object], repeats: int, clock: Callable[[], float] = time.perf_counter) -> float:
    """Median seconds of ``repeats`` calls of ``fn``.

    ``clock`` is the wall clock by default; ``time.process_time`` (CPU time of
    this process) counts less of other jobs' slices on a loaded machine.
    """
    times = []
    for _ in range(repeats):
        t0 = clock()
        fn()
        times.append(clock() - t0)
    return statistics.median(times)
