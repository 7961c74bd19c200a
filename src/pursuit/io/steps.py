"""Records to filter steps: grouping by time, and the out-of-order policy.

All records with the same time form one filter step; their sensors fill
their blocks of the measurement vector and every sensor that did not report
stays NaN (missing), so several sensors at one time and missing sensors need
nothing special.  A step is complete when a record with a later time arrives
or the input ends.

Records that arrive out of time order are handled by a policy:

``sort``
    (files only) records are sorted by time before filtering; records with
    equal times keep their file order.
``drop``
    a record older than the step being assembled is dropped with a warning
    (the default for live streams: a late packet cannot change estimates
    already written).
``error``
    such a record is a bad record.

Whatever the policy, a record at or before the prior's time, a second
record of one sensor at one time, and a record more than ``max_gap`` after
the last time reached (a corrupt clock far more likely than a pause the
model could predict across; see :mod:`pursuit.io.input_spec`) are bad
records.  The last time reached stays where it was, so the records after
such a one go on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Callable, Iterable, Iterator, Mapping

import numpy as np

from .blocks import RecordBlock, StepBlock
from .lines import INPUT_WAITS
from .records import BadRecord, Record, block_records, check_record

__all__ = ["Step", "Dropped", "OUT_OF_ORDER", "INPUT_WAITS", "assemble_steps", "block_steps", "mark_waits", "sort_records"]

OUT_OF_ORDER = ("sort", "drop", "error")


@dataclass(frozen=True)
class Step:
    """One filter step: every record at one time.

    Attributes
    ----------
    time
        The step's time, s.
    z
        ``(m,)`` measurement vector; NaN where no sensor reported.
    lines
        Input lines of the records in this step.
    sensors
        Ids of the sensors that reported.
    """

    time: float
    z: np.ndarray
    lines: tuple[int, ...]
    sensors: tuple[str, ...]


@dataclass(frozen=True)
class Dropped:
    """A late record dropped under the ``drop`` policy (a warning, not an error)."""

    line: int
    message: str

    def __str__(self) -> str:
        return f"line {self.line}: time: {self.message}"


def sort_records(items: Iterable[Record | BadRecord]) -> list[Record | BadRecord]:
    """Bad records first, then the good ones sorted by time.

    The sort is stable, so records with equal times keep their input order;
    bad records are reported by line number, so their place does not matter.
    """
    items = list(items)
    bad = [r for r in items if isinstance(r, BadRecord)]
    good = sorted((r for r in items if isinstance(r, Record)), key=lambda r: r.time)
    return [*bad, *good]




def mark_waits(items: Iterable[Any], ready: Callable[[], bool]) -> Iterator[Any]:
    """``items`` with :data:`INPUT_WAITS` before each item whose taking may wait.

    ``ready()`` says whether the next line is at hand (see
    :meth:`pursuit.io.lines.ChunkedLines.ready`).  :func:`assemble_steps`
    passes the marks on, so a consumer can finish what it holds (steps that
    are complete but not yet filtered) before the input blocks.
    """
    it = iter(items)
    while True:
        if not ready():
            yield INPUT_WAITS
        try:
            item = next(it)
        except StopIteration:
            return
        yield item


def assemble_steps(
    items: Iterable[Record | BadRecord],
    sensors: Mapping[str, object],
    measurement_dim: int,
    *,
    after: float | None = None,
    policy: str = "error",
    stop_at_bad: bool = False,
    max_gap: float = math.inf,
) -> Iterator[Step | BadRecord | Dropped]:
    """Group records into steps, lazily (one step of look-ahead).

    Parameters
    ----------
    items
        Records in arrival order (sort them first for the ``sort`` policy);
        bad records and :data:`INPUT_WAITS` marks are passed through.  A
        :class:`~pursuit.io.blocks.RecordBlock` of one sensor at strictly
        increasing good times gives one :class:`~pursuit.io.blocks.StepBlock`
        (all its steps but the last, which stays open); any other block is
        taken record by record.
    sensors
        The configured sensors by id (``dim``, ``valid``, ``block``).
    measurement_dim
        Length of the measurement vector.
    after
        The prior's time: records must come strictly later.
    policy
        ``"drop"`` or ``"error"`` for a record older than the step being
        assembled (``"sort"`` behaves as ``"error"``: after sorting, no
        record is late).
    stop_at_bad
        End at the first bad record, as if the input ended just before it:
        the step being assembled is yielded, then the bad record.
    max_gap
        A record more than this many seconds after the last time reached
        (the step being assembled, else ``after``) is a bad record.  The
        first record has no time to be measured from when ``after`` is None.

    Yields
    ------
    Step, StepBlock, BadRecord, Dropped or INPUT_WAITS
        In input order; a step is yielded when a later record arrives or the
        input ends.
    """
    if policy not in OUT_OF_ORDER:
        raise ValueError(f"policy: must be one of {', '.join(OUT_OF_ORDER)}, got {policy!r}")
    pending: list[Record] = []
    pending_time: float | None = None
    for item in items:
        if item is INPUT_WAITS:
            yield item  # the step being assembled stays open: a record of its time may still come
            continue
        if isinstance(item, RecordBlock):
            fast = _plain_block(item, sensors, measurement_dim, after, pending_time, max_gap)
            if fast is not None:
                if pending:
                    yield _make_step(pending, sensors, measurement_dim)
                steps, last = fast
                if steps is not None:
                    yield steps
                pending, pending_time = [last], last.time  # the last time stays open: a record of it may still come
                continue
            todo = block_records(item)  # the block is not plain: record by record, as the reference
        else:
            todo = (item,)
        for rec in todo:
            bad = _problem(rec, sensors, after, pending, pending_time, policy)
            if bad is None:
                bad = _too_far(rec, pending[0].line if pending else None, pending_time if pending else after, max_gap)
            if isinstance(bad, Dropped):
                yield bad
                continue
            if bad is not None:
                if stop_at_bad:
                    if pending:
                        yield _make_step(pending, sensors, measurement_dim)
                    yield bad
                    return
                yield bad
                continue
            if pending_time is not None and rec.time > pending_time:
                yield _make_step(pending, sensors, measurement_dim)
                pending = []
            pending.append(rec)
            pending_time = rec.time
    if pending:
        yield _make_step(pending, sensors, measurement_dim)


def _plain_block(
    block: RecordBlock, sensors: Mapping[str, Any], m: int, after: float | None, pending_time: float | None, max_gap: float
) -> tuple[StepBlock | None, Record] | None:
    """A block whose records are each a step of their own and all good: (its steps but the last, the last record).

    None when any record of the block is bad, late, shares a time or needs
    another rule: the caller then takes it record by record.
    """
    names = set(block.sensors)
    if len(names) != 1:
        return None
    (sid,) = names
    spec = sensors.get(sid)
    values, times = block.values, block.times
    if spec is None or spec.dim != values.shape[1]:
        return None
    lo, hi = spec.valid
    if not (np.all(values >= lo) and np.all(values <= hi)):
        return None
    reached = pending_time if pending_time is not None else after
    if after is not None and not times[0] > after:
        return None
    if pending_time is not None and not times[0] > pending_time:
        return None
    gaps = np.diff(times)
    if not np.all(gaps > 0) or np.any(gaps > max_gap):
        return None
    if reached is not None and times[0] - reached > max_gap:
        return None
    last = Record(int(block.lines[-1]), float(times[-1]), sid, tuple(values[-1].tolist()))
    n = len(times)
    if n == 1:
        return None, last
    z = np.full((n - 1, m), math.nan)
    z[:, spec.block] = values[:-1]
    return StepBlock(times[:-1], z, block.lines[:-1], block.sensors[:-1]), last


def _problem(item, sensors, after, pending, pending_time, policy) -> BadRecord | Dropped | None:
    """Why ``item`` cannot join the steps, or None when it can."""
    if isinstance(item, BadRecord):
        return item
    rec = check_record(item, sensors)
    if isinstance(rec, BadRecord):
        return rec
    # Before the late-record policy: at or before the prior's time is bad whatever the policy.
    if after is not None and rec.time <= after:
        return BadRecord(rec.line, "time", f"{rec.time!r} is not after the prior's time {after!r}")
    if pending_time is not None and rec.time < pending_time:
        message = f"{rec.time!r} is earlier than time {pending_time!r} already reached (line {pending[0].line})"
        if policy == "drop":
            return Dropped(rec.line, f"{message}; late record dropped")
        return BadRecord(rec.line, "time", f"out of order: {message}")
    if rec.sensor is not None and rec.time == pending_time:
        twin = next((p for p in pending if p.sensor == rec.sensor), None)
        if twin is not None:
            return BadRecord(rec.line, "sensor", f"{rec.sensor!r} already has a measurement at time {rec.time!r} (line {twin.line})")
    return None


def _too_far(rec: Record, line: int | None, reached: float | None, max_gap: float) -> BadRecord | None:
    """A bad record when ``rec`` comes more than ``max_gap`` after the time ``reached`` (of input ``line``)."""
    if reached is None or not rec.time - reached > max_gap:
        return None
    where = f"time {reached!r} (line {line})" if line is not None else f"the prior's time {reached!r}"
    return BadRecord(
        rec.line,
        "time",
        f"{rec.time!r} is {rec.time - reached:.6g} s after {where}, more than the largest gap the model predicts "
        f"across (input.max_gap = {max_gap:.6g} s): a corrupt time?",
    )


def _make_step(records: list[Record], sensors: Mapping[str, object], m: int) -> Step:
    z = [math.nan] * m  # a list, then one array: cheaper than filling an array for a step of one or two records
    if len(records) == 1:  # the usual step: one record, one line
        r = records[0]
        if r.sensor is not None:
            z[sensors[r.sensor].block] = r.values
        return Step(time=r.time, z=np.array(z, dtype=float), lines=(r.line,), sensors=() if r.sensor is None else (r.sensor,))
    for r in records:
        if r.sensor is not None:
            z[sensors[r.sensor].block] = r.values
    return Step(
        time=records[0].time,
        z=np.array(z, dtype=float),
        lines=tuple(dict.fromkeys(r.line for r in records)),  # a wide CSV row gives several records
        sensors=tuple(r.sensor for r in records if r.sensor is not None),
    )


def block_steps(block: StepBlock) -> list[Step]:
    """A :class:`~pursuit.io.blocks.StepBlock` as :class:`Step` objects (to be stepped one at a time)."""
    return [
        Step(time=t, z=z, lines=(line,), sensors=(s,))
        for t, z, line, s in zip(block.times.tolist(), block.z, block.lines.tolist(), block.sensors)
    ]
