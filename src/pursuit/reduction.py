"""Sums over Monte Carlo runs that do not depend on how the runs were split.

Floating-point addition is not associative: a sum over 10 000 runs computed
as ten chunk sums added together differs in its last bits from the same sum
computed in one pass, and from a split into five chunks.  pursuit promises
bit-identical summaries whatever the chunk size and the number of workers, so
every sum *over runs* is defined here by one fixed binary tree over the
absolute run index:

* the sum over an aligned block of runs ``[j 2^L, (j+1) 2^L)`` is the sum of
  its two halves (a block of one run is that run's value);
* the sum over runs ``[0, M)`` adds the maximal aligned blocks that tile
  ``[0, M)``, left to right.

A chunk ``[start, stop)`` returns the sums of the maximal aligned blocks
inside it (:func:`block_sums`); :func:`merge_blocks` assembles the blocks of
all chunks into the canonical sum, adding sibling blocks exactly as a single
pass would.  The result is therefore the same bits whichever way the runs were
chunked, and equal to :func:`run_sum` over the full array.

This module also reduces one chunk of one filter's output to the statistics
that the summaries need (:func:`filter_statistics`), so that a Monte Carlo
comparison can drop each chunk's arrays once they are reduced and keep memory
bounded by the chunk size.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterable, Sequence

import numpy as np

from . import metrics
from .divergence import DIVERGED_KEY, onset_step

__all__ = [
    "Blocks",
    "block_sums",
    "merge_blocks",
    "RunSumAccumulator",
    "run_sum",
    "component_groups",
    "group_key",
    "PartialStatistics",
    "FilterStatistics",
    "filter_statistics",
    "merge_statistics",
    "StatisticsAccumulator",
]

Blocks = dict[tuple[int, int], np.ndarray]
"""Sums of aligned blocks of runs, keyed by ``(level, index)``: the block covers runs
``[index * 2**level, (index + 1) * 2**level)``."""


def _aligned_spans(start: int, stop: int) -> list[tuple[int, int]]:
    """The maximal aligned blocks ``(level, index)`` that tile ``[start, stop)``."""
    spans = []
    pos = start
    while pos < stop:
        level = 0
        while (pos % (2 << level) == 0) and pos + (2 << level) <= stop:
            level += 1
        spans.append((level, pos >> level))
        pos += 1 << level
    return spans


def _halve(x: np.ndarray, levels: int) -> np.ndarray:
    """Pairwise sum of the ``2**levels`` leading entries of ``x``, bottom up."""
    for _ in range(levels):
        x = x[0::2] + x[1::2]
    return x[0].copy()


def block_sums(values: np.ndarray, start: int) -> Blocks:
    """Aligned block sums of ``values`` whose leading axis is runs ``start, start + 1, ...``.

    Parameters
    ----------
    values
        ``(c, ...)`` one entry per run, runs first.
    start
        Absolute index of the first run.

    Returns
    -------
    Blocks
        Each block's sum has shape ``values.shape[1:]``.
    """
    values = np.asarray(values)
    out: Blocks = {}
    for level, index in _aligned_spans(start, start + values.shape[0]):
        lo = (index << level) - start
        out[(level, index)] = _halve(values[lo : lo + (1 << level)], level)
    return out


def merge_blocks(parts: Iterable[Blocks], total: int) -> np.ndarray:
    """The canonical sum over runs ``[0, total)`` from the blocks of every chunk.

    Raises
    ------
    ValueError
        If a block arrives twice or a run is missing.
    """
    pool: Blocks = {}
    for part in parts:
        for key, value in part.items():
            if key in pool:
                raise ValueError(f"runs {key[1] << key[0]}..{((key[1] + 1) << key[0]) - 1} were reduced twice")
            pool[key] = value

    def get(level: int, index: int) -> np.ndarray:
        v = pool.get((level, index))
        if v is None:
            if level == 0:
                raise ValueError(f"run {index} is missing from the reduced chunks")
            v = get(level - 1, 2 * index) + get(level - 1, 2 * index + 1)
        return v

    spans = _aligned_spans(0, total)
    if not spans:
        raise ValueError("total: at least one run is needed")
    acc = get(*spans[0])
    for span in spans[1:]:
        acc = acc + get(*span)
    return acc


class RunSumAccumulator:
    """The canonical sum over runs ``[0, total)``, fed chunk by chunk in any order.

    Sibling blocks are added into their parent as soon as both are present
    (exactly as :func:`merge_blocks` would add them), so the memory held is
    a few blocks per level — about ``log2(total)`` — not one per chunk.
    """

    def __init__(self, total: int):
        self.total = int(total)
        self.pool: Blocks = {}

    def add(self, blocks: Blocks) -> None:
        """Take the block sums of one chunk (:func:`block_sums`)."""
        for (level, index), value in blocks.items():
            while True:
                if (level, index) in self.pool:
                    raise ValueError(f"runs {index << level}..{((index + 1) << level) - 1} were reduced twice")
                sibling = index ^ 1
                parent_end = ((index >> 1) + 1) << (level + 1)
                if (level, sibling) in self.pool and parent_end <= self.total:
                    other = self.pool.pop((level, sibling))
                    value = other + value if sibling < index else value + other  # left + right
                    level, index = level + 1, index >> 1
                    continue
                self.pool[(level, index)] = value
                break

    def result(self) -> np.ndarray:
        """The canonical sum (raises if a run is missing)."""
        return merge_blocks([self.pool], self.total)


def run_sum(values: np.ndarray, axis: int = 0) -> np.ndarray:
    """Canonical sum over ``axis`` (the runs), equal to the merged chunk sums bit for bit."""
    v = np.moveaxis(np.asarray(values), axis, 0)
    return merge_blocks([block_sums(v, 0)], v.shape[0])


# --------------------------------------------------------------------------
# per-filter statistics
# --------------------------------------------------------------------------
def group_key(indices: Sequence[int]) -> str:
    """The name under which a group of state indices is reduced: ``(0, 2)`` -> ``"0,2"``."""
    return ",".join(str(int(i)) for i in indices)


def component_groups(n: int, position: Sequence[int], velocity: Sequence[int]) -> list[tuple[int, ...]]:
    """The index groups whose errors every reduction keeps.

    Position, velocity, the whole state and each single component; the
    summaries (RMSE of position, velocity and each component) need no more.
    """
    groups: list[tuple[int, ...]] = []
    for g in (tuple(position), tuple(velocity), tuple(range(n)), *((i,) for i in range(n))):
        if g and g not in groups:
            groups.append(g)
    return groups


def squared_error_of(error: np.ndarray, indices: Sequence[int]) -> np.ndarray:
    """Sum of squared error components, added in index order (batch-invariant)."""
    idx = list(indices)
    out = error[..., idx[0]] ** 2
    for i in idx[1:]:
        out = out + error[..., i] ** 2
    return out


def _steps_mean(values: np.ndarray) -> np.ndarray:
    """Mean over the leading (time) axis with the canonical tree: ``(K, c) -> (c,)``."""
    return run_sum(values, axis=0) / values.shape[0]


@dataclass
class PartialStatistics:
    """One chunk of one filter, reduced.

    Attributes
    ----------
    start, stop
        The runs covered.
    sums
        Quantity name -> aligned block sums over runs of a ``(K,)`` per-step value.
    per_run
        Quantity name -> ``(stop - start,)`` one value per run.
    """

    start: int
    stop: int
    sums: dict[str, Blocks] = field(default_factory=dict)
    per_run: dict[str, np.ndarray] = field(default_factory=dict)


@dataclass
class FilterStatistics:
    """What the summaries of one filter need, over all runs.

    Quantities in ``sums`` (each ``(K,)``, summed over runs):

    * ``sse:G``: squared error of index group ``G`` (see :func:`group_key`);
    * ``nees``, ``nees_count``, ``nees_dof``: NEES over runs where it is
      finite, how many, and their χ² degrees of freedom summed;
    * ``nis``, ``nis_count``, ``nis_dof``: the same for NIS;
    * ``info:KEY`` and ``info:KEY_count``: any other scalar step-info value
      (fading factor, ESS, ...) over runs where it is finite.

    ``per_run`` holds ``mse:G`` (each run's time-averaged squared error of
    group ``G``), ``(M,)``, and, when the runs were tested for divergence,
    ``diverged_step``: the 1-based step at which each run was flagged
    diverged, NaN if never (:mod:`pursuit.divergence`).  The per-step count of
    flagged runs is ``info:diverged``.
    """

    runs: int
    steps: int
    sums: dict[str, np.ndarray] = field(default_factory=dict)
    per_run: dict[str, np.ndarray] = field(default_factory=dict)

    def require(self, name: str) -> np.ndarray:
        """A per-step sum by name, with a clear error when it was not reduced."""
        try:
            return self.sums[name]
        except KeyError:
            have = ", ".join(sorted(self.sums))
            raise KeyError(f"{name!r} was not reduced (have: {have})") from None


def _finite_sums(out: PartialStatistics, name: str, values: np.ndarray, dof: np.ndarray | None) -> None:
    """Reduce a ``(K, c)`` value where finite: its sum, count and (optionally) dof sum."""
    ok = np.isfinite(values)
    out.sums[name] = block_sums(np.where(ok, values, 0.0).T, out.start)
    out.sums[f"{name}_count"] = block_sums(ok.T.astype(float), out.start)
    if dof is not None:
        out.sums[f"{name}_dof"] = block_sums(np.where(ok, dof, 0.0).T, out.start)


def filter_statistics(
    truth: np.ndarray,
    estimates: np.ndarray,
    covariances: np.ndarray | None,
    info: dict[str, np.ndarray],
    start: int,
    groups: Sequence[Sequence[int]],
) -> PartialStatistics:
    """Reduce one chunk of one filter's output.

    Parameters
    ----------
    truth, estimates
        ``(K, c, n)`` for runs ``start .. start + c - 1``.
    covariances
        ``(K, c, n, n)`` or None (then no NEES).
    info
        Step info ``{key: (K, c, ...)}``.
    start
        Absolute index of the chunk's first run.
    groups
        Index groups to reduce (see :func:`component_groups`).
    """
    K, c, n = truth.shape
    out = PartialStatistics(start, start + c)
    error = np.asarray(estimates, dtype=float) - np.asarray(truth, dtype=float)
    for g in groups:
        sq = squared_error_of(error, g)
        key = group_key(g)
        out.sums[f"sse:{key}"] = block_sums(sq.T, start)
        out.per_run[f"mse:{key}"] = _steps_mean(sq)
    if covariances is not None:
        _finite_sums(out, "nees", metrics.nees(estimates, covariances, truth), np.full((K, c), float(n)))
    if "nis" in info:
        nis = np.asarray(info["nis"], dtype=float)
        dof = np.broadcast_to(np.asarray(info.get("dof", 1), dtype=float), nis.shape)
        _finite_sums(out, "nis", nis, dof)
    if DIVERGED_KEY in info:
        out.per_run["diverged_step"] = onset_step(info[DIVERGED_KEY])
    for key, value in info.items():
        if key in ("nis", "dof"):
            continue
        value = np.asarray(value)
        if value.shape == (K, c) and value.dtype.kind in "biuf":
            _finite_sums(out, f"info:{key}", value.astype(float), None)
    return out


class StatisticsAccumulator:
    """Folds the partial statistics of one filter's chunks, in any order, into :class:`FilterStatistics`.

    Holds a few blocks per quantity (see :class:`RunSumAccumulator`) and the
    per-run values (a few floats per run), so its memory does not grow with
    the number of chunks.
    """

    def __init__(self, runs: int, steps: int):
        self.runs, self.steps = int(runs), int(steps)
        self.sums: dict[str, RunSumAccumulator] = {}
        self.per_run: dict[str, dict[int, np.ndarray]] = {}
        self.spans: list[tuple[int, int]] = []

    def add(self, part: PartialStatistics) -> None:
        """Fold one chunk in."""
        if not self.spans:
            self.sums = {name: RunSumAccumulator(self.runs) for name in part.sums}
            self.per_run = {name: {} for name in part.per_run}
        elif set(part.sums) != set(self.sums) or set(part.per_run) != set(self.per_run):
            raise ValueError(f"chunk {part.start}..{part.stop - 1} reduced different quantities")
        self.spans.append((part.start, part.stop))
        for name, blocks in part.sums.items():
            self.sums[name].add(blocks)
        for name, values in part.per_run.items():
            self.per_run[name][part.start] = values

    def result(self) -> FilterStatistics:
        """The totals over all runs; raises if runs are missing or were reduced twice."""
        pos = 0
        for start, stop in sorted(self.spans):
            if start != pos:
                what = "reduced twice" if start < pos else "missing"
                raise ValueError(f"runs {min(start, pos)}..{max(start, pos) - 1} are {what}")
            pos = stop
        if pos != self.runs:
            raise ValueError(f"runs {pos}..{self.runs - 1} are missing" if pos < self.runs else f"got runs beyond {self.runs - 1}")
        sums = {name: acc.result() for name, acc in self.sums.items()}
        per_run = {name: np.concatenate([chunks[s] for s in sorted(chunks)]) for name, chunks in self.per_run.items()}
        return FilterStatistics(runs=self.runs, steps=self.steps, sums=sums, per_run=per_run)


def merge_statistics(parts: Sequence[PartialStatistics], runs: int, steps: int) -> FilterStatistics:
    """Assemble the partial statistics of every chunk (any order) into totals over ``runs``."""
    acc = StatisticsAccumulator(runs, steps)
    for part in parts:
        acc.add(part)
    return acc.result()
