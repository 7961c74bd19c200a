"""CSV and JSON Lines readers: good records, and a message with line and field for every bad one."""

from __future__ import annotations

import io
import json
import math
from datetime import datetime, timedelta, timezone

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pursuit.io import BadRecord, Record, check_record, read_csv, read_jsonl, read_records
from pursuit.io.input_spec import InputSpec
from pursuit.io.model import Sensor


def _csv(text: str):
    return list(read_csv(text.encode().splitlines(keepends=True)))


def _jsonl(text: str):
    return list(read_jsonl(text.encode().splitlines(keepends=True)))


def test_csv_records_with_one_and_several_values():
    out = _csv("time,sensor,value\n1.0,A,12.5\n1.0, gps ,3,4\n2.5,B,\n3,C,nan\n")
    _same(out, [(2, 1.0, "A", (12.5,)), (3, 1.0, "gps", (3.0, 4.0)), (4, 2.5, "B", (math.nan,)), (5, 3.0, "C", (math.nan,))])


def _same(records, expected):
    """Records equal (line, time, sensor, values) tuples, NaN equal to NaN."""
    assert len(records) == len(expected)
    for r, (line, t, s, vals) in zip(records, expected):
        assert isinstance(r, Record)
        assert (r.line, r.time, r.sensor) == (line, t, s)
        assert len(r.values) == len(vals)
        for a, b in zip(r.values, vals):
            assert (math.isnan(a) and math.isnan(b)) or a == b
    return True


def test_csv_header_variants_comments_blank_lines_crlf_and_bom():
    text = "\ufeff# recorded 2026-07-01\n\nTime, Sensor, Values\r\n1,A,2\r\n\r\n# a comment\n2,A,3\n"
    _same(_csv(text), [(4, 1.0, "A", (2.0,)), (7, 2.0, "A", (3.0,))])


def test_quoted_csv_fields():
    _same(_csv('time,sensor,value\n"1.5","A","2.0"\n'), [(2, 1.5, "A", (2.0,))])


@pytest.mark.parametrize(
    "line,field,message",
    [
        ("1.0,A", "record", "expected at least 3 fields"),
        ("", None, None),  # blank: skipped
        ("abc,A,1", "time", "not a number"),
        (",A,1", "time", "missing"),
        ("nan,A,1", "time", "must be a number"),
        ("1e999,A,1", "time", "too large"),
        ("inf,A,1", "time", "'inf' is not finite (a time must be a finite number of seconds)"),
        ("-Infinity,A,1", "time", "'-Infinity' is not finite"),
        ("1,,1", "sensor", "missing"),
        ("1,A,inf", "value", "not finite"),
        ("1,A,-Infinity", "value", "not finite"),
        ("1,A,1e400", "value", "too large"),
        ("1,A,1_000", "value", "not a number"),
        ("1,A,0x10", "value", "not a number"),
        ('1,"A,2', "record", "malformed CSV"),
        ("1,A,1\x00", "record", "NUL"),
    ],
)
def test_bad_csv_lines_name_their_line_and_field(line, field, message):
    out = _csv(f"time,sensor,value\n1,A,1\n{line}\n2,A,2\n")
    if field is None:
        assert all(isinstance(r, Record) for r in out)
        return
    bad = [r for r in out if isinstance(r, BadRecord)]
    assert len(bad) == 1
    assert bad[0].line == 3 and bad[0].field == field
    assert message in bad[0].message
    assert str(bad[0]).startswith(f"line 3: {field}: ")
    # the good lines around it are still read
    assert [r.line for r in out if isinstance(r, Record)] == [2, 4]


def test_a_missing_header_is_one_error_and_reading_stops_there():
    # every row would be misread: one error at the header, not one per row (issue 17)
    out = _csv("1,A,1\n2,A,2\n")
    assert len(out) == 1 and (out[0].line, out[0].field) == (1, "header")
    assert out[0].message.startswith("expected the columns time,sensor and the value column(s)")
    assert "found '1,A,1' (missing time,sensor)" in out[0].message


@pytest.mark.parametrize(
    "text,line,what",
    [("", 1, "the input is empty"), ("\n# a comment\n\n", 3, "the input has only blank and comment lines")],
)
def test_an_input_without_a_header_is_a_bad_header(text, line, what):
    out = _csv(text)
    assert [(r.line, r.field) for r in out] == [(line, "header")]
    assert out[0].message == f"missing: {what} (expected the header 'time,sensor,value')"


def test_a_bad_first_line_is_not_also_reported_as_a_missing_header():
    out = list(read_csv([b"\xff\n"]))
    assert [(r.line, r.field) for r in out] == [(1, "record")]


def test_invalid_utf8_is_a_bad_record():
    out = list(read_csv([b"time,sensor,value\n", b"1,\xff\xfe,1\n", b"2,A,2\n"]))
    assert isinstance(out[0], BadRecord) and out[0].line == 2 and "UTF-8" in out[0].message
    assert isinstance(out[1], Record)


def test_jsonl_records():
    text = (
        '{"time": 1, "sensor": "A", "value": 2.5}\n'
        '{"time": 1.5, "sensor": "gps", "values": [3, null]}\n'
        '\n'
        '{"time": 2, "sensor": "gps", "value": [NaN, 4]}\n'
        '{"time": 3}\n'
    )
    _same(_jsonl(text), [(1, 1.0, "A", (2.5,)), (2, 1.5, "gps", (3.0, math.nan)), (4, 2.0, "gps", (math.nan, 4.0)), (5, 3.0, None, ())])


@pytest.mark.parametrize(
    "line,field,message",
    [
        ("{", "record", "not valid JSON"),
        ("[1, 2]", "record", "expected an object"),
        ('"text"', "record", "expected an object"),
        ('{"sensor": "A", "value": 1}', "time", "missing"),
        ('{"time": "1", "sensor": "A", "value": 1}', "time", "expected a number"),
        ('{"time": true, "sensor": "A", "value": 1}', "time", "expected a number"),
        ('{"time": NaN, "sensor": "A", "value": 1}', "time", "NaN"),
        ('{"time": 1e999, "sensor": "A", "value": 1}', "time", "not finite (a time must be a finite number of seconds)"),
        ('{"time": Infinity, "sensor": "A", "value": 1}', "time", "not finite (a time must be a finite number of seconds)"),
        ('{"time": 1, "sensor": "A", "value": Infinity}', "value", "not finite"),
        ('{"time": 1, "sensor": "A", "value": -Infinity}', "value", "not finite"),
        ('{"time": 1, "sensor": "A", "value": 1' + "0" * 400 + "}", "value", "too large"),
        ('{"time": 1, "sensor": "A", "value": "3"}', "value", "expected a number"),
        ('{"time": 1, "sensor": "A", "value": [[1]]}', "value", "flat list"),
        ('{"time": 1, "sensor": "A", "value": []}', "value", "empty"),
        ('{"time": 1, "sensor": "A"}', "value", "missing"),
        ('{"time": 1, "value": 3}', "sensor", "missing"),
        ('{"time": 1, "sensor": 7, "value": 3}', "sensor", "expected a string"),
        ('{"time": 1, "sensor": "A", "value": 1, "values": [1]}', "values", "either"),
        ('{"time": 1, "sensor": "A", "vaule": 1}', "vaule", "unknown key"),
        ("[" * 100000, "record", "not valid JSON"),
    ],
)
def test_bad_jsonl_lines_name_their_line_and_field(line, field, message):
    out = _jsonl('{"time": 0.5, "sensor": "A", "value": 1}\n' + line + '\n{"time": 9, "sensor": "A", "value": 1}\n')
    bad = [r for r in out if isinstance(r, BadRecord)]
    assert len(bad) == 1, out
    assert (bad[0].line, bad[0].field) == (2, field)
    assert message in bad[0].message
    assert [r.line for r in out if isinstance(r, Record)] == [1, 3]


SENSORS = {
    "A": Sensor("A", "range", 1, 0, (0.0, 1000.0)),
    "gps": Sensor("gps", "position", 2, 1, (-1e9, 1e9)),
}


@pytest.mark.parametrize(
    "record,field,message",
    [
        (Record(4, 1.0, "Z", (1.0,)), "sensor", "unknown sensor 'Z' (known: A, gps)"),
        (Record(4, 1.0, "A", (1.0, 2.0)), "value", "has 1 component(s), got 2"),
        (Record(4, 1.0, "gps", (1.0,)), "value", "has 2 component(s), got 1"),
        (Record(4, 1.0, "A", (-3.0,)), "value", "outside the valid range [0, 1000]"),
        (Record(4, 1.0, "gps", (0.0, 2e9)), "value", "outside the valid range"),
    ],
)
def test_records_are_checked_against_the_sensors(record, field, message):
    bad = check_record(record, SENSORS)
    assert isinstance(bad, BadRecord)
    assert (bad.line, bad.field) == (4, field)
    assert message in bad.message


def test_good_and_predict_only_records_pass_the_check():
    for rec in (Record(1, 1.0, "A", (3.0,)), Record(2, 1.0, "gps", (math.nan, 2.0)), Record(3, 2.0, None, ())):
        assert check_record(rec, SENSORS) is rec


def test_unknown_format_is_refused():
    with pytest.raises(ValueError, match="format"):
        read_records([], "xml")


@pytest.mark.parametrize("fmt,good,cut", ids=["csv", "jsonl"], argvalues=[
    ("csv", b"time,sensor,value\n1.0,A,78.43\n", b"time,sensor,value\n1.0,A,78.43\n2.0,A,7"),
    ("jsonl", b'{"time": 1.0, "sensor": "A", "value": 78.43}\n', b'{"time": 1.0, "sensor": "A", "value": 78.43}\n{"time": 2.0, "sensor": "A", "value": 7'),
])
def test_a_last_line_without_its_newline(fmt, good, cut):
    def read(data, mode):
        return list(read_records(io.BytesIO(data), fmt, unterminated=mode))

    assert read(good, "reject") == read(good, "accept")  # complete lines are read alike
    # a stream: a record is complete only at its newline, so "78.43" cut to "7" is never read as 7
    *first, last = read(cut, "reject")
    assert all(isinstance(r, Record) for r in first) and len(first) == 1
    assert isinstance(last, BadRecord) and last.line == (3 if fmt == "csv" else 2)
    assert last.field == "record" and last.message.startswith("incomplete: the input ended inside")
    # a file: a whole record is read; a broken one says the input may have been cut off
    if fmt == "csv":
        assert read(cut, "hint")[-1] == Record(3, 2.0, "A", (7.0,))
        broken = read(b"time,sensor,value\n1.0,A,78.43\n2.0,A", "hint")[-1]
    else:
        broken = read(cut, "hint")[-1]
    assert isinstance(broken, BadRecord) and broken.message.endswith("(the last line has no newline: was the input cut off?)")
    with pytest.raises(ValueError, match="^unterminated: must be one of"):
        read(good, "drop")


@pytest.mark.parametrize("value", ["４１.5", "41.５", "٤١.5", "1e٣"])
def test_unicode_digits_are_not_numbers(value):
    (rec,) = read_csv([b"time,sensor,value\n", f"1.0,A,{value}\n".encode()])
    assert isinstance(rec, BadRecord) and rec.field == "value" and rec.message.startswith("not a number")
    (rec,) = read_csv([b"time,sensor,value\n", f"{value},A,1.0\n".encode()])
    assert isinstance(rec, BadRecord) and rec.field == "time"


def test_a_key_given_twice_in_a_json_record_is_bad():
    (rec,) = read_jsonl([b'{"time": 1.0, "sensor": "A", "value": 2.0, "value": 3.0}\n'])
    assert rec == BadRecord(1, "value", "given twice in one record")
    (ok,) = read_jsonl([b'{"time": 1.0, "sensor": "A", "value": 2.0}\n'])
    assert ok == Record(1, 1.0, "A", (2.0,))


# --------------------------------------------------------------------------
# headers that do not fit, named and wide columns (issue 17)
# --------------------------------------------------------------------------
def test_a_time_sensor_x_y_header_reads_position_records():
    out = _csv("time,sensor,x,y\n1.0,gps,12.5,40.1\n2.0,gps,13.0,\n2.0,A,41.5\n")
    _same(out, [(2, 1.0, "gps", (12.5, 40.1)), (3, 2.0, "gps", (13.0, math.nan)), (4, 2.0, "A", (41.5,))])


def test_the_truth_file_header_is_one_error_naming_the_columns_expected_and_found():
    out = _csv("time,x,vx,y,vy\n1.0,10.4,0.5,40.1,0.8\n2.0,10.9,0.5,40.9,0.8\n")
    assert len(out) == 1 and (out[0].line, out[0].field) == (1, "header")
    assert out[0].message.startswith(
        "expected the columns time,sensor and the value column(s) (value, or one per component such as x,y); "
        "found 'time,x,vx,y,vy' (missing sensor)"
    )
    assert "[input] columns" in out[0].message  # how to read such a file


@pytest.mark.parametrize(
    "header,problem",
    [("time,sensor", "(no value column)"), ("time,sensor,value,Sensor", "(sensor given twice)"), ("t,sensor,value", "(missing time)")],
)
def test_other_headers_that_do_not_fit(header, problem):
    out = _csv(f"# a comment\n{header}\n1,A,1\n")
    assert [(r.line, r.field) for r in out] == [(2, "header")]
    assert problem in out[0].message


def test_renamed_and_reordered_columns():
    spec = InputSpec(time_column="t", sensor_column="id")
    out = list(read_csv([b"id, T ,range\n", b"A,1.5,12.0\n", b"B,2.5,13.0,14.0\n", b"A,3\n"], layout=spec))
    _same(out[:2], [(2, 1.5, "A", (12.0,)), (3, 2.5, "B", (13.0, 14.0))])
    assert out[2] == BadRecord(4, "record", "expected at least 3 fields (id, T, value), got 2")
    (bad,) = read_csv([b"time,sensor,value\n", b"1,A,1\n"], layout=spec)
    assert bad.field == "header" and bad.message.startswith("expected the columns t,id and the value column(s)")


WIDE = InputSpec(time_column="t", columns={"gps": ("east", "north"), "A": ("r",)})


def test_a_wide_file_gives_one_record_per_sensor_with_a_value():
    text = "t,east,north,speed,r\n1.0,12.5,40.1,0.9,41.5\n2.0,13.0,,0.9,\n3.0,,nan,0.9,42.0\n4.0,,,,\n"
    out = list(read_csv(text.encode().splitlines(keepends=True), layout=WIDE))
    _same(
        out[:4],
        [
            (2, 1.0, "gps", (12.5, 40.1)),
            (2, 1.0, "A", (41.5,)),
            (3, 2.0, "gps", (13.0, math.nan)),  # a missing component; A did not report
            (4, 3.0, "A", (42.0,)),  # gps did not report: both empty or nan
        ],
    )
    assert out[4] == Record(5, 4.0, None, ())  # nothing measured: an estimate at that time


@pytest.mark.parametrize(
    "row,field,message",
    [
        ("1.0,12.5,40.1,0.9", "record", "expected 5 fields as in the header, got 4"),
        ("1.0,12.5,40.1,0.9,41.5,7", "record", "expected 5 fields as in the header, got 6"),
        ("1.0,12.5,x,0.9,41.5", "north", "not a number: 'x'"),
        ("soon,12.5,1,0.9,41.5", "time", "not a number: 'soon'"),
    ],
)
def test_bad_wide_rows_name_their_line_and_column(row, field, message):
    out = list(read_csv([b"t,east,north,speed,r\n", f"{row}\n".encode(), b"2.0,1,2,3,4\n"], layout=WIDE))
    assert out[0] == BadRecord(2, field, message)
    assert [r.line for r in out[1:]] == [3, 3]


def test_an_empty_input_names_the_header_the_layout_expects():
    (bad,) = read_csv([b"# nothing yet\n"], layout=WIDE)
    assert bad == BadRecord(1, "header", "missing: the input has only blank and comment lines (expected the header 't,east,north,r')")


def test_a_wide_header_without_the_mapped_columns_names_them():
    (bad,) = read_csv([b"t,x,y,r\n", b"1,2,3,4\n"], layout=WIDE)
    assert bad.line == 1 and bad.field == "header"
    assert bad.message == (
        "expected the columns t,east,north,r (from [input] in the model file; other columns are ignored); "
        "found 't,x,y,r' (missing east,north)"
    )


# --------------------------------------------------------------------------
# ISO 8601 times (issue 17)
# --------------------------------------------------------------------------
T0 = 1782864000.0  # 2026-07-01T00:00:00Z in seconds after the Unix epoch


@pytest.mark.parametrize(
    "text,seconds",
    [
        ("2026-07-01T00:00:00Z", T0),
        ("2026-07-01T00:00:01.25Z", T0 + 1.25),
        ("2026-07-01T02:00:00+02:00", T0),
        ("2026-06-30T23:30:00-0030", T0),
        ("2026-07-01 00:00:00", T0),  # naive: UTC
        ("2026-07-01", T0),
        ("2026-07-01T00:01", T0 + 60.0),
    ],
)
def test_iso_times_are_seconds_after_the_epoch(text, seconds):
    (rec,) = read_csv([b"time,sensor,value\n", f"{text},A,1\n".encode()])
    assert rec == Record(2, seconds, "A", (1.0,))
    (rec,) = read_jsonl([f'{{"time": "{text}", "sensor": "A", "value": 1}}\n'.encode()])
    assert rec == Record(1, seconds, "A", (1.0,))


def test_iso_times_after_a_chosen_origin():
    spec = InputSpec(time_origin=datetime(2026, 7, 1, tzinfo=timezone.utc))
    out = list(read_csv([b"time,sensor,value\n", b"2026-07-01T00:00:00.5Z,A,1\n", b"2026-07-01T01:00:00+01:00,A,2\n"], layout=spec))
    assert [r.time for r in out] == [0.5, 0.0]
    (rec,) = read_jsonl([b'{"time": "2026-07-01T00:00:02Z"}\n'], layout=spec)
    assert rec == Record(1, 2.0, None, ())


@pytest.mark.parametrize(
    "text,message",
    [
        ("2026-13-01T00:00:00Z", "not a valid ISO 8601 time: '2026-13-01T00:00:00Z' (month must be in 1..12)"),
        ("2026-07-01T23:59:60Z", "not a valid ISO 8601 time"),
        ("2026-07-01X00:00", "not a number"),
        ("2026-07-01T00:00:00 UTC", "not a number"),
        ("２026-07-01", "not a number"),
    ],
)
def test_bad_iso_times(text, message):
    (bad,) = read_csv([b"time,sensor,value\n", f"{text},A,1\n".encode()])
    assert (bad.line, bad.field) == (2, "time") and bad.message.startswith(message)
    (bad,) = read_jsonl([json.dumps({"time": text, "sensor": "A", "value": 1}).encode() + b"\n"])
    assert (bad.line, bad.field) == (1, "time")


@pytest.mark.parametrize("fmt", ["csv", "jsonl"])
def test_mixing_numeric_and_iso_times_is_a_bad_record_naming_the_line(fmt):
    def lines(*times):
        if fmt == "csv":
            return [b"time,sensor,value\n", b"bad,A,1\n", *(f"{t},A,1\n".encode() for t in times)]
        return [b"{}\n", *(json.dumps({"time": t, "sensor": "A", "value": 1}).encode() + b"\n" for t in times)]

    out = list(read_records(lines("2026-07-01T00:00:00Z", 1782864001.0, "2026-07-01T00:00:02Z"), fmt))
    assert [type(r).__name__ for r in out] == ["BadRecord", "Record", "BadRecord", "Record"]
    assert (out[2].line, out[2].field) == (4 if fmt == "csv" else 3, "time")
    first = 3 if fmt == "csv" else 2  # the first good time decides; the bad line before it does not
    assert out[2].message == (
        f"a number of seconds, but the times of this input are ISO 8601 date-times (since line {first}); use one kind in one input"
    )
    out = list(read_records(lines(1.0, "2026-07-01T00:00:00Z"), fmt))
    assert out[2].message.startswith(f"an ISO 8601 date-time, but the times of this input are numbers of seconds (since line {first})")


@settings(max_examples=200, deadline=None)
@given(
    st.datetimes(
        min_value=datetime(1, 1, 2), max_value=datetime(9999, 12, 30),
        timezones=st.sampled_from([None, timezone.utc, timezone(timedelta(hours=5, minutes=30)), timezone(-timedelta(hours=11))]),
    )
)
def test_any_iso_time_python_writes_is_read_as_its_seconds_after_the_epoch(when):
    text = when.isoformat()
    expected = (when if when.tzinfo else when.replace(tzinfo=timezone.utc)) - datetime(1970, 1, 1, tzinfo=timezone.utc)
    (rec,) = read_csv([b"time,sensor,value\n", f"{text},A,1\n".encode()])
    assert rec == Record(2, expected.total_seconds(), "A", (1.0,))


iso_like = st.from_regex(r"\A[0-9]{4}-[0-9]{2}-[0-9]{2}([T ][0-9]{2}(:[0-9]{2}(:[0-9]{2}([.,][0-9]{1,9})?)?)?(Z|[+-][0-9]{2}(:?[0-9]{2})?)?)?\Z")
cell = st.one_of(iso_like, st.sampled_from(["", "nan", "1.5", "-3", "1e999", "x"]), st.text(max_size=6))


@settings(max_examples=100, deadline=None)
@given(st.lists(st.lists(cell, min_size=1, max_size=6), max_size=12), st.booleans())
def test_iso_like_times_and_wide_rows_never_raise(rows, wide):
    text = "t,east,north,r\n" if wide else "time,sensor,value\n"
    text += "".join(",".join(c.replace('"', "").replace("\n", "").replace("\r", "") for c in row) + "\n" for row in rows)
    layout = WIDE if wide else None
    for r in read_csv(text.encode().splitlines(keepends=True), layout=layout):
        assert isinstance(r, (Record, BadRecord))
        if isinstance(r, Record):
            assert math.isfinite(r.time)
        else:
            assert r.field and "\n" not in r.message


def test_a_line_break_inside_a_csv_line_is_a_malformed_record():
    """A line handed over as a string with a line break inside (a list of lines) is refused as malformed CSV."""
    out = list(read_records(["time,sensor,value", "1,A,1", "2,A,2\n3,A,3"], "csv"))
    bad = [r for r in out if isinstance(r, BadRecord)]
    assert len(bad) == 1 and bad[0].field == "record" and "malformed CSV" in bad[0].message
