"""Recorded detections: CSV and JSON Lines files of unlabelled detections, grouped into scans.

A detection file holds one detection per record: its time, optionally the
sensor that made it, and its value columns, whose names the caller gives
(``x,y`` for position fixes, ``range,bearing`` for a radar).  There is no
target label: which target (or clutter) a detection came from is what a
tracker decides.

* CSV: a header naming at least ``time`` and the value columns (and
  ``sensor`` when there is one; other columns are ignored), then one row per
  detection::

      time,sensor,x,y
      1.0,radar,10.2,4.9
      1.0,radar,-3.1,17.0
      2.0,radar,,

  A row whose value fields are all empty says "a scan at this time with no
  detection" (a scan in which nothing was seen still counts for a tracker's
  misses).  Blank lines and lines starting with ``#`` are ignored.
* JSON Lines: one object per line, ``{"time": 1.0, "sensor": "radar",
  "x": 10.2, "y": 4.9}``; ``{"time": 2.0}`` alone is an empty scan.

Times are numbers of seconds or ISO 8601 date-times (seconds after the Unix
epoch), as in :mod:`pursuit.io.records`.  Consecutive records with equal
times form one scan; times must not decrease (``out_of_order="sort"`` sorts
a whole file first, as ``pursuit track`` does; ``"drop"`` skips late records
with a :class:`~pursuit.io.steps.Dropped` note in the low-level grouping).

Bad input: a malformed record, a missing or unknown column or key, a
missing, NaN or infinite value, a decreasing time.  The low-level readers
(:func:`read_detection_records`, :func:`group_scans`) never raise: each
problem is a :class:`~pursuit.io.records.BadRecord` naming its line and
field, so a command can list them all.  The file readers
(:func:`read_detections`, :func:`iter_detections`) raise
:class:`DetectionFileError` naming the file, the line and the field of the
first problem.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any, Iterable, Iterator, Sequence

import numpy as np

from ..multitarget.detections import Scans, pad_scans
from .input_spec import EPOCH
from .records import (
    _INF,
    _NAN,
    _NUMBER,
    UNTERMINATED,
    BadRecord,
    Record,
    _Bad,
    _Clock,
    _decode,
    _json_type,
    _reject_constant,
    _show,
    _split_csv,
    _terminated,
    _unique_keys,
)
from .steps import OUT_OF_ORDER, Dropped, sort_records

__all__ = [
    "DetectionScan",
    "DetectionFileError",
    "read_detection_records",
    "group_scans",
    "iter_detections",
    "read_detections",
]

_CUT = "incomplete: the input ended inside this record (no newline after it)"


@dataclass(frozen=True)
class DetectionScan:
    """The detections of one scan of a recorded file.

    Attributes
    ----------
    time
        The scan's time, s.
    z
        ``(n, m)`` detections (n may be 0), in file order.
    sensors
        The sensor of each detection (None where the file has no sensor).
    lines
        The input lines of the scan's records.
    """

    time: float
    z: np.ndarray
    sensors: tuple[str | None, ...]
    lines: tuple[int, ...]


class DetectionFileError(ValueError):
    """A detection file that cannot be used; the message names the file, the line and the field.

    Attributes
    ----------
    path, line, field, message
        Where and what: ``str(error)`` is ``"path:line: field: message"``,
        the format of ``pursuit track``'s bad records (``line`` is None
        for a file that cannot be opened).
    """

    def __init__(self, path: str, line: int | None, field: str, message: str):
        self.path, self.line, self.field, self.message = str(path), line, field, message
        where = self.path if line is None else f"{self.path}:{line}"
        super().__init__(f"{where}: {field}: {message}")

    @classmethod
    def from_bad(cls, path: str, bad: BadRecord) -> "DetectionFileError":
        """The error of a :class:`~pursuit.io.records.BadRecord` in file ``path``."""
        return cls(path, bad.line, bad.field, bad.message)


# --------------------------------------------------------------------------
# records
# --------------------------------------------------------------------------
def _columns(values: Sequence[str], time_column: str, sensor_column: str) -> tuple[str, ...]:
    if isinstance(values, str) or not isinstance(values, Sequence) or not values:
        raise ValueError(f"values: expected a non-empty list of value column names (e.g. ['x', 'y']), got {values!r}")
    names = tuple(values)
    for v in names:
        if not isinstance(v, str) or not v.strip():
            raise ValueError(f"values: column names must be non-empty strings, got {v!r}")
    lower = [v.strip().lower() for v in names]
    if len(set(lower)) != len(lower):
        raise ValueError(f"values: a column is named twice in {list(names)}")
    for other in (time_column, sensor_column):
        if other.lower() in lower:
            raise ValueError(f"values: {other!r} is the time or sensor column, not a value column")
    return tuple(v.strip() for v in names)


def _value(text: str, column: str) -> float | None:
    """A value from CSV text; None when empty."""
    t = text.strip()
    if not t:
        return None
    if t.lower() in _NAN:
        raise _Bad(column, "NaN is not a detection (leave every value empty for a scan without detections)")
    if not _NUMBER.match(t):
        if t.lower().lstrip("+-") in _INF:
            raise _Bad(column, f"{_show(t)} is not finite")
        raise _Bad(column, f"not a number: {_show(t)}")
    v = float(t)
    if not math.isfinite(v):
        raise _Bad(column, f"{_show(t)} is too large (overflows to infinity)")
    return v


def _detection(values: list[float | None], columns: tuple[str, ...]) -> tuple[float, ...]:
    """All values (a detection), or none (an empty scan); some but not all is a bad record."""
    missing = [c for c, v in zip(columns, values) if v is None]
    if len(missing) == len(columns):
        return ()
    if missing:
        raise _Bad(missing[0], "missing (a detection needs every value column; give none for a scan without detections)")
    return tuple(values)  # type: ignore[arg-type]


@dataclass(frozen=True)
class _Header:
    time: int
    sensor: int | None
    values: tuple[int, ...]
    width: int

    @staticmethod
    def read(fields: list[str], columns: tuple[str, ...], time_column: str, sensor_column: str) -> "_Header":
        names = [f.strip() for f in fields]
        lower = [n.lower() for n in names]
        wanted = [time_column, *columns]
        expected = ",".join([time_column, *columns]) + f" ({sensor_column} optional; other columns are ignored)"
        missing = [w for w in wanted if w.lower() not in lower]
        twice = [w for w in [*wanted, sensor_column] if lower.count(w.lower()) > 1]
        if missing or twice:
            problem = f"missing {','.join(missing)}" if missing else f"{','.join(twice)} given twice"
            found = ",".join(names)
            found = found if len(found) <= 80 else found[:76] + "..."
            raise _Bad("header", f"expected the columns {expected}; found {found!r} ({problem})")
        sensor = lower.index(sensor_column.lower()) if sensor_column.lower() in lower else None
        return _Header(lower.index(time_column.lower()), sensor, tuple(lower.index(c.lower()) for c in columns), len(names))


def _csv_records(lines, columns, time_column, sensor_column, unterminated) -> Iterator[Record | BadRecord]:
    clock = _Clock(EPOCH)
    header: _Header | None = None
    lineno = 0
    for lineno, raw in enumerate(lines, start=1):
        cut = unterminated != "accept" and not _terminated(raw)
        try:
            text = _decode(raw, lineno)
            if not text.strip() or text.lstrip().startswith("#"):
                continue
            if cut and unterminated == "reject":
                raise _Bad("record", _CUT)
            fields = _split_csv(text)
            if header is None:
                try:
                    header = _Header.read(fields, columns, time_column, sensor_column)
                except _Bad as e:
                    yield BadRecord(lineno, e.field, e.message)
                    return  # every row would be misread
                continue
            if len(fields) != header.width:
                raise _Bad("record", f"expected {header.width} fields as in the header, got {len(fields)}")
            time = clock.text(fields[header.time], lineno)
            sensor = None
            if header.sensor is not None:
                sensor = fields[header.sensor].strip()
                if not sensor:
                    raise _Bad(sensor_column, "missing")
            values = _detection([_value(fields[i], c) for i, c in zip(header.values, columns)], columns)
            yield Record(lineno, time, sensor, values)
        except _Bad as e:
            hint = " (the last line has no newline: was the input cut off?)" if cut and unterminated == "hint" else ""
            yield BadRecord(lineno, e.field, e.message + hint)
    if header is None:
        what = "the input is empty" if lineno == 0 else "the input has only blank and comment lines"
        yield BadRecord(max(lineno, 1), "header", f"missing: {what} (expected the header '{','.join([time_column, *columns])}')")


def _jsonl_records(lines, columns, time_column, sensor_column, unterminated) -> Iterator[Record | BadRecord]:
    clock = _Clock(EPOCH)
    known = (time_column, sensor_column, *columns)
    for lineno, raw in enumerate(lines, start=1):
        cut = unterminated != "accept" and not _terminated(raw)
        try:
            text = _decode(raw, lineno)
            if not text.strip():
                continue
            if cut and unterminated == "reject":
                raise _Bad("record", _CUT)
            try:
                obj = json.loads(text, parse_constant=_reject_constant, object_pairs_hook=_unique_keys)
            except json.JSONDecodeError as e:
                raise _Bad("record", f"not valid JSON ({e.msg} at column {e.colno})") from None
            except (ValueError, RecursionError) as e:
                raise _Bad("record", f"not valid JSON ({type(e).__name__})") from None
            yield _json_record(lineno, obj, clock, columns, time_column, sensor_column, known)
        except _Bad as e:
            hint = " (the last line has no newline: was the input cut off?)" if cut and unterminated == "hint" else ""
            yield BadRecord(lineno, e.field, e.message + hint)


def _json_record(lineno, obj: Any, clock: _Clock, columns, time_column, sensor_column, known) -> Record:
    if not isinstance(obj, dict):
        example = ", ".join([f'"{time_column}": 1.0', *(f'"{c}": 0.0' for c in columns)])
        raise _Bad("record", f"expected an object like {{{example}}}, got {_json_type(obj)}")
    for key in obj:
        if key not in known:
            name = key.encode("unicode_escape").decode("ascii")[:40] or "''"
            raise _Bad(name, f"unknown key (known: {', '.join(known)})")
    if time_column not in obj:
        raise _Bad(time_column, "missing")
    time = clock.json(obj[time_column], lineno)
    sensor = obj.get(sensor_column)
    if sensor_column in obj:
        if not isinstance(sensor, str):
            raise _Bad(sensor_column, f"expected a string, got {_json_type(sensor)}")
        sensor = sensor.strip()
        if not sensor:
            raise _Bad(sensor_column, "missing")
    values = [_json_value(obj[c], c) if c in obj else None for c in columns]
    return Record(lineno, time, sensor, _detection(values, columns))


def _json_value(v: Any, column: str) -> float:
    if v is None:
        raise _Bad(column, "null is not a detection (leave every value key out for a scan without detections)")
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise _Bad(column, f"expected a number, got {_json_type(v)}")
    try:
        f = float(v)
    except OverflowError:
        raise _Bad(column, "too large (overflows to infinity)") from None
    if math.isnan(f):
        raise _Bad(column, "NaN is not a detection (leave every value key out for a scan without detections)")
    if not math.isfinite(f):
        raise _Bad(column, "not finite")
    return f


def read_detection_records(
    lines: Iterable[bytes | str],
    fmt: str,
    values: Sequence[str],
    *,
    time_column: str = "time",
    sensor_column: str = "sensor",
    unterminated: str = "accept",
) -> Iterator[Record | BadRecord]:
    """Detection records from CSV or JSON Lines lines; never raises on bad input.

    Parameters
    ----------
    lines
        Lines of bytes or text (newlines kept or not).
    fmt
        ``"csv"`` or ``"jsonl"``.
    values
        The value columns (CSV) or keys (JSON), in component order.
    time_column, sensor_column
        Names of the time and (optional) sensor columns.
    unterminated
        What a line without a newline is, as in
        :func:`pursuit.io.records.read_csv`.

    Yields
    ------
    Record or BadRecord
        A :class:`~pursuit.io.records.Record` per detection (``values`` of
        length m; ``sensor`` None without a sensor column), a record with no
        values for a scan without detections, or a
        :class:`~pursuit.io.records.BadRecord` naming the line and field.

    Raises
    ------
    ValueError
        Only for bad arguments (``fmt``, ``values``, ``unterminated``).
    """
    columns = _columns(values, time_column, sensor_column)
    if unterminated not in UNTERMINATED:
        raise ValueError(f"unterminated: must be one of {', '.join(UNTERMINATED)}, got {unterminated!r}")
    if fmt == "csv":
        return _csv_records(lines, columns, time_column, sensor_column, unterminated)
    if fmt == "jsonl":
        return _jsonl_records(lines, columns, time_column, sensor_column, unterminated)
    raise ValueError(f"format: must be csv or jsonl, got {fmt!r}")


# --------------------------------------------------------------------------
# scans
# --------------------------------------------------------------------------
def group_scans(
    items: Iterable[Record | BadRecord], *, out_of_order: str = "error", dim: int = 0
) -> Iterator[DetectionScan | BadRecord | Dropped]:
    """Group records into scans, lazily: consecutive equal times make one scan.

    A scan is yielded when a record with a later time arrives or the input
    ends.  Bad records pass through.  A record earlier than the scan being
    assembled is a bad ``time`` record (``out_of_order="error"``) or is
    dropped with a :class:`~pursuit.io.steps.Dropped` note (``"drop"``);
    ``"sort"`` behaves as ``"error"`` here (sort the records first, as
    :func:`read_detections` does).  ``dim`` is the width of an empty
    scan's ``z`` (``(0, dim)``).
    """
    if out_of_order not in OUT_OF_ORDER:
        raise ValueError(f"out_of_order: must be one of {', '.join(OUT_OF_ORDER)}, got {out_of_order!r}")
    pending: list[Record] = []
    for item in items:
        if isinstance(item, BadRecord):
            yield item
            continue
        if pending and item.time < pending[0].time:
            message = f"{item.time!r} is earlier than time {pending[0].time!r} already reached (line {pending[0].line})"
            if out_of_order == "drop":
                yield Dropped(item.line, f"{message}; late record dropped")
            else:
                yield BadRecord(item.line, "time", f"out of order: {message}")
            continue
        if pending and item.time > pending[0].time:
            yield _scan(pending, dim)
            pending = []
        pending.append(item)
    if pending:
        yield _scan(pending, dim)


def _scan(records: list[Record], dim: int) -> DetectionScan:
    dets = [r for r in records if r.values]
    m = len(dets[0].values) if dets else dim
    z = np.array([r.values for r in dets], dtype=float).reshape(len(dets), m)
    return DetectionScan(records[0].time, z, tuple(r.sensor for r in dets), tuple(r.line for r in records))


# --------------------------------------------------------------------------
# files
# --------------------------------------------------------------------------
_EXTENSIONS = {".csv": "csv", ".jsonl": "jsonl", ".ndjson": "jsonl", ".json": "jsonl"}


def _format(name: str, fmt: str | None) -> str:
    if fmt is not None:
        return fmt
    found = _EXTENSIONS.get(Path(name).suffix.lower())
    if found is None:
        raise ValueError(f"fmt: cannot tell the format of {name} from its extension; give fmt='csv' or fmt='jsonl'")
    return found


def iter_detections(
    source: str | Path | IO[bytes],
    values: Sequence[str],
    *,
    fmt: str | None = None,
    time_column: str = "time",
    sensor_column: str = "sensor",
    out_of_order: str = "error",
) -> Iterator[DetectionScan]:
    """Scans of a detection file, one at a time (the file is never held whole).

    Parameters
    ----------
    source
        A path, or a binary file object (a pipe, standard input); a stream's
        last line must end with a newline (a record cut off mid-write is
        never read).
    values, time_column, sensor_column
        As in :func:`read_detection_records`.
    fmt
        ``"csv"`` or ``"jsonl"``; default from the file's extension.
    out_of_order
        ``"error"`` (default) or ``"drop"`` (late records skipped silently);
        a stream cannot be sorted.

    Yields
    ------
    DetectionScan
        Each scan once the next time arrives (or the input ends).

    Raises
    ------
    DetectionFileError
        At the first bad record, naming the file, line and field.  The scans
        yielded before it are complete; the one being assembled when it came
        is not yielded (the bad record may have belonged to it).
    """
    if out_of_order not in ("error", "drop"):
        raise ValueError(f"out_of_order: a stream can only use error or drop, got {out_of_order!r} (read_detections sorts)")
    if isinstance(source, (str, Path)):
        name = str(source)
        fmt = _format(name, fmt)
        columns = _columns(values, time_column, sensor_column)  # checked before the file is opened
        return _iter_file(name, fmt, columns, time_column, sensor_column, out_of_order)
    name = str(getattr(source, "name", "<stream>"))
    if fmt is None:
        raise ValueError("fmt: give fmt='csv' or fmt='jsonl' for a file object")
    records = read_detection_records(
        iter(source.readline, b""), fmt, values, time_column=time_column, sensor_column=sensor_column, unterminated="reject"
    )
    return _raising(name, group_scans(records, out_of_order=out_of_order, dim=len(values)))


def _iter_file(name, fmt, columns, time_column, sensor_column, out_of_order) -> Iterator[DetectionScan]:
    try:
        fh = open(name, "rb")
    except OSError as e:
        raise DetectionFileError(name, None, "file", f"cannot read: {e.strerror or e}") from None
    with fh:
        records = read_detection_records(fh, fmt, columns, time_column=time_column, sensor_column=sensor_column, unterminated="hint")
        yield from _raising(name, group_scans(records, out_of_order=out_of_order, dim=len(columns)))


def _raising(name: str, events: Iterable[DetectionScan | BadRecord | Dropped]) -> Iterator[DetectionScan]:
    for event in events:
        if isinstance(event, BadRecord):
            raise DetectionFileError.from_bad(name, event)
        if isinstance(event, DetectionScan):
            yield event


def read_detections(
    source: str | Path,
    values: Sequence[str],
    *,
    fmt: str | None = None,
    time_column: str = "time",
    sensor_column: str = "sensor",
    out_of_order: str = "error",
) -> Scans:
    """A whole detection file as :class:`~pursuit.multitarget.Scans` of one run.

    Parameters
    ----------
    source
        The file's path.
    values, fmt, time_column, sensor_column
        As in :func:`iter_detections`.
    out_of_order
        ``"error"`` (default): a time earlier than one before it is a bad
        record; ``"sort"``: records are sorted by time first (stable, so
        equal times keep their file order); ``"drop"``: late records are
        skipped.

    Returns
    -------
    Scans
        ``z (K, 1, D, m)`` (one run, detections in file order, NaN padding),
        ``times (K,)``, no origin.  The sensor ids are not kept: read with
        :func:`iter_detections` to have them.

    Raises
    ------
    DetectionFileError
        For the first bad record (by line), naming the file, line and field,
        or a file without a single record.
    """
    name = str(source)
    fmt = _format(name, fmt)
    columns = _columns(values, time_column, sensor_column)
    if out_of_order not in OUT_OF_ORDER:
        raise ValueError(f"out_of_order: must be one of {', '.join(OUT_OF_ORDER)}, got {out_of_order!r}")
    try:
        with open(name, "rb") as fh:
            records = read_detection_records(fh, fmt, columns, time_column=time_column, sensor_column=sensor_column, unterminated="hint")
            items = list(records)
    except OSError as e:
        raise DetectionFileError(name, None, "file", f"cannot read: {e.strerror or e}") from None
    if out_of_order == "sort":
        items = sort_records(items)
    events = list(group_scans(items, out_of_order="error" if out_of_order == "sort" else out_of_order, dim=len(columns)))
    bad = [e for e in events if isinstance(e, BadRecord)]
    if bad:
        raise DetectionFileError.from_bad(name, min(bad, key=lambda b: b.line))
    scans = [e for e in events if isinstance(e, DetectionScan)]
    if not scans:
        raise DetectionFileError(name, 1, "record", "no detection records: nothing to read")
    return pad_scans([[s.z] for s in scans], [s.time for s in scans], dim=len(columns))
