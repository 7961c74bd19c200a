"""Monte Carlo comparison of filters with common random numbers.

Run i gets the seed ``SeedSequence(root, spawn_key=(i,))``.  From it come two
streams: the scenario's (truth and measurements, identical for every filter)
and the filters' own (particle filters' draws, also identical for every
filter).  Runs are processed in chunks to bound memory; because each run
draws only from its own streams and every batched operation in pursuit is
batch-invariant, the results are bit-identical whatever the chunk size.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from .._validation import positive_int
from ..results import FilterResult, MonteCarloResult
from ..rng import run_streams
from .progress import Progress
from .run import run

__all__ = ["monte_carlo", "run_chunk", "ChunkResult", "DEFAULT_CHUNK"]

DEFAULT_CHUNK = 1000
SCENARIO_STREAM = 0
FILTER_STREAM = 1


@dataclass
class ChunkResult:
    """Everything computed for runs ``start`` to ``stop − 1``."""

    start: int
    stop: int
    times: np.ndarray
    truth: np.ndarray
    measurements: np.ndarray
    tracks: dict[str, FilterResult]


def run_chunk(
    scenario: Any,
    filters: Sequence[Any],
    seed: int,
    start: int,
    stop: int,
    *,
    keep_cov: bool = True,
    keep_info: Iterable[str] | None = None,
    on_filter_done: Callable[[], None] | None = None,
) -> ChunkResult:
    """Simulate runs ``[start, stop)`` and run every filter on them.

    A pure function of its arguments: any process that calls it with the
    same arguments computes the same bits.
    """
    runs = range(start, stop)
    sim = scenario.simulate(run_streams(seed, runs, SCENARIO_STREAM), len(runs))
    tracks: dict[str, FilterResult] = {}
    for filt in filters:
        streams = run_streams(seed, runs, FILTER_STREAM)
        t0 = time.perf_counter()
        track = run(filt, sim.measurements, sim.prior, rng=streams, keep_cov=keep_cov, keep_info=keep_info)
        wall = time.perf_counter() - t0
        tracks[filt.name] = FilterResult(filt.name, track.mean, track.cov, track.info, wall)
        if on_filter_done is not None:
            on_filter_done()
    return ChunkResult(start, stop, sim.times, sim.truth, sim.measurements, tracks)


def _chunks(runs: int, chunk_size: int) -> list[tuple[int, int]]:
    return [(s, min(s + chunk_size, runs)) for s in range(0, runs, chunk_size)]


def combine_chunks(
    chunks: Sequence[ChunkResult], scenario: Any, filters: Sequence[Any], seed: int, config: dict | None
) -> MonteCarloResult:
    """Concatenate chunk results, in run order, into one :class:`MonteCarloResult`."""
    chunks = sorted(chunks, key=lambda c: c.start)
    truth = np.concatenate([c.truth for c in chunks], axis=1)
    zs = np.concatenate([c.measurements for c in chunks], axis=1)
    results: dict[str, FilterResult] = {}
    for filt in filters:
        parts = [c.tracks[filt.name] for c in chunks]
        covs = None if parts[0].covariances is None else np.concatenate([p.covariances for p in parts], axis=1)
        info = {key: np.concatenate([p.info[key] for p in parts], axis=1) for key in parts[0].info}
        results[filt.name] = FilterResult(
            filt.name,
            np.concatenate([p.estimates for p in parts], axis=1),
            covs,
            info,
            float(sum(p.wall_time for p in parts)),
        )
    return MonteCarloResult(
        scenario=getattr(scenario, "name", type(scenario).__name__),
        seed=int(seed),
        times=chunks[0].times,
        truth=truth,
        measurements=zs,
        state_labels=tuple(scenario.state_labels),
        position_indices=tuple(scenario.position_indices),
        velocity_indices=tuple(scenario.velocity_indices),
        filters=results,
        config=config,
    )


def validate_filters(filters: Sequence[Any]) -> list[Any]:
    """Check that there is at least one filter and that names are unique."""
    filters = list(filters)
    if not filters:
        raise ValueError("filters: at least one filter is needed")
    names = [getattr(f, "name", "") for f in filters]
    for f, name in zip(filters, names):
        if not name:
            raise ValueError(f"filters: {type(f).__name__} has no name")
    dupes = sorted({n for n in names if names.count(n) > 1})
    if dupes:
        raise ValueError(f"filters: names must be unique; repeated: {', '.join(dupes)}")
    return filters


def monte_carlo(
    scenario: Any,
    filters: Sequence[Any],
    runs: int,
    seed: int,
    *,
    chunk_size: int | None = None,
    keep_cov: bool = True,
    keep_info: Iterable[str] | None = None,
    progress: bool = False,
    config: dict | None = None,
) -> MonteCarloResult:
    """Compare filters on ``runs`` Monte Carlo runs of a scenario.

    Parameters
    ----------
    scenario
        A scenario object (see :mod:`pursuit.scenarios`).
    filters
        Filters with unique ``name`` attributes.
    runs
        Number of Monte Carlo runs.
    seed
        Root seed; run i uses ``SeedSequence(seed, spawn_key=(i,))``.
    chunk_size
        Runs processed together (default 1000).  Memory grows with it; the
        results do not depend on it.
    keep_cov
        Keep covariances (needed for NEES).
    keep_info
        Step-info keys to keep (default all).
    progress
        Show a progress bar on standard error (only when it is a terminal).
    config
        The configuration to store with the result.

    Returns
    -------
    MonteCarloResult
    """
    runs = positive_int("runs", runs)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed: must be a non-negative integer, got {seed!r}")
    filters = validate_filters(filters)
    chunk_size = positive_int("chunk_size", DEFAULT_CHUNK if chunk_size is None else chunk_size)
    spans = _chunks(runs, chunk_size)
    bar = Progress(total=len(spans) * len(filters), label=getattr(scenario, "name", "runs"), enabled=progress)
    try:
        chunks = [
            run_chunk(scenario, filters, int(seed), s, e, keep_cov=keep_cov, keep_info=keep_info, on_filter_done=bar.advance)
            for s, e in spans
        ]
    finally:
        bar.close()
    return combine_chunks(chunks, scenario, filters, int(seed), config)
