"""Readers for recorded measurements: CSV files and JSON Lines streams.

Both formats carry one measurement of one sensor per record:

* CSV: a header ``time,sensor,value`` (or ``time,sensor,x,y``: any names
  for the value columns), then one row per record: the time, the sensor id,
  and the sensor's components, one per column (a range or a bearing has one,
  a 2-D position fix two).  An empty field or ``nan`` is a missing
  component.  Blank lines and lines starting with ``#`` are ignored.  The
  model file's ``[input]`` section may rename the time and sensor columns,
  or describe a *wide* file whose rows hold named columns of several
  sensors (:mod:`pursuit.io.input_spec`).
* JSON Lines: one object per line, ``{"time": 1.5, "sensor": "A", "value":
  12.3}``; ``value`` may be a list (or use ``values``), ``null`` or NaN is a
  missing component.  ``{"time": 7.0}`` alone asks for an estimate at that
  time without a measurement.

A time is a number of seconds (any origin) or an ISO 8601 date-time
(``2026-07-01T12:00:00.25Z``), read as seconds after the model's
``[input] time_origin`` (the Unix epoch unless set); one input uses one kind.

The readers take lines of *bytes* and never raise on bad input: each record
comes out either as a :class:`Record` or as a :class:`BadRecord` naming its
line and field, so a caller can report every problem in a file at once.
:func:`check_record` then checks a record against the configured sensors.
"""

from __future__ import annotations

import csv
import json
import math
import re
from dataclasses import dataclass
from itertools import repeat
from datetime import datetime, timezone
from typing import Any, Callable, Iterable, Iterator, Mapping

import numpy as np

from .blocks import RecordBlock
from .lines import INPUT_WAITS
from .input_spec import InputSpec

__all__ = [
    "Record",
    "BadRecord",
    "read_csv",
    "read_jsonl",
    "read_records",
    "read_record_chunks",
    "block_records",
    "check_record",
    "FORMATS",
]

FORMATS = ("csv", "jsonl")

# ASCII digits only: Python's float() also reads full-width and other Unicode digits ("４１.5")
_NUMBER = re.compile(r"^[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?$")
_NAN = {"nan", "+nan", "-nan"}
# an ISO 8601 date and time in the extended format: 2026-07-01T12:00:00.5Z, 2026-07-01 12:00+02:00, 2026-07-01
_ISO_TIME = re.compile(
    r"^[0-9]{4}-[0-9]{2}-[0-9]{2}(?:[T ][0-9]{2}(?::[0-9]{2}(?::[0-9]{2}(?:[.,][0-9]+)?)?)?(?:Z|[+-][0-9]{2}(?::?[0-9]{2})?)?)?$"
)
_DEFAULT_SPEC = InputSpec()
_INF = {"inf", "infinity"}
_TIME_FINITE = "a time must be a finite number of seconds"
_JSON_KEYS = ("time", "sensor", "value", "values")


@dataclass(frozen=True)
class Record:
    """One measurement of one sensor.

    Attributes
    ----------
    line
        Line number in the input (1-based).
    time
        Measurement time, s.
    sensor
        Sensor id, or None for a request for an estimate without measurement.
    values
        The components; NaN = missing.
    """

    line: int
    time: float
    sensor: str | None
    values: tuple[float, ...]


@dataclass(frozen=True)
class BadRecord:
    """A record that cannot be used, and why.

    Attributes
    ----------
    line
        Line number in the input (1-based).
    field
        The offending field (``time``, ``sensor``, ``value``, ``header`` or
        ``record`` for the line as a whole).
    message
        What is wrong.
    """

    line: int
    field: str
    message: str

    def __str__(self) -> str:
        return f"line {self.line}: {self.field}: {self.message}"


class _Bad(Exception):
    def __init__(self, field: str, message: str):
        super().__init__(message)
        self.field = field
        self.message = message


def _show(text: str, limit: int = 40) -> str:
    """A short, printable rendering of a bad field for messages."""
    r = repr(text)
    return r if len(r) <= limit else r[: limit - 4] + "...'"


# --------------------------------------------------------------------------
# numbers
# --------------------------------------------------------------------------
def _parse_time_text(text: str) -> float:
    t = text.strip()
    if _NUMBER.match(t):  # the usual case first; the checks below name what else it is
        v = float(t)
        if math.isfinite(v):
            return v
    if not t:
        raise _Bad("time", "missing")
    if t.lower() in _NAN:
        raise _Bad("time", "must be a number, got nan")
    if t.lower().lstrip("+-") in _INF:
        raise _Bad("time", f"{_show(t)} is not finite ({_TIME_FINITE})")
    if not _NUMBER.match(t):
        raise _Bad("time", f"not a number: {_show(t)}")
    v = float(t)
    if not math.isfinite(v):
        raise _Bad("time", f"{_show(t)} is too large (overflows to infinity)")
    return v


def _parse_value_text(text: str, field: str) -> float:
    t = text.strip()
    if _NUMBER.match(t):  # the usual case first; the checks below name what else it is
        v = float(t)
        if math.isfinite(v):
            return v
    if not t or t.lower() in _NAN:
        return math.nan
    if not _NUMBER.match(t):
        if t.lower().lstrip("+-") in _INF:
            raise _Bad(field, f"{_show(t)} is not finite (write nan or leave it empty for a missing value)")
        raise _Bad(field, f"not a number: {_show(t)}")
    v = float(t)
    if not math.isfinite(v):
        raise _Bad(field, f"{_show(t)} is too large (overflows to infinity)")
    return v


def _json_number(v: Any, field: str, *, allow_missing: bool) -> float:
    if v is None:
        if allow_missing:
            return math.nan
        raise _Bad(field, "missing (null)")
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        raise _Bad(field, f"expected a number, got {_json_type(v)}")
    try:
        f = float(v)
    except OverflowError:
        raise _Bad(field, "too large (overflows to infinity)") from None
    if math.isnan(f):
        if allow_missing:
            return math.nan
        raise _Bad(field, "must be a number, got NaN")
    if not math.isfinite(f):
        raise _Bad(field, f"not finite ({'use null for a missing value' if allow_missing else _TIME_FINITE})")
    return f


class _Clock:
    """Reads the times of one input: seconds, or ISO 8601 date-times as seconds after the origin.

    One input uses one kind of time: the first good time decides, and a time
    of the other kind later is a bad record naming the line that decided.
    Naive ISO times (no offset, no ``Z``) are read as UTC.
    """

    def __init__(self, origin: datetime):
        self.origin = origin
        self.kind: str | None = None
        self.since = 0

    def _agree(self, kind: str, lineno: int) -> None:
        if self.kind is None:
            self.kind, self.since = kind, lineno
        elif kind != self.kind:
            other = "numbers of seconds" if self.kind == "number" else "ISO 8601 date-times"
            this = "a number of seconds" if kind == "number" else "an ISO 8601 date-time"
            raise _Bad("time", f"{this}, but the times of this input are {other} (since line {self.since}); use one kind in one input")

    def _iso(self, text: str) -> float:
        try:
            when = datetime.fromisoformat(text)
        except ValueError as e:
            raise _Bad("time", f"not a valid ISO 8601 time: {_show(text)} ({e})") from None
        if when.tzinfo is None:
            when = when.replace(tzinfo=timezone.utc)
        return (when - self.origin).total_seconds()

    def text(self, text: str, lineno: int) -> float:
        """A time from CSV text."""
        t = text.strip()
        if self.kind == "number" and _NUMBER.match(t):  # the usual case: neither an ISO time nor the first time
            return _parse_time_text(t)
        if _ISO_TIME.match(t):
            value = self._iso(t)
            self._agree("iso", lineno)
            return value
        value = _parse_time_text(t)
        self._agree("number", lineno)
        return value

    def json(self, v: Any, lineno: int) -> float:
        """A time from a JSON value: a number, or an ISO 8601 string."""
        if isinstance(v, str):
            if not _ISO_TIME.match(v.strip()):
                raise _Bad("time", f"expected a number or an ISO 8601 time, got {_json_type(v)}")
            value = self._iso(v.strip())
            self._agree("iso", lineno)
            return value
        value = _json_number(v, "time", allow_missing=False)
        self._agree("number", lineno)
        return value


def _json_type(v: Any) -> str:
    if isinstance(v, bool):
        return "a boolean"
    if isinstance(v, str):
        return f"a string ({_show(v)})"
    if isinstance(v, list):
        return "a list"
    if isinstance(v, dict):
        return "an object"
    return type(v).__name__


# --------------------------------------------------------------------------
# CSV
# --------------------------------------------------------------------------
def _decode(raw: bytes | str, lineno: int) -> str:
    if isinstance(raw, str):
        text = raw
    else:
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError:
            raise _Bad("record", "not valid UTF-8 text") from None
    if lineno == 1 and text.startswith("\ufeff"):
        text = text[1:]
    text = text.rstrip("\r\n")
    if "\x00" in text:
        raise _Bad("record", "contains a NUL byte")
    return text


UNTERMINATED = ("accept", "hint", "reject")
"""What the readers do with a line that has no newline (in a file, only the last can lack one)."""

_CUT_HINT = " (the last line has no newline: was the input cut off?)"
_CUT_MESSAGE = "incomplete: the input ended inside this record (no newline after it); a record is complete at its newline"


def _terminated(raw: bytes | str) -> bool:
    return raw.endswith(b"\n" if isinstance(raw, bytes) else "\n")


def read_csv(
    lines: Iterable[bytes | str], unterminated: str = "accept", layout: InputSpec | None = None
) -> Iterator[Record | BadRecord]:
    """Records from CSV lines (bytes or text, newlines included or not).

    The first line that is neither blank nor a ``#`` comment must be the
    header: ``time,sensor`` and the value columns (``value``, or one name
    per component such as ``x,y``), or the columns ``layout`` names (see
    :class:`~pursuit.io.input_spec.InputSpec`; a wide layout gives one record
    per sensor with a value in the row).  A header that does not fit is one
    bad ``header`` naming the columns expected and found, and reading stops
    there (every row would be misread).  An input without a header (an empty
    file, or only blank and comment lines) is a bad ``header`` too.  Times are
    numbers of seconds or ISO 8601 date-times (seconds after
    ``layout.time_origin``).  Never raises on bad input: every problem comes
    out as a :class:`BadRecord`.

    ``unterminated`` says what a line without a newline is (lines read from
    a file: the last one, when the writer stopped before its newline):
    ``"accept"`` reads it as any line (for lists of lines without newlines),
    ``"hint"`` too, but a problem in it says the input may have been cut
    off, and ``"reject"`` reports it as incomplete (a stream: a record is
    complete only at its newline, so a half-written ``78.43`` cut to ``7``
    is never read as 7).
    """
    reader = _CsvReader(unterminated, layout)
    for raw in lines:
        yield from reader.line(raw)
        if reader.stopped:
            return
    yield from reader.end()


class _CsvReader:
    """The state of :func:`read_csv` (line number, header, clock), one line or one chunk of lines at a time."""

    def __init__(self, unterminated: str, layout: InputSpec | None):
        if unterminated not in UNTERMINATED:
            raise ValueError(f"unterminated: must be one of {', '.join(UNTERMINATED)}, got {unterminated!r}")
        self.unterminated = unterminated
        self.spec = layout or _DEFAULT_SPEC
        self.clock = _Clock(self.spec.time_origin)
        self.columns: _Columns | None = None
        self.content_seen = False
        self.lineno = 0
        self.stopped = False  # a header that does not fit ends the input

    def line(self, raw: bytes | str) -> list[Record | BadRecord]:
        """The records of the next line."""
        self.lineno += 1
        lineno, unterminated = self.lineno, self.unterminated
        cut = unterminated != "accept" and not _terminated(raw)
        try:
            text = _decode(raw, lineno)
            if not text.strip() or text.lstrip().startswith("#"):
                return []
            self.content_seen = True
            if cut and unterminated == "reject":
                raise _Bad("record", _CUT_MESSAGE)
            fields = _split_csv(text)
            if self.columns is None:
                try:
                    self.columns = _Columns.from_header(fields, self.spec)
                except _Bad as e:
                    self.stopped = True  # every row would be misread: one error, not one per row
                    return [BadRecord(lineno, e.field, e.message)]
                return []
            return list(self.columns.records(lineno, fields, self.clock))
        except _Bad as e:
            self.content_seen = True
            return [BadRecord(lineno, e.field, e.message + (_CUT_HINT if cut and unterminated == "hint" else ""))]

    def chunk(self, raws: list[bytes]) -> list:
        """The records of the next lines: :class:`~pursuit.io.blocks.RecordBlock` objects for runs of plain lines."""
        out: list = []
        i = 0
        while self.columns is None and i < len(raws) and not self.stopped:  # up to the header, line by line
            out.extend(self.line(raws[i]))
            i += 1
        if not self.stopped:
            _blocks_or_lines(self, raws[i:] if i else raws, out)
        return out

    def _plain(self, raws: list[bytes]):
        """The chunk as one block, or None when any line needs the line-by-line reader (which names the problem)."""
        cols = self.columns
        if cols is None or cols.time != 0 or cols.sensor != 1 or self.clock.kind == "iso" or len(raws) < 2:
            return None
        if not raws[-1].endswith(b"\n"):
            return None
        data = b"".join(raws)
        if b'"' in data or b"\r" in data or b"\x00" in data:
            return None
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError:
            return None
        lines = text[:-1].split("\n")
        if len(lines) != len(raws):
            return None
        # every line as wide as the first (counted in C, no list per line); then one split of the whole chunk
        commas = lines[0].count(",")
        if commas < 2 or set(map(str.count, lines, repeat(","))) != {commas}:
            return None
        fields = text[:-1].replace("\n", ",").split(",")
        width = commas + 1
        sensors = fields[1::width]
        names = set(sensors)
        if any(not name or name != name.strip() for name in names):
            return None
        numbers = [fields[0::width], *(fields[k::width] for k in range(2, width))]
        # only the characters of a plain number: float() then reads exactly what _NUMBER matches (no spaces, _ or words)
        if "".join(["".join(c) for c in numbers]).translate(_PLAIN_NUMBER):
            return None
        try:
            table = np.array([list(map(float, c)) for c in numbers], dtype=float)
        except ValueError:
            return None
        if not np.isfinite(table).all():
            return None
        if self.clock.kind is None:  # the first good time decides the kind of the input's times
            self.clock._agree("number", self.lineno + 1)
        first = self.lineno + 1
        return RecordBlock(np.arange(first, first + len(raws)), table[0], list(sensors), table[1:].T)

    def end(self) -> list[BadRecord]:
        """The problem of an input that ended without a header, if it is one."""
        if self.content_seen or self.stopped:
            return []
        spec, lineno = self.spec, self.lineno
        what = "the input is empty" if lineno == 0 else "the input has only blank and comment lines"
        if spec.columns is None:
            header = f"{spec.time_column},{spec.sensor_column},value"
        else:
            header = ",".join([spec.time_column, *(c for cols in spec.columns.values() for c in cols)])
        return [BadRecord(max(lineno, 1), "header", f"missing: {what} (expected the header '{header}')")]


_PLAIN_NUMBER = str.maketrans("", "", "0123456789.eE+-")
_SMALLEST_SPLIT = 32


def _blocks_or_lines(reader: Any, raws: list[bytes], out: list) -> None:
    """Append the records of ``raws`` to ``out``: a block where all are plain, else halves, else line by line.

    Halving finds the plain runs around a bad line at the cost of a few more
    tries, in input order, so the reader's state advances as line by line.
    """
    block = reader._plain(raws)
    if block is not None:
        reader.lineno += len(raws)
        out.append(block)
        return
    if len(raws) >= 2 * _SMALLEST_SPLIT:
        half = len(raws) // 2
        _blocks_or_lines(reader, raws[:half], out)
        if not reader.stopped:
            _blocks_or_lines(reader, raws[half:], out)
        return
    for raw in raws:
        out.extend(reader.line(raw))
        if reader.stopped:
            return


def _split_csv(text: str) -> list[str]:
    if '"' not in text and "\r" not in text and "\n" not in text:  # no quoting, no stray line break: csv would split at the commas
        return text.split(",")
    try:
        rows = list(csv.reader([text], strict=True))
    except csv.Error as e:
        raise _Bad("record", f"malformed CSV: {e}") from None
    return rows[0] if rows else []


@dataclass(frozen=True)
class _Columns:
    """Where a CSV's time, sensor and values are, from its header.

    ``sensor`` is the sensor column's index (every other column is a value,
    in order, including fields beyond the header), or None for a wide file
    whose ``wide`` entries give each sensor's value columns.
    """

    names: tuple[str, ...]
    time: int
    sensor: int | None
    wide: tuple[tuple[str, tuple[int, ...]], ...] = ()

    @staticmethod
    def from_header(fields: list[str], spec: InputSpec) -> "_Columns":
        names = tuple(f.strip() for f in fields)
        lower = [n.lower() for n in names]
        found = ",".join(names)
        found = found if len(found) <= 80 else found[:76] + "..."
        hint = "" if spec.columns is not None else (
            "; a file with no sensor column (one column per quantity) needs [input] columns in the model file (docs/track.md)"
        )
        if spec.columns is None:
            wanted = [spec.time_column, spec.sensor_column]
            expected = f"{spec.time_column},{spec.sensor_column} and the value column(s) (value, or one per component such as x,y)"
        else:
            wanted = [spec.time_column, *(c for cols in spec.columns.values() for c in cols)]
            expected = ",".join(wanted) + " (from [input] in the model file; other columns are ignored)"
        missing = [w for w in wanted if w.lower() not in lower]
        twice = [w for w in wanted if lower.count(w.lower()) > 1]
        if missing or twice or (spec.columns is None and len(names) < 3):
            if missing:
                problem = f"missing {','.join(missing)}"
            else:
                problem = f"{','.join(twice)} given twice" if twice else "no value column"
            raise _Bad("header", f"expected the columns {expected}; found {found!r} ({problem}){hint}")
        index = {w: lower.index(w.lower()) for w in wanted}
        if spec.columns is None:
            return _Columns(names, index[spec.time_column], index[spec.sensor_column])
        wide = tuple((sensor, tuple(index[c] for c in cols)) for sensor, cols in spec.columns.items())
        return _Columns(names, index[spec.time_column], None, wide)

    def records(self, lineno: int, fields: list[str], clock: _Clock) -> Iterator[Record]:
        """The records of one data row (a wide row: one per sensor with a value, or a prediction request)."""
        if self.sensor is None:
            yield from self._wide(lineno, fields, clock)
            return
        need = max(self.time, self.sensor) + 1
        need = need + 1 if need == 2 else need  # a value column after time and sensor
        if len(fields) < need:
            what = ", ".join(self.names[i] if i in (self.time, self.sensor) else "value" for i in range(need))
            raise _Bad("record", f"expected at least {need} fields ({what}), got {len(fields)}")
        time = clock.text(fields[self.time], lineno)
        sensor = fields[self.sensor].strip()
        if not sensor:
            raise _Bad("sensor", "missing")
        if self.time == 0 and self.sensor == 1:  # the usual layout: every field after them is a value
            values = tuple([_parse_value_text(f, "value") for f in fields[2:]])
        else:
            values = tuple(_parse_value_text(f, "value") for i, f in enumerate(fields) if i not in (self.time, self.sensor))
        yield Record(lineno, time, sensor, values)

    def _wide(self, lineno: int, fields: list[str], clock: _Clock) -> Iterator[Record]:
        if len(fields) != len(self.names):
            raise _Bad("record", f"expected {len(self.names)} fields as in the header, got {len(fields)}")
        time = clock.text(fields[self.time], lineno)
        found = []
        for sensor, idx in self.wide:
            values = tuple(_parse_value_text(fields[i], self.names[i]) for i in idx)
            if not all(math.isnan(v) for v in values):  # a sensor with no value in the row did not report
                found.append(Record(lineno, time, sensor, values))
        yield from found or [Record(lineno, time, None, ())]


# --------------------------------------------------------------------------
# JSON Lines
# --------------------------------------------------------------------------
def _reject_constant(name: str) -> float:
    # json accepts NaN, Infinity and -Infinity by default; keep NaN (a missing
    # value, as in CSV) and turn the infinities into a value we reject later.
    return math.nan if name == "NaN" else (math.inf if name == "Infinity" else -math.inf)


def _unique_keys(pairs: list[tuple[str, Any]]) -> dict[str, Any]:
    # json keeps the last of repeated keys silently; a record that says two things is bad
    obj: dict[str, Any] = {}
    for key, value in pairs:
        if key in obj:
            name = key.encode("unicode_escape").decode("ascii")[:40] or "''"
            raise _Bad(name, "given twice in one record")
        obj[key] = value
    return obj


def read_jsonl(
    lines: Iterable[bytes | str], unterminated: str = "accept", layout: InputSpec | None = None
) -> Iterator[Record | BadRecord]:
    """Records from JSON Lines (one object per line; blank lines ignored).

    Never raises on bad input: every problem comes out as a
    :class:`BadRecord`.  ``unterminated`` as in :func:`read_csv`; a time is
    a number of seconds or an ISO 8601 string (seconds after
    ``layout.time_origin``, the Unix epoch by default); the column names of
    ``layout`` apply to CSV only.
    """
    reader = _JsonlReader(unterminated, layout)
    for raw in lines:
        yield from reader.line(raw)


class _JsonlReader:
    """The state of :func:`read_jsonl` (line number, clock), one line or one chunk of lines at a time."""

    stopped = False

    def __init__(self, unterminated: str, layout: InputSpec | None):
        if unterminated not in UNTERMINATED:
            raise ValueError(f"unterminated: must be one of {', '.join(UNTERMINATED)}, got {unterminated!r}")
        self.unterminated = unterminated
        self.clock = _Clock((layout or _DEFAULT_SPEC).time_origin)
        self.lineno = 0

    def line(self, raw: bytes | str) -> list[Record | BadRecord]:
        """The record of the next line (none for a blank line)."""
        self.lineno += 1
        lineno, unterminated = self.lineno, self.unterminated
        cut = unterminated != "accept" and not _terminated(raw)
        try:
            text = _decode(raw, lineno)
            if not text.strip():
                return []
            if cut and unterminated == "reject":
                raise _Bad("record", _CUT_MESSAGE)
            try:
                obj = json.loads(text, parse_constant=_reject_constant, object_pairs_hook=_unique_keys)
            except json.JSONDecodeError as e:
                raise _Bad("record", f"not valid JSON ({e.msg} at column {e.colno})") from None
            except (ValueError, RecursionError) as e:  # huge integers, absurd nesting
                raise _Bad("record", f"not valid JSON ({type(e).__name__})") from None
            return [_json_record(lineno, obj, self.clock)]
        except _Bad as e:
            return [BadRecord(lineno, e.field, e.message + (_CUT_HINT if cut and unterminated == "hint" else ""))]

    def chunk(self, raws: list[bytes]) -> list:
        """The records of the next lines: :class:`~pursuit.io.blocks.RecordBlock` objects for runs of plain lines."""
        out: list = []
        _blocks_or_lines(self, raws, out)
        return out

    def _plain(self, raws: list[bytes]):
        """The chunk as one block, or None when any line needs the line-by-line reader (which names the problem).

        Plain lines are ``{"time": number, "sensor": "id", "value": [numbers]}`` (keys in any order, each
        once: a line holds exactly 8 quotes), with finite numbers and times in seconds.
        """
        if self.clock.kind == "iso" or len(raws) < 2 or not raws[-1].endswith(b"\n"):
            return None
        if any(raw.count(b'"') != 8 for raw in raws):  # a repeated key or a quoted value needs more quotes
            return None
        data = b"".join(raws)
        if b"\x00" in data or b"NaN" in data or b"Infinity" in data:
            return None
        try:
            objs = json.loads(b"[" + data[:-1].replace(b"\n", b",") + b"]")
        except (ValueError, RecursionError):
            return None  # one line is not valid JSON (or not UTF-8): the line reader names it
        if len(objs) != len(raws) or any(type(o) is not dict or o.keys() != _PLAIN_KEYS for o in objs):
            return None
        times = [o["time"] for o in objs]
        sensors = [o["sensor"] for o in objs]
        values = [o["value"] for o in objs]
        if not set(map(type, times)) <= _NUMBER_TYPES or set(map(type, sensors)) != {str}:
            return None
        if any(not name or name != name.strip() for name in set(sensors)):
            return None
        if set(map(type, values)) != {list} or len(set(map(len, values))) != 1 or not values[0]:
            return None
        if not {type(v) for row in values for v in row} <= _NUMBER_TYPES:
            return None
        try:
            t = np.array(times, dtype=float)
            v = np.array(values, dtype=float)
        except (OverflowError, ValueError):
            return None
        if not (np.isfinite(t).all() and np.isfinite(v).all()):
            return None
        if self.clock.kind is None:  # the first good time decides the kind of the input's times
            self.clock._agree("number", self.lineno + 1)
        first = self.lineno + 1
        return RecordBlock(np.arange(first, first + len(raws)), t, sensors, v)


_PLAIN_KEYS = {"time", "sensor", "value"}
_NUMBER_TYPES = {int, float}


def _json_record(lineno: int, obj: Any, clock: _Clock) -> Record:
    if not isinstance(obj, dict):
        raise _Bad("record", f'expected an object like {{"time": 1.0, "sensor": "A", "value": 2.5}}, got {_json_type(obj)}')
    for key in obj:
        if key not in _JSON_KEYS:
            name = key.encode("unicode_escape").decode("ascii")[:40] or "''"  # one printable line
            raise _Bad(name, f"unknown key (known: {', '.join(_JSON_KEYS)})")
    if "time" not in obj:
        raise _Bad("time", "missing")
    time = clock.json(obj["time"], lineno)
    has_value = "value" in obj or "values" in obj
    if "value" in obj and "values" in obj:
        raise _Bad("values", "give either value or values, not both")
    sensor = obj.get("sensor")
    if sensor is None:
        if has_value:
            raise _Bad("sensor", "missing")
        return Record(lineno, time, None, ())
    if not isinstance(sensor, str):
        raise _Bad("sensor", f"expected a string, got {_json_type(sensor)}")
    sensor = sensor.strip()
    if not sensor:
        raise _Bad("sensor", "missing")
    if not has_value:
        raise _Bad("value", "missing")
    key = "value" if "value" in obj else "values"
    raw = obj[key]
    items = raw if isinstance(raw, list) else [raw]
    if not items:
        raise _Bad(key, "empty list")
    if isinstance(raw, list) and any(isinstance(v, (list, dict)) for v in raw):
        raise _Bad(key, "expected a number or a flat list of numbers")
    values = tuple(_json_number(v, key, allow_missing=True) for v in items)
    return Record(lineno, time, sensor, values)


def read_records(
    lines: Iterable[bytes | str], fmt: str, unterminated: str = "accept", layout: InputSpec | None = None
) -> Iterator[Record | BadRecord]:
    """Records in format ``fmt`` (``"csv"`` or ``"jsonl"``); ``unterminated`` and ``layout`` as in :func:`read_csv`."""
    if fmt == "csv":
        return read_csv(lines, unterminated, layout)
    if fmt == "jsonl":
        return read_jsonl(lines, unterminated, layout)
    raise ValueError(f"format: must be one of {', '.join(FORMATS)}, got {fmt!r}")


def read_record_chunks(
    chunks: Iterable[list[bytes]],
    fmt: str,
    unterminated: str = "accept",
    layout: InputSpec | None = None,
    ready: Callable[[], bool] | None = None,
) -> Iterator[Any]:
    """:func:`read_records` over chunks of lines: a chunk of plain lines comes out as one :class:`~pursuit.io.blocks.RecordBlock`.

    The records, the bad records and their messages are those of
    :func:`read_records` on the same lines (a chunk with any line that is
    not plain is read line by line).  ``ready`` as in
    :func:`pursuit.io.steps.mark_waits`: an :data:`~pursuit.io.lines.INPUT_WAITS`
    mark comes before each chunk whose taking may wait (a chunk is what the
    input had at hand, see :meth:`pursuit.io.lines.ChunkedLines.chunks`).
    """
    if fmt not in FORMATS:
        raise ValueError(f"format: must be one of {', '.join(FORMATS)}, got {fmt!r}")
    reader = _CsvReader(unterminated, layout) if fmt == "csv" else _JsonlReader(unterminated, layout)
    it = iter(chunks)
    while True:
        if ready is not None and not ready():
            yield INPUT_WAITS
        raws = next(it, None)
        if raws is None:
            break
        yield from reader.chunk(raws)
        if reader.stopped:
            return
    if fmt == "csv":
        yield from reader.end()


# --------------------------------------------------------------------------
# against the model
# --------------------------------------------------------------------------
def check_record(record: Record, sensors: Mapping[str, Any]) -> Record | BadRecord:
    """Check a record against the configured sensors (id, component count, valid range).

    ``sensors`` maps ids to objects with ``dim`` and ``valid = (low, high)``
    (see :class:`pursuit.io.model.Sensor`).
    """
    if record.sensor is None:
        return record
    spec = sensors.get(record.sensor)
    if spec is None:
        known = ", ".join(sensors) or "none"
        return BadRecord(record.line, "sensor", f"unknown sensor {_show(record.sensor)} (known: {known})")
    if len(record.values) != spec.dim:
        return BadRecord(
            record.line,
            "value",
            f"sensor {record.sensor!r} has {spec.dim} component(s), got {len(record.values)} value(s)",
        )
    lo, hi = spec.valid
    for v in record.values:
        if not math.isnan(v) and not lo <= v <= hi:
            return BadRecord(record.line, "value", f"{v!r} is outside the valid range [{lo:g}, {hi:g}] of sensor {record.sensor!r}")
    return record


def block_records(block: RecordBlock) -> list[Record]:
    """A :class:`~pursuit.io.blocks.RecordBlock` as :class:`Record` objects (for the record-by-record path)."""
    return [
        Record(line, time, sensor, tuple(vals))
        for line, time, sensor, vals in zip(block.lines.tolist(), block.times.tolist(), block.sensors, block.values.tolist())
    ]
