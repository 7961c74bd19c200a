"""Divergence detection: no filter's run diverges silently.

A run is *diverged* when its estimate has left every reading the filter could
defend.  Two documented tests decide it, both batched over runs (no Python
loop over runs; :func:`detect_divergence` has none over time steps either,
so it costs a few passes over the run's arrays, less than the compiled
filter that produced them):

**The consistency test** (every run, no truth needed).  A step is
*inconsistent* when

* the estimate or its covariance is not finite, or
* the step measured something (``dof > 0`` and a finite NIS) and its NIS
  exceeds the χ²(dof) quantile at upper-tail probability ``tail``
  (default 1e-6: 28.4 for one measured component, 33.4 for three).

Steps that measured nothing (NaN NIS or ``dof = 0``) with a finite estimate
are *skipped*: they neither extend nor break a streak.  A consistent measured
step breaks it.  A run is flagged diverged at the first step of a streak of
``streak`` (default 20) consecutive inconsistent steps, and stays flagged
(sticky).  On a matched model the NIS of successive steps are independent
χ²(dof) draws, so a given step starts a false streak with probability
``tail**streak`` (1e-120 by default): a consistent filter is never flagged.
The streak is long so that a filter that is inconsistent for a while and
recovers is not called diverged: on ``p4-maneuver`` (40 runs) the NIS of the
multiple-switching filter stayed beyond the tail for up to 14 steps in a row
during a maneuver, then came back (a streak of 5 flagged 33 of its 40 runs,
of 15 none); a filter that has lost the target stays beyond it.

**The region test** (experiments, where the truth is known).  The physically
possible region of a run is the bounding box of its true positions over all
steps and of the sensor positions (anchors), grown on every side by
``region`` (default 10) times its scale; the scale is the box's largest side,
or the prior's largest position standard deviation when that is larger (a
target that hardly moves).  A position estimate outside it flags the run at
that step, with no streak: ten times the size of everything that happened
away from it is not a tracking error.  This catches the divergence the NIS
cannot see, a particle cloud so spread that its own covariance excuses any
innovation.

The engine's driver (:func:`pursuit.run`) adds the flag to every filter's
step info under the key ``diverged`` (``(K, *batch)``, bool): from the onset
step on, looking at the whole run, so the flag marks where the divergence
began.  The streaming tracker (``pursuit track``) cannot look ahead: there the
flag appears at the step that completes the streak (:class:`DivergenceMonitor`).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Sequence

import numpy as np

from ._chi2 import chi2_isf

__all__ = [
    "DivergenceTest",
    "DivergenceMonitor",
    "detect_divergence",
    "outside_region",
    "possible_region",
    "onset_step",
    "DIVERGED_KEY",
]

DIVERGED_KEY = "diverged"
"""The step-info key of the flag."""


@dataclass(frozen=True)
class DivergenceTest:
    """The thresholds of the divergence tests (see the module docstring).

    Parameters
    ----------
    tail
        Upper-tail probability of χ²(dof) beyond which a step's NIS is
        inconsistent, in (0, 1).
    streak
        Consecutive inconsistent steps (skipping steps with no measurement)
        that flag a run, at least 1.
    region
        How far the physically possible region extends beyond the box of the
        truth and the sensors, in units of the box's scale (> 0).
    """

    tail: float = 1e-6
    streak: int = 20
    region: float = 10.0

    def __post_init__(self) -> None:
        if not (isinstance(self.tail, (int, float)) and 0.0 < self.tail < 1.0):
            raise ValueError(f"tail: must be a probability in (0, 1), got {self.tail!r}")
        if isinstance(self.streak, bool) or not isinstance(self.streak, (int, np.integer)) or self.streak < 1:
            raise ValueError(f"streak: must be an integer >= 1, got {self.streak!r}")
        if not (isinstance(self.region, (int, float)) and np.isfinite(self.region) and self.region > 0):
            raise ValueError(f"region: must be a positive number, got {self.region!r}")

    def threshold(self, dof) -> np.ndarray:
        """The NIS above which a step with ``dof`` measured components is inconsistent."""
        return chi2_isf(self.tail, np.maximum(np.asarray(dof, dtype=float), 1.0))

    def thresholds(self, dof: np.ndarray) -> np.ndarray:
        """:meth:`threshold` of integer ``dof`` through a table (one quantile per distinct dof, not per run)."""
        d = np.maximum(np.asarray(dof, dtype=float), 1.0)
        top = int(d.max(initial=1.0))
        if top > 64 or np.any(d != np.round(d)):
            return self.threshold(d)
        table = _table(self.tail, top)
        return table[d.astype(np.int64)]


@lru_cache(maxsize=64)
def _table(tail: float, top: int) -> np.ndarray:
    """χ²(d) quantiles at upper tail ``tail`` for d = 0 .. top (entry 0 unused: d ≥ 1)."""
    return np.concatenate([[np.inf], chi2_isf(tail, np.arange(1, top + 1))])


def _not_finite(mean: np.ndarray, cov: np.ndarray | None, batch: tuple[int, ...]) -> np.ndarray:
    """``batch`` bool: the estimate (or its covariance) has a non-finite entry."""
    bad = ~np.all(np.isfinite(np.asarray(mean, dtype=float)), axis=-1)
    if cov is not None:
        bad = bad | ~np.all(np.isfinite(np.asarray(cov, dtype=float)), axis=(-2, -1))
    return np.broadcast_to(bad, batch)


class DivergenceMonitor:
    """The consistency test, one step at a time, for a batch of runs.

    Parameters
    ----------
    batch
        The batch shape (runs).
    test
        The thresholds.

    Attributes
    ----------
    onset
        ``batch`` int: index (0-based, in steps seen) of the first step of the
        streak that flagged each run; -1 while it is not flagged.
    """

    def __init__(self, batch: Sequence[int], test: DivergenceTest | None = None):
        self.test = test if test is not None else DivergenceTest()
        self.batch = tuple(int(b) for b in batch)
        self.length = np.zeros(self.batch, dtype=np.int64)  # the current streak
        self.start = np.zeros(self.batch, dtype=np.int64)  # where it began
        self.onset = np.full(self.batch, -1, dtype=np.int64)
        self.steps = 0

    @property
    def flagged(self) -> np.ndarray:
        """``batch`` bool: runs flagged so far."""
        return self.onset >= 0

    def update(self, nis, dof, mean, cov=None) -> np.ndarray:
        """Take one step's NIS, dof, estimate and covariance; returns :attr:`flagged` after it.

        ``nis`` and ``dof`` broadcast to the batch (``nis`` may be None for a
        filter that reports none: then only the finiteness test applies).
        """
        i = self.steps
        nonfinite = _not_finite(mean, cov, self.batch)
        if nis is None:
            measured = np.zeros(self.batch, dtype=bool)
            exceeded = measured
        else:
            nis = np.broadcast_to(np.asarray(nis, dtype=float), self.batch)
            dof = np.broadcast_to(np.asarray(1.0 if dof is None else dof, dtype=float), self.batch)
            with np.errstate(invalid="ignore"):
                measured = (dof > 0) & ~np.isnan(nis)
                exceeded = measured & ~(nis <= self.test.thresholds(np.where(measured, dof, 1.0)))  # +inf exceeds
        bad = nonfinite | exceeded
        good = measured & ~bad
        self.start = np.where(bad & (self.length == 0), i, self.start)
        self.length = np.where(bad, self.length + 1, np.where(good, 0, self.length))
        newly = (self.onset < 0) & (self.length >= self.test.streak)
        self.onset = np.where(newly, self.start, self.onset)
        self.steps += 1
        return self.flagged

    def flags(self) -> np.ndarray:
        """``(steps, *batch)`` bool: each run flagged from its onset step on (looking back over the whole run)."""
        return _sticky(self.onset, self.steps)


def _sticky(onset: np.ndarray, steps: int) -> np.ndarray:
    """``(steps, *batch)``: True from ``onset`` on (never where ``onset`` < 0)."""
    k = np.arange(steps).reshape((steps,) + (1,) * onset.ndim)
    return (onset >= 0) & (k >= onset)


def detect_divergence(
    nis: np.ndarray | None,
    dof: np.ndarray | None,
    mean: np.ndarray,
    cov: np.ndarray | None = None,
    *,
    outside: np.ndarray | None = None,
    test: DivergenceTest | None = None,
) -> np.ndarray:
    """The ``diverged`` flag of whole runs.

    Parameters
    ----------
    nis, dof
        ``(K, *batch)`` NIS and measured dimension per step (``dof`` may be a
        scalar); ``nis`` None when the filter reports none.
    mean
        ``(K, *batch, n)`` estimates.
    cov
        ``(K, *batch, n, n)`` covariances, or None if not kept.
    outside
        ``(K, *batch)`` bool from :func:`outside_region`, or None.
    test
        The thresholds (default :class:`DivergenceTest`).

    Returns
    -------
    np.ndarray
        ``(K, *batch)`` bool, True from the first step of the first streak
        (or the first step outside the region) on.
    """
    mean = np.asarray(mean, dtype=float)
    K, batch = mean.shape[0], mean.shape[1:-1]
    test = test if test is not None else DivergenceTest()
    runs = int(np.prod(batch, dtype=np.int64))
    if K == 0 or runs == 0:
        return np.zeros((K, *batch), dtype=bool)  # no step or no run: nothing can diverge (reshape(..., -1) cannot size an empty array)
    # every step's verdict at once (what DivergenceMonitor.update computes step by step)
    bad = _not_finite_steps(mean.reshape(K, runs, mean.shape[-1]))
    if cov is not None:
        cov = _per_step(np.asarray(cov, dtype=float), K, batch, tail=2)
        bad |= _not_finite_steps(cov.reshape(K, runs, -1))
    measured = np.zeros((K, runs), dtype=bool)
    if nis is not None:
        nis = _per_step(np.asarray(nis, dtype=float), K, batch)
        dof = np.asarray(1.0 if dof is None else dof)
        with np.errstate(invalid="ignore"):
            if dof.ndim == 0:  # one threshold for every step
                measured = ~np.isnan(nis) if dof > 0 else measured
                limit = test.thresholds(np.maximum(dof, 1)[None])[0]
            else:
                dof = _per_step(dof, K, batch)
                measured = (dof > 0) & ~np.isnan(nis)
                limit = _limits(test, dof, measured)
            bad |= measured & ~(nis <= limit)  # +inf exceeds
    onset = np.full(runs, -1, dtype=np.int64)
    if bad.any():
        scan = _may_streak(measured & ~bad, test.streak)
        if scan.size:
            onset[scan] = _streak_onsets(bad[:, scan], measured[:, scan] & ~bad[:, scan], test.streak)
    flags = _sticky(onset.reshape(batch), K) if (onset >= 0).any() else np.zeros((K, *batch), dtype=bool)
    if outside is not None:
        flags = flags | np.logical_or.accumulate(np.asarray(outside, dtype=bool), axis=0)
    return flags


def _per_step(values: np.ndarray, K: int, batch: tuple[int, ...], tail: int = 0) -> np.ndarray:
    """``(K, runs, *last tail axes)``: a scalar, or a ``(K, ...)`` array whose step ``i`` broadcasts to ``batch`` (as ``update`` takes it)."""
    last = values.shape[values.ndim - tail:] if tail else ()
    if values.ndim:
        values = values.reshape(K, *(1,) * (len(batch) + tail - values.ndim + 1), *values.shape[1:])
    runs = int(np.prod(batch, dtype=np.int64))
    return np.broadcast_to(values, (K, *batch, *last)).reshape(K, runs, *last)


def _limits(test: DivergenceTest, dof: np.ndarray, measured: np.ndarray) -> np.ndarray:
    """The NIS threshold of every step: integer ``dof`` through the quantile table, else :meth:`DivergenceTest.thresholds`."""
    if dof.dtype.kind in "iu" and dof.size:
        top, low = max(int(dof.max()), 1), max(int(dof.min()), 1)
        if top == low:  # every step measured as much (a filter with no missing components): one threshold
            return test.thresholds(np.array([top]))[0]
        if top <= 64:  # the table's entry d is the quantile at d (entry 0, unused, where nothing was measured)
            return _table(test.tail, top)[np.clip(dof, 0, top)]
    return test.thresholds(np.where(measured, dof, 1.0))


def _not_finite_steps(values: np.ndarray) -> np.ndarray:
    """``(K, runs)`` bool from ``(K, runs, w)`` floats: some entry of the row is not finite.

    A row with a NaN or an infinity sums to a non-finite value, so a finite
    sum clears a row in one product; the rare rows whose sum is not finite
    (an overflow of large finite entries among them) are checked entry by entry.
    A finite sum of everything clears every row at once (the common case:
    one pass, no temporary the size of the rows).
    """
    with np.errstate(over="ignore", invalid="ignore"):
        if np.isfinite(np.add.reduce(values, axis=None)):
            return np.zeros(values.shape[:2], dtype=bool)
        suspect = ~np.isfinite(values @ np.ones(values.shape[-1]))
    if suspect.any():
        rows = np.nonzero(suspect)
        suspect[rows] = ~np.all(np.isfinite(values[rows]), axis=-1)
    return suspect


def _may_streak(good: np.ndarray, streak: int) -> np.ndarray:
    """Indices of the runs (columns of ``(K, runs)`` bool) that may hold a streak: a necessary test.

    A streak of ``streak`` steps has no consistent measured step inside, and
    any ``streak`` consecutive steps contain a whole aligned block of
    ``b = (streak + 1) // 2`` steps; so a run with a good step in every such
    block cannot be flagged.  A consistent filter has them nearly everywhere,
    and the scan of :func:`_streak_onsets` is left with few runs, if any.
    """
    b = (streak + 1) // 2
    blocks = good.shape[0] // b
    if blocks == 0:
        return np.zeros(0, dtype=np.int64)
    covered = good[: blocks * b].reshape(blocks, b, good.shape[1]).any(axis=1)
    return np.flatnonzero(~covered.all(axis=0))


def _streak_onsets(bad: np.ndarray, good: np.ndarray, streak: int) -> np.ndarray:
    """Onset step of each column's first streak of ``streak`` bad steps (-1: none); ``(K, c)`` bool in.

    The rules of :meth:`DivergenceMonitor.update`, over all steps at once: a
    bad step extends the streak, a good one ends it, any other step leaves it
    as it is.  So at step k the streak holds the bad steps after the last good
    one (a difference of running counts), it first reaches ``streak`` on a bad
    step, and it began at the first bad step after that last good one.
    """
    K, cols = bad.shape
    steps = np.arange(K).reshape(K, 1)
    last_good = np.maximum.accumulate(np.where(good, steps, -1), axis=0)
    count = np.cumsum(bad, axis=0, dtype=np.int64)
    col = np.arange(cols)
    before = np.where(last_good >= 0, count[np.maximum(last_good, 0), col], 0)
    reached = (count - before) >= streak
    onset = np.full(cols, -1, dtype=np.int64)
    hit = np.flatnonzero(reached.any(axis=0))
    if hit.size:
        first = reached[:, hit].argmax(axis=0)
        next_bad = np.minimum.accumulate(np.where(bad[:, hit], steps, K)[::-1], axis=0)[::-1]  # first bad step >= k
        onset[hit] = next_bad[last_good[first, hit] + 1, np.arange(hit.size)]
    return onset


def possible_region(
    truth: np.ndarray,
    position_indices: Sequence[int],
    *,
    sensors: np.ndarray | None = None,
    scale: np.ndarray | float | None = None,
    test: DivergenceTest | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """The physically possible region of each run: ``(low, high)``, each ``(*batch, d)``.

    Parameters
    ----------
    truth
        ``(K, *batch, n)`` true states.
    position_indices
        The ``d`` position components.
    sensors
        ``(s, d)`` sensor positions (only their first ``d`` columns are used), or None.
    scale
        A floor on the box's scale broadcasting to ``batch`` (e.g. the prior's
        largest position standard deviation), or None.
    test
        ``test.region`` is the margin in units of the scale.
    """
    test = test if test is not None else DivergenceTest()
    idx = list(position_indices)
    pos = np.asarray(truth, dtype=float)[..., idx]
    low, high = np.nanmin(pos, axis=0), np.nanmax(pos, axis=0)
    if sensors is not None and len(sensors):
        s = np.asarray(sensors, dtype=float)[:, : len(idx)]
        if s.shape[1] == len(idx):
            low, high = np.minimum(low, s.min(axis=0)), np.maximum(high, s.max(axis=0))
    size = np.max(high - low, axis=-1)
    if scale is not None:
        size = np.maximum(size, scale)
    margin = (test.region * size)[..., None]
    return low - margin, high + margin


def outside_region(
    estimates: np.ndarray,
    truth: np.ndarray,
    position_indices: Sequence[int],
    *,
    sensors: np.ndarray | None = None,
    scale: np.ndarray | float | None = None,
    test: DivergenceTest | None = None,
) -> np.ndarray:
    """``(K, *batch)`` bool: the position estimate lies outside the run's :func:`possible_region`.

    A non-finite position is outside.  With no position components nothing
    is outside (the test does not apply).
    """
    est = np.asarray(estimates, dtype=float)
    if not len(position_indices):
        return np.zeros(est.shape[:-1], dtype=bool)
    low, high = possible_region(truth, position_indices, sensors=sensors, scale=scale, test=test)
    pos = est[..., list(position_indices)]
    with np.errstate(invalid="ignore"):
        inside = np.all((pos >= low) & (pos <= high), axis=-1)
    return ~inside


def onset_step(flags: np.ndarray) -> np.ndarray:
    """``batch`` float: the 1-based step at which each run was first flagged, NaN if never.

    ``flags`` is ``(K, *batch)`` bool, time first.
    """
    flags = np.asarray(flags, dtype=bool)
    any_flag = flags.any(axis=0)
    first = np.argmax(flags, axis=0).astype(float) + 1.0
    return np.where(any_flag, first, np.nan)
