"""Readers for recorded measurements: CSV files and JSON Lines streams.

Both formats carry one measurement of one sensor per record:

* CSV: a header ``time,sensor,value`` (or ``time,sensor,values``), then one
  row per record: the time in seconds, the sensor id, and the sensor's
  components, one per column (a range or a bearing has one, a 2-D position
  fix two).  An empty field or ``nan`` is a missing component.  Blank lines
  and lines starting with ``#`` are ignored.
* JSON Lines: one object per line, ``{"time": 1.5, "sensor": "A", "value":
  12.3}``; ``value`` may be a list (or use ``values``), ``null`` or NaN is a
  missing component.  ``{"time": 7.0}`` alone asks for an estimate at that
  time without a measurement.

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
from typing import Any, Iterable, Iterator, Mapping

__all__ = [
    "Record",
    "BadRecord",
    "read_csv",
    "read_jsonl",
    "read_records",
    "check_record",
    "FORMATS",
]

FORMATS = ("csv", "jsonl")

# ASCII digits only: Python's float() also reads full-width and other Unicode digits ("４１.5")
_NUMBER = re.compile(r"^[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?$")
_NAN = {"nan", "+nan", "-nan"}
_CSV_HEADERS = (("time", "sensor", "value"), ("time", "sensor", "values"))
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


def read_csv(lines: Iterable[bytes | str], unterminated: str = "accept") -> Iterator[Record | BadRecord]:
    """Records from CSV lines (bytes or text, newlines included or not).

    The first line that is neither blank nor a ``#`` comment must be the
    header ``time,sensor,value`` (or ``values``); an input without one (an
    empty file, or only blank and comment lines) is a bad ``header``.  Never
    raises on bad input: every problem comes out as a :class:`BadRecord`.

    ``unterminated`` says what a line without a newline is (lines read from
    a file: the last one, when the writer stopped before its newline):
    ``"accept"`` reads it as any line (for lists of lines without newlines),
    ``"hint"`` too, but a problem in it says the input may have been cut
    off, and ``"reject"`` reports it as incomplete (a stream: a record is
    complete only at its newline, so a half-written ``78.43`` cut to ``7``
    is never read as 7).
    """
    if unterminated not in UNTERMINATED:
        raise ValueError(f"unterminated: must be one of {', '.join(UNTERMINATED)}, got {unterminated!r}")
    header_seen = content_seen = False
    lineno = 0
    for lineno, raw in enumerate(lines, start=1):
        cut = unterminated != "accept" and not _terminated(raw)
        try:
            text = _decode(raw, lineno)
            if not text.strip() or text.lstrip().startswith("#"):
                continue
            content_seen = True
            if cut and unterminated == "reject":
                raise _Bad("record", _CUT_MESSAGE)
            fields = _split_csv(text)
            if not header_seen:
                header_seen = True
                names = tuple(f.strip().lower() for f in fields)
                if names not in _CSV_HEADERS:
                    raise _Bad("header", f"expected 'time,sensor,value' as the first line, got {_show(text, 60)}")
                continue
            yield _csv_record(lineno, fields)
        except _Bad as e:
            content_seen = True
            yield BadRecord(lineno, e.field, e.message + (_CUT_HINT if cut and unterminated == "hint" else ""))
    if not content_seen:  # nothing but blank and comment lines: no header to read
        what = "the input is empty" if lineno == 0 else "the input has only blank and comment lines"
        yield BadRecord(max(lineno, 1), "header", f"missing: {what} (expected the header 'time,sensor,value')")


def _split_csv(text: str) -> list[str]:
    try:
        rows = list(csv.reader([text], strict=True))
    except csv.Error as e:
        raise _Bad("record", f"malformed CSV: {e}") from None
    return rows[0] if rows else []


def _csv_record(lineno: int, fields: list[str]) -> Record:
    if len(fields) < 3:
        raise _Bad("record", f"expected at least 3 fields (time, sensor, value), got {len(fields)}")
    time = _parse_time_text(fields[0])
    sensor = fields[1].strip()
    if not sensor:
        raise _Bad("sensor", "missing")
    values = tuple(_parse_value_text(f, "value") for f in fields[2:])
    return Record(lineno, time, sensor, values)


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


def read_jsonl(lines: Iterable[bytes | str], unterminated: str = "accept") -> Iterator[Record | BadRecord]:
    """Records from JSON Lines (one object per line; blank lines ignored).

    Never raises on bad input: every problem comes out as a
    :class:`BadRecord`.  ``unterminated`` as in :func:`read_csv`.
    """
    if unterminated not in UNTERMINATED:
        raise ValueError(f"unterminated: must be one of {', '.join(UNTERMINATED)}, got {unterminated!r}")
    for lineno, raw in enumerate(lines, start=1):
        cut = unterminated != "accept" and not _terminated(raw)
        try:
            text = _decode(raw, lineno)
            if not text.strip():
                continue
            if cut and unterminated == "reject":
                raise _Bad("record", _CUT_MESSAGE)
            try:
                obj = json.loads(text, parse_constant=_reject_constant, object_pairs_hook=_unique_keys)
            except json.JSONDecodeError as e:
                raise _Bad("record", f"not valid JSON ({e.msg} at column {e.colno})") from None
            except (ValueError, RecursionError) as e:  # huge integers, absurd nesting
                raise _Bad("record", f"not valid JSON ({type(e).__name__})") from None
            yield _json_record(lineno, obj)
        except _Bad as e:
            yield BadRecord(lineno, e.field, e.message + (_CUT_HINT if cut and unterminated == "hint" else ""))


def _json_record(lineno: int, obj: Any) -> Record:
    if not isinstance(obj, dict):
        raise _Bad("record", f'expected an object like {{"time": 1.0, "sensor": "A", "value": 2.5}}, got {_json_type(obj)}')
    for key in obj:
        if key not in _JSON_KEYS:
            name = key.encode("unicode_escape").decode("ascii")[:40] or "''"  # one printable line
            raise _Bad(name, f"unknown key (known: {', '.join(_JSON_KEYS)})")
    if "time" not in obj:
        raise _Bad("time", "missing")
    time = _json_number(obj["time"], "time", allow_missing=False)
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


def read_records(lines: Iterable[bytes | str], fmt: str, unterminated: str = "accept") -> Iterator[Record | BadRecord]:
    """Records in format ``fmt`` (``"csv"`` or ``"jsonl"``); ``unterminated`` as in :func:`read_csv`."""
    if fmt == "csv":
        return read_csv(lines, unterminated)
    if fmt == "jsonl":
        return read_jsonl(lines, unterminated)
    raise ValueError(f"format: must be one of {', '.join(FORMATS)}, got {fmt!r}")


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
