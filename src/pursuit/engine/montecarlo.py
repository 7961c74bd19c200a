"""Monte Carlo comparison of filters with common random numbers.

Run i gets the seed ``SeedSequence(root, spawn_key=(i,))``.  From it come two
streams: the scenario's (truth and measurements, identical for every filter)
and the filters' own (particle filters' draws, also identical for every
filter).  Runs are processed in chunks to bound memory; because each run
draws only from its own streams and every batched operation in pursuit is
batch-invariant, the results are bit-identical whatever the chunk size.

Chunks are computed by a backend (:mod:`pursuit.engine.backends`): in this
process, in local worker processes or on a Dask cluster.  In ``summary``
storage mode each chunk is reduced where it was computed
(:mod:`pursuit.reduction`) and only the reduction travels back, so memory is
bounded by the chunk size, not by the number of runs; sums over runs are
taken in a fixed order, so the summaries are again bit-identical whatever the
chunking, and equal to those computed from the full arrays.
"""

from __future__ import annotations

import time
from collections import abc
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Sequence

import numpy as np

from .._validation import positive_int
from ..divergence import DIVERGED_KEY, DivergenceTest, outside_region
from ..reduction import PartialStatistics, StatisticsAccumulator, component_groups, filter_statistics
from ..results import STORE_MODES, FilterResult, MonteCarloResult
from ..rng import run_streams
from .backends import Serial, current_options, make_backend
from .memory import INFO_SCALARS, _measurement_dim, check_memory, result_bytes_full  # noqa: F401 (re-exported)
from .progress import Progress
from .run import run

__all__ = [
    "monte_carlo",
    "run_chunk",
    "ChunkResult",
    "ChunkSummary",
    "ChunkTask",
    "combine_chunks",
    "FullCollector",
    "combine_summaries",
    "SummaryCollector",
    "DEFAULT_CHUNK",
    "DEFAULT_KEEP_RUNS",
    "AUTO_FULL_LIMIT",
]

DEFAULT_CHUNK = 1000
DEFAULT_KEEP_RUNS = 10
AUTO_FULL_LIMIT = 1 << 30
"""``store="auto"`` keeps every run's arrays while they are estimated to take at most this many bytes."""
SCENARIO_STREAM = 0
FILTER_STREAM = 1
WARMUP_STREAM = 2  # the untimed one-step call that compiles a filter's kernels (never the filter's own draws)


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
    divergence: DivergenceTest | None = DivergenceTest(),
) -> ChunkResult:
    """Simulate runs ``[start, stop)`` and run every filter on them.

    A pure function of its arguments: any process that calls it with the
    same arguments computes the same bits.  With ``divergence`` (the default
    thresholds), each filter's info carries ``diverged``: the driver's
    consistency test, or'ed with the region test against the truth and the
    scenario's sensors (:mod:`pursuit.divergence`).
    """
    runs = range(start, stop)
    sim = scenario.simulate(run_streams(seed, runs, SCENARIO_STREAM), len(runs))
    tracks: dict[str, FilterResult] = {}
    for filt in filters:
        if getattr(filt, "compiled", False):
            # compile (or load from numba's cache) outside the timed call, so wall_time is filtering time
            run(filt, sim.measurements[:1], sim.prior, rng=run_streams(seed, runs, WARMUP_STREAM), keep_cov=keep_cov, divergence=None)
        streams = run_streams(seed, runs, FILTER_STREAM)
        t0 = time.perf_counter()
        track = run(filt, sim.measurements, sim.prior, rng=streams, keep_cov=keep_cov, keep_info=keep_info, divergence=divergence)
        wall = time.perf_counter() - t0
        info = track.info
        if divergence is not None:
            outside = outside_region(
                track.mean, sim.truth, scenario.position_indices, sensors=_sensors(scenario),
                scale=_prior_scale(sim.prior, scenario.position_indices), test=divergence,
            )
            info = {**info, DIVERGED_KEY: info[DIVERGED_KEY] | np.logical_or.accumulate(outside, axis=0)}
        tracks[filt.name] = FilterResult(filt.name, track.mean, track.cov, info, wall)
        if on_filter_done is not None:
            on_filter_done()
    return ChunkResult(start, stop, sim.times, sim.truth, sim.measurements, tracks)


def _sensors(scenario: Any) -> np.ndarray | None:
    """The scenario's sensor positions (its measurement model's ``anchors``), or None."""
    anchors = getattr(getattr(scenario, "measurement", None), "anchors", None)
    return None if anchors is None else np.atleast_2d(np.asarray(anchors, dtype=float))


def _prior_scale(prior: Any, position_indices: Sequence[int]) -> np.ndarray | None:
    """Each run's largest prior position standard deviation (the region's scale for a target that hardly moves)."""
    cov = getattr(prior, "cov", None)
    if cov is None or not len(position_indices):
        return None
    idx = list(position_indices)
    var = np.diagonal(np.asarray(cov, dtype=float), axis1=-2, axis2=-1)[..., idx]
    return np.sqrt(np.max(var, axis=-1))


class Spans(abc.Sequence):
    """The chunks ``(start, stop)`` of ``runs`` runs, computed when asked for, never listed.

    A sequence (``len``, indexing, iteration, ``in``) that holds two
    integers: a billion chunks cost no memory until a backend walks them.
    """

    def __init__(self, runs: int, chunk_size: int):
        self.runs, self.chunk_size = int(runs), int(chunk_size)

    def __len__(self) -> int:
        return -(-self.runs // self.chunk_size)

    def __getitem__(self, i: Any) -> Any:
        if isinstance(i, slice):
            return [self[j] for j in range(*i.indices(len(self)))]
        if i < 0:
            i += len(self)
        if not 0 <= i < len(self):
            raise IndexError(f"chunk {i} of {len(self)}")
        start = i * self.chunk_size
        return (start, min(start + self.chunk_size, self.runs))

    def __contains__(self, span: object) -> bool:
        if not isinstance(span, tuple) or len(span) != 2:
            return False
        start, stop = span
        return (
            isinstance(start, int) and 0 <= start < self.runs and start % self.chunk_size == 0
            and stop == min(start + self.chunk_size, self.runs)
        )

    def __iter__(self):
        for start in range(0, self.runs, self.chunk_size):
            yield (start, min(start + self.chunk_size, self.runs))


def _chunks(runs: int, chunk_size: int) -> Spans:
    return Spans(runs, chunk_size)


@dataclass
class ChunkSummary:
    """Runs ``start`` to ``stop − 1`` reduced: per-filter statistics, wall times, example runs."""

    start: int
    stop: int
    times: np.ndarray
    stats: dict[str, PartialStatistics]
    wall_times: dict[str, float]
    example: ChunkResult | None


def summarise_chunk(chunk: ChunkResult, groups: Sequence[Sequence[int]], keep_runs: int) -> ChunkSummary:
    """Reduce a chunk to what the summaries need, keeping runs below ``keep_runs`` whole."""
    stats = {
        name: filter_statistics(chunk.truth, fr.estimates, fr.covariances, fr.info, chunk.start, groups)
        for name, fr in chunk.tracks.items()
    }
    example = None
    if chunk.start < keep_runs:
        r = min(chunk.stop, keep_runs) - chunk.start
        tracks = {
            name: FilterResult(
                name,
                fr.estimates[:, :r].copy(),
                None if fr.covariances is None else fr.covariances[:, :r].copy(),
                {k: v[:, :r].copy() for k, v in fr.info.items()},
                fr.wall_time,
            )
            for name, fr in chunk.tracks.items()
        }
        example = ChunkResult(
            chunk.start, chunk.start + r, chunk.times, chunk.truth[:, :r].copy(), chunk.measurements[:, :r].copy(), tracks
        )
    walls = {name: fr.wall_time for name, fr in chunk.tracks.items()}
    return ChunkSummary(chunk.start, chunk.stop, chunk.times, stats, walls, example)


@dataclass(frozen=True)
class ChunkTask:
    """The work for one chunk, picklable so that any backend can ship it.

    ``task(start, stop)`` runs :func:`run_chunk` and, in summary mode, reduces
    the chunk where it was computed.
    """

    scenario: Any
    filters: tuple[Any, ...]
    seed: int
    keep_cov: bool = True
    keep_info: tuple[str, ...] | None = None
    store: str = "full"
    keep_runs: int = DEFAULT_KEEP_RUNS
    divergence: DivergenceTest | None = DivergenceTest()

    def __call__(self, start: int, stop: int, on_filter_done: Callable[[], None] | None = None):
        chunk = run_chunk(
            self.scenario,
            self.filters,
            self.seed,
            start,
            stop,
            keep_cov=self.keep_cov,
            keep_info=self.keep_info,
            on_filter_done=on_filter_done,
            divergence=self.divergence,
        )
        if self.store == "full":
            return chunk
        s = self.scenario
        groups = component_groups(len(s.state_labels), s.position_indices, s.velocity_indices)
        return summarise_chunk(chunk, groups, self.keep_runs)


def _check_tiling(spans: Sequence[tuple[int, int]], runs: int) -> None:
    pos = 0
    for s, e in sorted(spans):
        if s != pos:
            raise RuntimeError(f"runs {min(s, pos)}..{max(s, pos) - 1} were {'computed twice' if s < pos else 'lost'}")
        pos = e
    if pos != runs:
        raise RuntimeError(f"runs {pos}..{runs - 1} were lost")


def _result_fields(scenario: Any) -> dict[str, Any]:
    units = getattr(scenario, "state_units", None)
    return dict(
        scenario=getattr(scenario, "name", type(scenario).__name__),
        state_labels=tuple(scenario.state_labels),
        position_indices=tuple(scenario.position_indices),
        velocity_indices=tuple(scenario.velocity_indices),
        state_units=None if units is None else tuple(units),
    )


class FullCollector:
    """Copies chunk results, as they arrive in any order, into one full-mode result.

    The arrays for all runs are allocated when the first chunk arrives and
    each chunk is copied into its slice, so the caller can drop it at once:
    memory is the result plus the chunks in flight, not the result twice
    (as concatenating every chunk at the end would need).  A single chunk
    that covers every run is kept as it is, without a copy.  The result is
    the same bits as concatenating the chunks in run order.
    """

    def __init__(self, scenario: Any, filters: Sequence[Any], seed: int, config: dict | None, runs: int):
        self.scenario, self.filters, self.seed, self.config, self.runs = scenario, list(filters), int(seed), config, runs
        self.spans: list[tuple[int, int]] = []
        self.times: np.ndarray | None = None
        self.truth: np.ndarray | None = None
        self.measurements: np.ndarray | None = None
        self.tracks: dict[str, dict[str, Any]] = {}
        self.walls = {f.name: 0.0 for f in self.filters}

    def _put(self, buf: np.ndarray | None, part: np.ndarray, start: int, what: str) -> np.ndarray:
        if buf is None:
            buf = np.empty((part.shape[0], self.runs, *part.shape[2:]), dtype=part.dtype)
        elif part.shape[:1] + part.shape[2:] != buf.shape[:1] + buf.shape[2:]:
            raise RuntimeError(f"{what}: a chunk has shape {part.shape}, another {buf.shape} (runs on axis 1)")
        elif part.dtype != buf.dtype and not np.can_cast(part.dtype, buf.dtype, "safe"):
            buf = buf.astype(np.result_type(buf.dtype, part.dtype))
        buf[:, start : start + part.shape[1]] = part
        return buf

    def add(self, chunk: ChunkResult) -> None:
        """Copy one chunk in (then the caller can drop it)."""
        self.spans.append((chunk.start, chunk.stop))
        if self.times is None:
            self.times = chunk.times
        whole = (chunk.start, chunk.stop) == (0, self.runs) and self.truth is None
        if whole:  # the only chunk: its arrays are the result's
            self.truth, self.measurements = chunk.truth, chunk.measurements
        else:
            self.truth = self._put(self.truth, chunk.truth, chunk.start, "truth")
            self.measurements = self._put(self.measurements, chunk.measurements, chunk.start, "measurements")
        for filt in self.filters:
            name = filt.name
            part = chunk.tracks[name]
            self.walls[name] += part.wall_time
            slot = self.tracks.get(name)
            if slot is None:
                slot = self.tracks[name] = {"estimates": None, "covariances": None, "info": {}, "has_cov": part.covariances is not None}
                slot["keys"] = set(part.info)
            if set(part.info) != slot["keys"] or (part.covariances is not None) != slot["has_cov"]:
                raise RuntimeError(f"{name}: chunks differ in what they kept (info keys or covariances)")
            if whole:
                slot["estimates"], slot["covariances"], slot["info"] = part.estimates, part.covariances, dict(part.info)
                continue
            slot["estimates"] = self._put(slot["estimates"], part.estimates, chunk.start, f"{name}.estimates")
            if part.covariances is not None:
                slot["covariances"] = self._put(slot["covariances"], part.covariances, chunk.start, f"{name}.covariances")
            for key, value in part.info.items():
                slot["info"][key] = self._put(slot["info"].get(key), value, chunk.start, f"{name}.info[{key!r}]")

    def result(self) -> MonteCarloResult:
        """The full-mode :class:`MonteCarloResult`."""
        _check_tiling(self.spans, self.runs)
        results: dict[str, FilterResult] = {}
        for filt in self.filters:
            slot = self.tracks[filt.name]
            results[filt.name] = FilterResult(
                filt.name, slot["estimates"], slot["covariances"], slot["info"], float(self.walls[filt.name])
            )
        return MonteCarloResult(
            seed=self.seed,
            times=self.times,
            truth=self.truth,
            measurements=self.measurements,
            filters=results,
            config=self.config,
            **_result_fields(self.scenario),
        )


def combine_chunks(
    chunks: Sequence[ChunkResult], scenario: Any, filters: Sequence[Any], seed: int, config: dict | None
) -> MonteCarloResult:
    """Concatenate chunk results, in run order, into one :class:`MonteCarloResult`."""
    chunks = sorted(chunks, key=lambda c: c.start)
    _check_tiling([(c.start, c.stop) for c in chunks], chunks[-1].stop)
    collector = FullCollector(scenario, filters, seed, config, chunks[-1].stop)
    for c in chunks:
        collector.add(c)
    return collector.result()


class SummaryCollector:
    """Folds reduced chunks into one summary-mode result as they arrive, in any order.

    Memory: a few blocks per reduced quantity, a few floats per run and the
    kept example runs; not the chunks themselves.
    """

    def __init__(self, scenario: Any, filters: Sequence[Any], seed: int, config: dict | None, runs: int):
        self.scenario, self.filters, self.seed, self.config, self.runs = scenario, list(filters), int(seed), config, runs
        self.stats: dict[str, StatisticsAccumulator] = {}
        self.walls = {f.name: 0.0 for f in self.filters}
        self.examples: list[ChunkResult] = []
        self.spans: list[tuple[int, int]] = []
        self.times: np.ndarray | None = None

    def add(self, part: ChunkSummary) -> None:
        """Fold one reduced chunk in (then the caller can drop it)."""
        if self.times is None:
            self.times = part.times
            self.stats = {f.name: StatisticsAccumulator(self.runs, len(part.times)) for f in self.filters}
        self.spans.append((part.start, part.stop))
        for name, acc in self.stats.items():
            acc.add(part.stats[name])
            self.walls[name] += part.wall_times[name]
        if part.example is not None:
            self.examples.append(part.example)

    def result(self) -> MonteCarloResult:
        """The summary-mode :class:`MonteCarloResult`."""
        _check_tiling(self.spans, self.runs)
        stats = {name: acc.result() for name, acc in self.stats.items()}
        results = {name: FilterResult(name, None, None, {}, float(self.walls[name])) for name in self.stats}
        ex = combine_chunks(self.examples, self.scenario, self.filters, self.seed, None) if self.examples else None
        return MonteCarloResult(
            seed=self.seed,
            times=self.times,
            truth=None,
            measurements=None,
            filters=results,
            config=self.config,
            statistics=stats,
            total_runs=self.runs,
            examples=ex,
            **_result_fields(self.scenario),
        )


def combine_summaries(
    parts: Sequence[ChunkSummary], scenario: Any, filters: Sequence[Any], seed: int, config: dict | None, runs: int
) -> MonteCarloResult:
    """Merge reduced chunks into one summary-mode :class:`MonteCarloResult`."""
    collector = SummaryCollector(scenario, filters, seed, config, runs)
    for part in parts:
        collector.add(part)
    return collector.result()


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


def _estimated_bytes(scenario: Any, filters: Sequence[Any], runs: int, keep_cov: bool) -> int:
    """Bytes of the arrays a full-mode result holds (see :func:`pursuit.engine.memory.result_bytes_full`).

    The real size was 0.73-1.07 times this for each filter of the bundled
    experiments (0.86-1.03 for each experiment's filters together);
    ``tests/engine/test_memory.py`` checks 0.7-1.1.  While it runs, the engine
    also holds the chunks in flight and the filters' working memory for one
    chunk (each chunk is copied into the result as it arrives and dropped,
    see :class:`FullCollector`); :func:`pursuit.engine.memory.check_memory`
    counts those too before anything runs.
    """
    return result_bytes_full(scenario, len(filters), runs, keep_cov)


def resolve_store(store: str, scenario: Any, filters: Sequence[Any], runs: int, keep_cov: bool) -> str:
    """``"full"`` or ``"summary"`` for a requested mode (``"auto"``: full unless it would exceed :data:`AUTO_FULL_LIMIT`)."""
    if store == "auto":
        return "full" if _estimated_bytes(scenario, filters, runs, keep_cov) <= AUTO_FULL_LIMIT else "summary"
    if store not in STORE_MODES:
        raise ValueError(f"store: must be 'auto', 'full' or 'summary', got {store!r}")
    return store


def monte_carlo(
    scenario: Any,
    filters: Sequence[Any],
    runs: int,
    seed: int,
    *,
    chunk_size: int | None = None,
    keep_cov: bool = True,
    keep_info: Iterable[str] | None = None,
    progress: bool | Callable[[int, int], None] = False,
    config: dict | None = None,
    backend: Any = None,
    store: str | None = None,
    keep_runs: int | None = None,
    label: str | None = None,
    divergence: DivergenceTest | None = DivergenceTest(),
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
        True: show a progress bar on standard error (only when it is a
        terminal).  A callable is called as ``progress(done, total)`` each
        time work finishes (units: filters x chunks).
    config
        The configuration to store with the result.
    backend
        Where to compute the chunks: None (the :func:`~pursuit.engine.backends.engine_options`
        in force, else this process), a number of local worker processes, a
        Dask scheduler address ``"tcp://HOST:PORT"``, or a backend object
        from :mod:`pursuit.engine.backends` (not closed here).
    store
        ``"full"`` keeps every run's arrays; ``"summary"`` reduces each
        chunk and keeps only ``keep_runs`` example runs whole (memory bounded
        by the chunk size); ``"auto"`` (default) is full unless the arrays
        would take more than :data:`AUTO_FULL_LIMIT` bytes.  The summaries are
        bit-identical in both modes.
    keep_runs
        Runs ``0 .. keep_runs-1`` kept whole in summary mode (default 10).
    label
        What the progress bar says it is computing, e.g. the experiment and
        the swept value (default: the scenario's name).  Computed in this
        process, the bar adds the filter running now.
    divergence
        The thresholds of the divergence tests (:mod:`pursuit.divergence`);
        each filter's info then carries ``diverged`` and the summary counts
        the diverged runs.  None: no test.

    Returns
    -------
    MonteCarloResult
    """
    runs = positive_int("runs", runs)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ValueError(f"seed: must be a non-negative integer, got {seed!r}")
    filters = validate_filters(filters)
    chunk_size = positive_int("chunk_size", DEFAULT_CHUNK if chunk_size is None else chunk_size)
    opts = current_options()
    can_summarise = store is None  # a caller that asked for a mode (a sweep needs every run) keeps it
    store = resolve_store(store or opts.store or "auto", scenario, filters, runs, keep_cov)
    keep_runs = opts.keep_runs if keep_runs is None else keep_runs
    keep_runs = DEFAULT_KEEP_RUNS if keep_runs is None else keep_runs
    if isinstance(keep_runs, bool) or not isinstance(keep_runs, (int, np.integer)) or keep_runs < 0:
        raise ValueError(f"keep_runs: must be a non-negative integer, got {keep_runs!r}")
    owned = None
    if backend is None:
        backend = opts.backend if opts.backend is not None else Serial()
    elif isinstance(backend, bool):
        raise ValueError(f"backend: expected a worker count, an address or a backend, got {backend!r}")
    elif isinstance(backend, (int, np.integer)):
        backend = owned = make_backend(workers=int(backend))
    elif isinstance(backend, str):
        backend = owned = make_backend(scheduler=backend)

    # Refuse what cannot fit before computing anything (one line naming the setting to change).
    # A local pool computes up to `workers` chunks at once, each in its own process on this machine,
    # and never more chunks than there are.
    workers = getattr(backend, "workers", None)
    chunks_at_once = workers if isinstance(workers, int) and not isinstance(backend, Serial) else 1
    try:
        check_memory(
            scenario, filters, runs, chunk_size, store=store, keep_cov=keep_cov,
            in_flight=max(1, min(chunks_at_once, len(_chunks(runs, chunk_size)))),
            can_summarise=can_summarise,
        )
    except BaseException:
        if owned is not None:
            owned.close()
        raise
    task = ChunkTask(
        scenario,
        tuple(filters),
        int(seed),
        keep_cov=keep_cov,
        keep_info=None if keep_info is None else tuple(keep_info),
        store=store,
        keep_runs=int(keep_runs),
        divergence=divergence,
    )
    spans = _chunks(runs, chunk_size)
    base = label or getattr(scenario, "name", "runs")
    in_process = isinstance(backend, Serial)

    def bar_label(done: int) -> str:
        # in process the filters of a chunk run one after the other: name the one running now
        if in_process and done < len(spans) * len(filters):
            return f"{base} {filters[done % len(filters)].name}"
        return base

    bar = Progress(total=len(spans) * len(filters), label=bar_label(0), enabled=progress is True)

    def advance(n: int) -> None:
        bar.label = bar_label(bar.done + n)
        bar.advance(n)
        if callable(progress):
            progress(bar.done, bar.total)

    collector: SummaryCollector | FullCollector
    if store == "summary":
        collector = SummaryCollector(scenario, filters, int(seed), config, runs)
    else:
        collector = FullCollector(scenario, filters, int(seed), config, runs)

    seen: set[tuple[int, int]] = set()  # a set: checking the collector's list made k chunks cost k²

    def on_result(span: tuple[int, int], part: Any) -> None:
        if span in seen:
            raise RuntimeError(f"the backend returned runs {span[0]}..{span[1] - 1} twice")
        # summary: folded in and dropped, memory stays bounded by the chunk size;
        # full: copied into the result's arrays and dropped, so the runs are not held twice
        seen.add(span)
        collector.add(part)
        if not isinstance(backend, Serial):
            advance(len(filters))

    try:
        if isinstance(backend, Serial):
            backend.map_chunks(task, spans, on_result, on_filter_done=lambda: advance(1))
        else:
            backend.map_chunks(task, spans, on_result)
    finally:
        bar.close()
        if owned is not None:
            owned.close()
    if len(seen) != len(spans):
        missing = [span for span in spans if span not in seen]
        raise RuntimeError(f"the backend returned no result for runs {missing[0][0]}..{missing[-1][1] - 1}")
    return collector.result()
