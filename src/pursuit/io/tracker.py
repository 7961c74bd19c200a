"""Running a configured filter over recorded steps, one at a time.

:class:`Tracker` holds the filter's state and the time it refers to; each
:class:`~pursuit.io.steps.Step` advances it by ``dt = t_k − t_{k−1}`` (the
motion models take dt per step, so irregular sampling needs nothing else)
and gives an :class:`Estimate`.  A step that would leave the filter with a
non-finite or non-positive estimate (a measurement absurd enough to overflow,
a gap of 10³⁰⁰ s) is refused: the state stays as it was and the step's
records are reported as bad (field ``time`` when a prediction alone over the
gap already breaks the filter, else ``record``), so no NaN ever reaches the
output.

A filter that diverges is flagged, not hidden: the tracker runs the
consistency test of :mod:`pursuit.divergence` step by step, and from the step
that completes a streak of inconsistent NIS values on, every estimate carries
the flag ``diverged`` (a stream cannot look back, so the flag starts at the
end of the streak, not at its first step as in an experiment).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Callable, Iterable, Iterator

import numpy as np

from ..divergence import DIVERGED_KEY, DivergenceTest
from ..filters.gaussian import GaussianState
from ..rng import RunStreams
from .initiate import initiate
from .model import TrackModel
from .records import BadRecord, Record
from .blocks import EstimateBlock, StepBlock
from .steps import INPUT_WAITS, Dropped, Step, assemble_steps, block_steps, mark_waits, sort_records

__all__ = ["Estimate", "Tracker", "StepRefused", "TrackResult", "track_records", "stream_records", "block_estimates", "BLOCK_STEPS"]

BLOCK_STEPS = 4096
"""The most steps :func:`stream_records` filters in one block (one compiled call where the filter has one)."""


@dataclass(frozen=True)
class Estimate:
    """The filter's estimate after one step.

    Attributes
    ----------
    time
        Step time, s.
    mean
        ``(n,)`` state estimate.
    var
        ``(n,)`` diagonal of the estimate's covariance.
    nis
        Normalised innovation squared (NaN when nothing was measured).
    dof
        Number of measured components.
    flags
        Names of the step's true boolean info entries (``gated``,
        ``repaired``, and any a filter adds), plus ``predict`` when nothing
        was measured and ``diverged`` once the track has failed the
        divergence test (:mod:`pursuit.divergence`; it stays).
    lines
        Input lines of the step's records.
    cov
        ``(n, n)`` covariance of the estimate.
    """

    time: float
    mean: np.ndarray
    var: np.ndarray
    nis: float
    dof: int
    flags: tuple[str, ...]
    lines: tuple[int, ...]
    cov: np.ndarray | None = None


class StepRefused(Exception):
    """A step whose update would break the filter; the state is unchanged.

    ``field`` names what to blame: ``"time"`` when even a prediction over
    the step's gap would break the filter (a gap of 10³⁰⁰ s), else
    ``"record"`` (the update with the step's measurements, from the state
    the filter is in).
    """

    def __init__(self, message: str, field: str = "record"):
        super().__init__(message)
        self.field = field


class Tracker:
    """A configured filter advancing over recorded steps.

    Parameters
    ----------
    model
        The loaded MODEL.toml.
    """

    def __init__(self, model: TrackModel):
        if model.prior is None:
            raise ValueError("model: its prior is to come from the measurements; run it with stream_records or track_records")
        self.model = model
        rng = RunStreams([np.random.default_rng(model.seed)])
        self.state = model.filter.init(model.prior, batch=(1,), rng=rng)
        self.time = model.prior_time
        self.k = 0
        self.monitor = _Streak(DivergenceTest())
        self._flag_keys: tuple[str, ...] | None = None  # the boolean info keys of a step, in the step's order
        self._sequence_off = not getattr(model.filter, "compiled", False)

    def _try(self, z: np.ndarray, dt: float):
        """One filter step from the current state: ``(problem, state, info, mean, var)``, problem '' if healthy."""
        try:
            with np.errstate(all="ignore"):  # overflow is detected below, not warned about
                state, info = self.model.filter.step(self.state, z[None, :], k=self.k + 1, dt=dt)
                mean = np.asarray(state.mean, dtype=float)[0]
                cov = np.asarray(state.cov, dtype=float)[0]
                var = np.diagonal(cov).copy()
                healthy = np.all(np.isfinite(mean)) and np.all(np.isfinite(cov)) and np.all(var > 0)
        except (ArithmeticError, ValueError, np.linalg.LinAlgError) as e:
            return f"the filter failed: {_describe(e)}", None, None, None, None
        if not healthy:
            return "the estimate would not be finite with positive variances", None, None, None, None
        if np.any(np.asarray(info["nis"]) < 0):  # exactly S ⪰ R > 0: a negative NIS is round-off, never written
            return "round-off made its NIS negative (the covariance is too large for the sensors' noise)", None, None, None, None
        return "", state, info, mean, var

    def update(self, step: Step) -> Estimate:
        """Advance to ``step.time`` and update with ``step.z``.

        Raises
        ------
        StepRefused
            When the result would not be finite with a positive variance; the
            tracker's state is left unchanged.  Its ``field`` is ``"time"``
            when a prediction alone over the gap ``dt`` already breaks the
            filter, else ``"record"``.
        """
        dt = self.model.dt if self.time is None else step.time - self.time
        if not dt > 0:  # pragma: no cover - the step assembler guarantees increasing times
            raise StepRefused(f"time {step.time!r} is not after {self.time!r}", "time")
        problem, state, info, mean, var = self._try(step.z, dt)
        if problem:
            # blame the gap when a prediction alone over it breaks the filter, else the measurement
            gap_problem = self._try(np.full_like(step.z, np.nan), dt)[0] if np.any(np.isfinite(step.z)) else problem
            since = "the prior" if self.time is None else f"the previous step at {self.time!r}"
            if gap_problem:
                raise StepRefused(f"{dt:g} s after {since} is a gap the filter cannot predict across ({gap_problem})", "time")
            raise StepRefused(f"updating with this step's measurements would break the filter (dt = {dt:g} s): {problem}", "record")
        self.state, self.time, self.k = state, step.time, self.k + 1
        dof = int(np.asarray(info["dof"]).reshape(-1)[0])
        self._flag_keys = tuple(key for key, value in info.items() if np.asarray(value).dtype == bool)
        flags = [key for key, value in info.items() if _true_flag(value)]
        nis = float(np.asarray(info["nis"]).reshape(-1)[0])
        return self._estimate(step, mean, var, np.asarray(state.cov, dtype=float)[0], nis, dof, flags)

    def _estimate(self, step: Step, mean, var, cov, nis: float, dof: int, flags: list[str]) -> Estimate:
        if dof == 0:
            flags.append("predict")
        if self.monitor.update(nis, dof) and DIVERGED_KEY not in flags:
            flags.append(DIVERGED_KEY)
        return Estimate(time=step.time, mean=mean, var=var, nis=nis, dof=dof, flags=tuple(flags), lines=step.lines, cov=cov)

    @property
    def needs_step(self) -> bool:
        """Whether :meth:`update_sequence` needs a step by :meth:`update` first (to learn the filter's flags)."""
        return self._flag_keys is None and not self._sequence_off

    def update_sequence(self, steps: list[Step]) -> list[Estimate] | None:
        """Advance over ``steps`` in one compiled call, or None (nothing changed) where that does not apply.

        Applies to a compiled filter whose :meth:`~pursuit.filters.base.FilterBase.run_sequence`
        runs from the current state (a KF/EKF with a time-invariant linear motion and no
        gate), when every step comes the model's ``dt`` after the one before it and the
        whole block is healthy.  The compiled sequence gives the bits of ``len(steps)``
        calls of :meth:`update` (the filter's contract), so the estimates are those
        :meth:`update` would give; otherwise the caller steps the block.
        """
        if not steps:
            return None
        times = np.fromiter((s.time for s in steps), dtype=float, count=len(steps))
        result = self._sequence(times, np.stack([s.z for s in steps]))
        if result is None:
            return None
        means, covs, var, nis, dof, flag_rows = result
        out = []
        for i, step in enumerate(steps):
            flags = [key for key, row in zip(self._flag_keys, flag_rows) if row[i]]
            out.append(self._estimate(step, means[i], var[i].copy(), covs[i], float(nis[i]), int(dof[i]), flags))
        return out

    def update_block(self, times: np.ndarray, zs: np.ndarray, lines: np.ndarray) -> EstimateBlock | None:
        """:meth:`update_sequence` on steps given as columns (times ``(n,)``, measurements ``(n, m)``, one line each).

        The estimates are those of :meth:`update_sequence` (and so of
        :meth:`update`), as one :class:`~pursuit.io.blocks.EstimateBlock`; None
        (nothing changed) where the compiled sequence does not apply.
        """
        result = self._sequence(times, zs) if len(times) else None
        if result is None:
            return None
        means, covs, var, nis, dof, flag_rows = result
        n = len(times)
        diverged = self.monitor.update_many(nis, dof)
        # each row's flags as bits (the filter's flag keys, then "predict", then "diverged"): the names of each
        # distinct pattern are made once, so a long flagged stretch (a diverged track) costs a lookup per row
        columns = [np.asarray(row, dtype=bool) for row in flag_rows]
        columns += [np.asarray(dof) == 0, np.asarray(diverged, dtype=bool)]
        code = np.zeros(n, dtype=np.int64)
        for bit, column in enumerate(columns):
            code |= column.astype(np.int64) << bit
        flags: list[tuple[str, ...]] = [()] * n
        marked = np.flatnonzero(code)
        if marked.size:
            codes = code[marked].tolist()
            names = {c: self._flag_names(c) for c in set(codes)}
            for i, c in zip(marked.tolist(), codes):
                flags[i] = names[c]
        return EstimateBlock(times, means, var, nis, dof, flags, lines, covs)

    def _flag_names(self, code: int) -> tuple[str, ...]:
        """The flags of a row whose bits are ``code`` (see :meth:`update_block`), in :meth:`_estimate`'s order."""
        keys = self._flag_keys
        names = [key for bit, key in enumerate(keys) if code >> bit & 1]
        if code >> len(keys) & 1:
            names.append("predict")
        if code >> (len(keys) + 1) & 1 and DIVERGED_KEY not in names:
            names.append(DIVERGED_KEY)
        return tuple(names)

    def _sequence(self, times: np.ndarray, zs: np.ndarray):
        """The compiled sequence from the current state over ``zs`` at ``times``, advancing the tracker.

        ``(means, covs, var, nis, dof, flag_rows)``, or None (nothing changed)
        where it does not apply or the block is not healthy.
        """
        if self._sequence_off or self._flag_keys is None or self.time is None or not isinstance(self.state, GaussianState):
            return None
        n = len(times)
        dts = np.diff(times, prepend=self.time)
        if not np.all(dts == self.model.dt) or getattr(self.state, "memory", None) is not None:
            return None  # irregular sampling: the motion differs per step, which the sequence cannot take
        zs = zs[:, None, :]
        try:
            start = dataclasses.replace(self.state, k=0)  # the model is time-invariant: k names no step in it
            with np.errstate(all="ignore"):
                result = self.model.filter.run_sequence(start, zs, keep_cov=True)
        except (ArithmeticError, ValueError, np.linalg.LinAlgError):
            return None  # this block's numbers: stepping it reports the step that breaks the filter
        if result is None:
            self._sequence_off = True  # it will not apply later either (the filter or its models)
            return None
        means, covs, info = result
        if any(key not in info for key in self._flag_keys):
            self._sequence_off = True
            return None
        means, covs = means[:, 0], covs[:, 0]
        var = np.diagonal(covs, axis1=1, axis2=2)
        nis = np.asarray(info["nis"], dtype=float).reshape(n)
        with np.errstate(invalid="ignore"):
            healthy = np.all(np.isfinite(means)) and np.all(np.isfinite(covs)) and np.all(var > 0) and not np.any(nis < 0)
        if not healthy:
            return None  # the caller steps the block and refuses the steps that break the filter
        dof = np.asarray(info["dof"]).reshape(n).tolist()
        flag_rows = [np.asarray(info[key]).reshape(n).tolist() for key in self._flag_keys]
        self.state = dataclasses.replace(self.state, mean=means[-1:].copy(), cov=covs[-1:].copy(), k=self.k + n)
        self.time, self.k = float(times[-1]), self.k + n
        return means, covs, var, nis, dof, flag_rows


class _Streak:
    """The consistency test of :class:`pursuit.divergence.DivergenceMonitor` for one run, in Python scalars.

    The tracker refuses every step whose estimate is not finite, so only the
    NIS streak applies; this is the monitor's arithmetic for a batch of one,
    without an array operation per step.
    """

    def __init__(self, test: DivergenceTest):
        self.test = test
        self.length = 0
        self.flagged = False
        self._thresholds: dict[int, float] = {}

    def update(self, nis: float, dof: int) -> bool:
        """Take one accepted step's NIS and measured dimension; whether the run is flagged after it."""
        if dof > 0 and not math.isnan(nis):
            limit = self._thresholds.get(dof)
            if limit is None:
                limit = self._thresholds[dof] = float(self.test.thresholds(np.asarray([float(dof)]))[0])
            if not nis <= limit:  # +inf exceeds
                self.length += 1
            else:
                self.length = 0
        if self.length >= self.test.streak:
            self.flagged = True
        return self.flagged

    def update_many(self, nis: np.ndarray, dof: list[int]) -> np.ndarray:
        """:meth:`update` over consecutive steps, as array operations; whether the run is flagged after each.

        The same counts as :meth:`update` step by step (integers and the same
        comparison, so no rounding can differ): a measured step over its
        threshold lengthens the streak, a measured step within it ends it, an
        unmeasured step leaves it; the run is flagged from the first step whose
        streak reaches ``test.streak`` on.
        """
        nis = np.asarray(nis, dtype=float)
        dofs = np.asarray(dof, dtype=np.int64)
        n = len(nis)
        measured = (dofs > 0) & ~np.isnan(nis)
        limits = np.full(n, np.inf)
        for k in np.unique(dofs[measured]).tolist():
            limit = self._thresholds.get(k)
            if limit is None:
                limit = self._thresholds[k] = float(self.test.thresholds(np.asarray([float(k)]))[0])
            limits[dofs == k] = limit
        over = measured & ~(nis <= limits)  # +inf exceeds, as in update
        ends = measured & ~over
        count = np.cumsum(over)
        # the streak after step i: the steps over since the last step that ended it (or since the block began, on
        # top of the length carried in)
        last_end = np.maximum.accumulate(np.where(ends, np.arange(n), -1))
        since = np.where(last_end >= 0, count[np.maximum(last_end, 0)], -self.length)
        length = count - since
        flagged = np.logical_or.accumulate((length >= self.test.streak) | self.flagged)
        if n:
            self.length, self.flagged = int(length[-1]), bool(flagged[-1])
        return flagged


def _initiation_estimate(step: Step, g, flags: tuple[str, ...]) -> Estimate:
    """The output record of a step used to start the track (no filter update, no NIS)."""
    measured = int(np.count_nonzero(np.isfinite(step.z)))
    return Estimate(step.time, g.mean, np.diagonal(g.cov).copy(), float("nan"), measured, flags, step.lines, g.cov)


def _describe(e: Exception) -> str:
    if isinstance(e, OverflowError):
        return "a number overflows"
    return f"{type(e).__name__}: {e}" if str(e) else type(e).__name__


def _true_flag(value) -> bool:
    arr = np.asarray(value)
    return arr.dtype == bool and arr.size == 1 and bool(arr.reshape(-1)[0])


def _refused(step: Step, refusal: StepRefused) -> list[BadRecord]:
    return [BadRecord(line, refusal.field, f"rejected at time {step.time!r}: {refusal}") for line in step.lines]


@dataclass
class TrackResult:
    """Everything a batch run over a file produced.

    Attributes
    ----------
    estimates
        One per step, in time order.
    problems
        Bad records, sorted by line.
    dropped
        Late records dropped under the ``drop`` policy.
    """

    estimates: list[Estimate]
    problems: list[BadRecord]
    dropped: list[Dropped]


def track_records(items: Iterable[Record | BadRecord], model: TrackModel, *, out_of_order: str = "sort") -> TrackResult:
    """Run the model's filter over every record of a file.

    Bad records are skipped and collected; the caller decides whether any
    estimate may be written (``pursuit track`` writes none unless
    ``--skip-bad``).

    Parameters
    ----------
    items
        Records from :func:`pursuit.io.read_records`.
    model
        The loaded model.
    out_of_order
        ``"sort"`` (default), ``"drop"`` or ``"error"``; see
        :mod:`pursuit.io.steps`.
    """
    items = sort_records(items) if out_of_order == "sort" else list(items)
    result = TrackResult([], [], [])
    for event in stream_records(items, model, out_of_order=out_of_order):
        if isinstance(event, Estimate):
            result.estimates.append(event)
        elif isinstance(event, Dropped):
            result.dropped.append(event)
        else:
            result.problems.append(event)
    result.problems.sort(key=lambda p: p.line)
    result.dropped.sort(key=lambda p: p.line)
    return result


def _filter_block(tracker: Tracker, block: list[Step | StepBlock], stop_at_bad: bool) -> Iterator[Estimate | EstimateBlock | BadRecord]:
    """Filter a block of steps (in one compiled call where that applies); returns True when a refusal stops the input."""
    if not tracker.needs_step and all(isinstance(seg, StepBlock) or len(seg.lines) == 1 for seg in block):
        times = np.concatenate([seg.times if isinstance(seg, StepBlock) else [seg.time] for seg in block])
        zs = np.concatenate([seg.z if isinstance(seg, StepBlock) else seg.z[None, :] for seg in block])
        lines = np.concatenate([seg.lines if isinstance(seg, StepBlock) else seg.lines for seg in block])
        estimates = tracker.update_block(times, zs, lines)
        if estimates is not None:
            yield estimates
            return False
        first = -1  # the sequence did not apply: step the block (update_sequence would say the same)
    else:
        first = 1 if tracker.needs_step else 0  # one step by update() first tells which info keys are flags
    steps = [step for seg in block for step in (block_steps(seg) if isinstance(seg, StepBlock) else (seg,))]
    estimates = None
    for i, step in enumerate(steps):
        if i == first:
            estimates = tracker.update_sequence(steps[i:])
            if estimates is not None:
                break
        try:
            yield tracker.update(step)
        except StepRefused as e:
            yield from _refused(step, e)
            if stop_at_bad:
                return True
    if estimates is not None:
        yield from estimates
    return False


def stream_records(
    items: Iterable[Record | BadRecord],
    model: TrackModel,
    *,
    out_of_order: str = "drop",
    stop_at_bad: bool = False,
    ready: Callable[[], bool] | None = None,
    blocks: bool = False,
) -> Iterator[Estimate | EstimateBlock | BadRecord | Dropped]:
    """Run the model's filter over records as they arrive.

    Yields estimates, bad records and dropped-record notices in the order
    they are known; an estimate for time t comes out as soon as a record
    with a later time (or the end of the input) shows that step t is
    complete.  A refused step (see :class:`Tracker`) yields one bad record
    per line of the step and the filter goes on from its previous state.
    With ``stop_at_bad`` the input ends at the first bad record: the
    records before it are filtered, then the bad record is yielded last.

    Complete steps are filtered in blocks of up to :data:`BLOCK_STEPS` (one
    compiled call where :meth:`Tracker.update_sequence` applies, else step by
    step; the estimates are the same either way).  ``ready`` says whether the
    input has more lines at hand without waiting (a live stream); a block ends
    before any read that may wait (:func:`pursuit.io.steps.mark_waits`), so no
    complete step waits for a record that has not arrived.  None: the input
    never waits (a list, a file), or ``items`` carries its own
    :data:`~pursuit.io.steps.INPUT_WAITS` marks (:func:`pursuit.io.records.read_record_chunks`).
    ``items`` may hold :class:`~pursuit.io.blocks.RecordBlock` objects; with
    ``blocks`` the estimates of a block filtered in one compiled call come out
    as one :class:`~pursuit.io.blocks.EstimateBlock` (for a writer's
    :meth:`~pursuit.io.writers.EstimateWriter.write_block`), else one
    :class:`Estimate` each.
    """
    policy = "error" if out_of_order == "sort" else out_of_order
    if ready is not None:
        items = mark_waits(items, ready)
    steps = assemble_steps(
        items,
        model.sensors,
        model.measurement_dim,
        after=model.prior_time,
        policy=policy,
        stop_at_bad=stop_at_bad,
        max_gap=model.input.max_gap,
    )
    if model.prior is None:  # [prior] from = "measurements": the first steps that fix a position start the track
        model = yield from initiate(steps, model, _initiation_estimate)
        if model is None:
            return
    tracker = Tracker(model)
    for event in _blocks(tracker, steps, stop_at_bad):
        if isinstance(event, EstimateBlock) and not blocks:
            yield from block_estimates(event)
        else:
            yield event


def _blocks(tracker: Tracker, steps: Iterable, stop_at_bad: bool) -> Iterator[Estimate | EstimateBlock | BadRecord | Dropped]:
    """The events of :func:`stream_records` once the tracker is set up: steps filtered in blocks."""
    block: list[Step | StepBlock] = []
    size = 0
    for event in steps:
        if isinstance(event, StepBlock) and size + len(event) > BLOCK_STEPS:  # the part that fits, then the rest
            while size + len(event) > BLOCK_STEPS:
                room = BLOCK_STEPS - size
                block.append(event.part(0, room))
                if (yield from _filter_block(tracker, block, stop_at_bad)):
                    return
                block, size, event = [], 0, event.part(room, len(event))
        if isinstance(event, (Step, StepBlock)):
            block.append(event)
            size += len(event) if isinstance(event, StepBlock) else 1
            if size < BLOCK_STEPS:
                continue
        if block:  # the block is full, the input would wait, or another kind of event comes next
            if (yield from _filter_block(tracker, block, stop_at_bad)):
                return
            block, size = [], 0
        if isinstance(event, (Step, StepBlock)) or event is INPUT_WAITS:
            continue
        yield event
    if block:
        yield from _filter_block(tracker, block, stop_at_bad)


def block_estimates(block: EstimateBlock) -> list[Estimate]:
    """An :class:`~pursuit.io.blocks.EstimateBlock` as :class:`Estimate` objects (for ``--truth`` and ``--plot``)."""
    return [
        Estimate(time=t, mean=block.means[i], var=block.var[i].copy(), nis=nis, dof=dof, flags=flags, lines=(line,), cov=block.covs[i])
        for i, (t, nis, dof, flags, line) in enumerate(
            zip(block.times.tolist(), block.nis.tolist(), block.dof, block.flags, block.lines.tolist())
        )
    ]
