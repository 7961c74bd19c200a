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

from dataclasses import dataclass
from typing import Iterable, Iterator

import numpy as np

from ..divergence import DIVERGED_KEY, DivergenceMonitor
from ..rng import RunStreams
from .initiate import initiate
from .model import TrackModel
from .records import BadRecord, Record
from .steps import Dropped, Step, assemble_steps, sort_records

__all__ = ["Estimate", "Tracker", "StepRefused", "TrackResult", "track_records", "stream_records"]


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
        self.monitor = DivergenceMonitor((1,))

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
        flags = [key for key, value in info.items() if _true_flag(value)]
        if dof == 0:
            flags.append("predict")
        if self.monitor.update(info.get("nis"), info.get("dof"), state.mean, state.cov)[0] and DIVERGED_KEY not in flags:
            flags.append(DIVERGED_KEY)
        return Estimate(
            time=step.time,
            mean=mean,
            var=var,
            nis=float(np.asarray(info["nis"]).reshape(-1)[0]),
            dof=dof,
            flags=tuple(flags),
            lines=step.lines,
            cov=np.asarray(state.cov, dtype=float)[0],
        )


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


def stream_records(
    items: Iterable[Record | BadRecord], model: TrackModel, *, out_of_order: str = "drop", stop_at_bad: bool = False
) -> Iterator[Estimate | BadRecord | Dropped]:
    """Run the model's filter over records as they arrive.

    Yields estimates, bad records and dropped-record notices in the order
    they are known; an estimate for time t comes out as soon as a record
    with a later time (or the end of the input) shows that step t is
    complete.  A refused step (see :class:`Tracker`) yields one bad record
    per line of the step and the filter goes on from its previous state.
    With ``stop_at_bad`` the input ends at the first bad record: the
    records before it are filtered, then the bad record is yielded last.
    """
    policy = "error" if out_of_order == "sort" else out_of_order
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
    for event in steps:
        if isinstance(event, Step):
            try:
                yield tracker.update(event)
            except StepRefused as e:
                yield from _refused(event, e)
                if stop_at_bad:
                    return
        else:
            yield event
