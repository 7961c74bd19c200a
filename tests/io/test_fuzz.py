"""Fuzzing the readers and ``pursuit track``: never a traceback, never a silent wrong answer.

Random bytes, truncated lines, huge numbers, NaN and infinity, unknown
sensors and wrong column counts.  Where a test can know the right answer it
checks it with an oracle written independently of the readers: every line is
either reported bad with its line number, or accepted with exactly the
values its text says, and the estimates equal a run on the good lines alone.
"""

from __future__ import annotations

import dataclasses
import io
import json
import math
import re
import sys

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pursuit.cli import main
from pursuit.io import BadRecord, Record, load_track_model, read_csv, read_jsonl, track_records
from pursuit.io.input_spec import InputSpec

from .conftest import EXAMPLES

MODEL = load_track_model(EXAMPLES / "wsn-range.toml")  # sensors A1..A4, range, valid [-1e9, 1e9], prior at t = 0
SENSORS = ["A1", "A2", "A3", "A4"]
# the oracles judge each record alone; the largest-gap rule depends on the records before (tests/io/test_steps.py)
UNLIMITED = dataclasses.replace(MODEL, input=InputSpec())
FUZZ = settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])


def _check_outputs(out, n_lines):
    for r in out:
        assert isinstance(r, (Record, BadRecord))
        assert 1 <= r.line <= n_lines
        if isinstance(r, Record):
            assert math.isfinite(r.time)
            assert all(math.isfinite(v) or math.isnan(v) for v in r.values)
        else:
            assert r.field and r.message and "\n" not in r.message


@FUZZ
@given(st.binary(max_size=2000))
def test_csv_reader_survives_random_bytes(blob):
    data = b"time,sensor,value\n" + blob
    out = list(read_csv(io.BytesIO(data)))
    _check_outputs(out, data.count(b"\n") + 1)


@FUZZ
@given(st.binary(max_size=2000))
def test_jsonl_reader_survives_random_bytes(blob):
    out = list(read_jsonl(io.BytesIO(blob)))
    _check_outputs(out, blob.count(b"\n") + 1)


# --------------------------------------------------------------------------
# CSV with an oracle
# --------------------------------------------------------------------------
_NUM = re.compile(r"[+-]?([0-9]+\.?[0-9]*|\.[0-9]+)([eE][+-]?[0-9]+)?")  # ASCII digits (docs/track.md)

good_number = st.floats(min_value=0.001, max_value=500.0, allow_nan=False).map(repr)
bad_number = st.sampled_from(["inf", "-inf", "Infinity", "1e999", "-1e400", "abc", "1.2.3", "0x1F", "1_0", "--1", "1e", "e5", "∞", "NaN-ish"])
huge_number = st.sampled_from(["1e12", "-5e9", "1.7976931348623157e308"])
value_token = st.one_of(good_number, good_number, good_number, st.just(""), st.just("nan"), bad_number, huge_number)
time_token = st.one_of(
    st.floats(min_value=0.5, max_value=50.0, allow_nan=False).map(lambda t: repr(round(t, 1))),
    st.sampled_from(["", "nan", "inf", "1e999", "t", "-3", "0", "1e400"]),
)
sensor_token = st.one_of(st.sampled_from(SENSORS), st.sampled_from(["", "A5", "a1", "B", " A2 "]))


@st.composite
def csv_lines(draw):
    """A line of text and whether the generator meant it as a record line."""
    kind = draw(st.sampled_from(["record", "record", "record", "record", "short", "long", "garbage", "comment", "blank"]))
    t, s = draw(time_token), draw(sensor_token)
    if kind == "record":
        text = f"{t},{s},{draw(value_token)}"
    elif kind == "short":
        text = draw(st.sampled_from([f"{t}", f"{t},{s}", ""]))
    elif kind == "long":
        text = ",".join([t, s, *draw(st.lists(value_token, min_size=2, max_size=4))])
    elif kind == "garbage":
        text = draw(st.text(alphabet=st.characters(blacklist_characters='\n\r"', blacklist_categories=("Cs",)), max_size=30))
    elif kind == "comment":
        text = "# " + draw(st.text(alphabet="abc ,1", max_size=10))
    else:
        text = ""
    if draw(st.booleans()) and len(text) > 1 and kind != "comment":  # truncated somewhere
        text = text[: draw(st.integers(1, len(text) - 1))]
    return text


def oracle(text: str):
    """The record a line should give: None (skipped), "bad", or (time, sensor, values)."""
    if not text.strip() or text.lstrip().startswith("#"):
        return None
    parts = [p.strip() for p in text.split(",")]
    if len(parts) < 3:
        return "bad"
    t, s, vals = parts[0], parts[1], parts[2:]
    if not _NUM.fullmatch(t) or not math.isfinite(float(t)) or not s:
        return "bad"
    values = []
    for v in vals:
        if v.lower() in ("", "nan"):
            values.append(math.nan)
        elif _NUM.fullmatch(v) and math.isfinite(float(v)):
            values.append(float(v))
        else:
            return "bad"
    if s not in SENSORS or len(values) != 1 or (not math.isnan(values[0]) and abs(values[0]) > 1e9):
        return "bad"
    if float(t) <= 0.0:  # the prior is at t = 0
        return "bad"
    return float(t), s, tuple(values)


def _mark_duplicates(expected: dict) -> dict:
    """After the stable sort by time, a second record of one sensor at one time is bad."""
    good = sorted(((ln, r) for ln, r in expected.items() if isinstance(r, tuple)), key=lambda p: p[1][0])
    seen = set()
    for ln, (t, s, _) in good:
        if (t, s) in seen:
            expected[ln] = "bad"
        seen.add((t, s))
    return expected


@FUZZ
@given(st.lists(csv_lines(), max_size=40))
def test_every_csv_line_is_reported_or_read_exactly(lines):
    text = "time,sensor,value\n" + "\n".join(lines) + "\n"
    result = track_records(read_csv(io.BytesIO(text.encode())), MODEL)
    expected = _mark_duplicates({i + 2: oracle(line) for i, line in enumerate(lines)})
    bad_lines = {ln for ln, r in expected.items() if r == "bad"}
    reported = {p.line: p for p in result.problems}
    refused = {ln for ln, p in reported.items() if p.field in ("record", "time") and p.message.startswith("rejected at time")}
    assert set(reported) - refused == bad_lines
    for est in result.estimates:
        assert np.all(np.isfinite(est.mean)) and np.all(est.var > 0)
    if not refused:
        # the estimates equal a run on the good lines alone, written cleanly
        clean = "time,sensor,value\n" + "".join(
            f"{r[0]!r},{r[1]},{r[2][0]!r}\n" for ln, r in sorted(expected.items()) if isinstance(r, tuple)
        )
        ref = track_records(read_csv(io.BytesIO(clean.encode())), MODEL)
        assert ref.problems == []
        assert [e.time for e in result.estimates] == [e.time for e in ref.estimates]
        for a, b in zip(result.estimates, ref.estimates):
            np.testing.assert_array_equal(a.mean, b.mean)
            np.testing.assert_array_equal(a.var, b.var)


# --------------------------------------------------------------------------
# JSON Lines with an oracle
# --------------------------------------------------------------------------
json_scalars = st.one_of(
    st.none(),
    st.booleans(),
    st.integers(min_value=-(10**30), max_value=10**30),
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(min_value=0.1, max_value=100.0),
    st.text(max_size=5),
)
json_values = st.recursive(json_scalars, lambda inner: st.lists(inner, max_size=3) | st.dictionaries(st.text(max_size=4), inner, max_size=3), max_leaves=8)


@st.composite
def json_objects(draw):
    """Half well-formed records (some with a flaw), half random objects."""
    if draw(st.booleans()):
        obj = {"time": draw(st.floats(min_value=0.1, max_value=60.0)), "sensor": draw(st.sampled_from(SENSORS))}
        key = draw(st.sampled_from(["value", "values"]))
        obj[key] = draw(st.one_of(st.floats(min_value=0.1, max_value=150.0), st.lists(st.floats(min_value=0.1, max_value=150.0), min_size=1, max_size=1), st.none()))
        flaw = draw(st.integers(0, 9))
        if flaw == 0:
            obj[draw(st.sampled_from(["time", "sensor", key]))] = draw(json_values)
        elif flaw == 1:
            del obj[draw(st.sampled_from(["time", "sensor", key]))]
        elif flaw == 2:
            obj[draw(st.text(max_size=5))] = 1
        return obj
    obj = {}
    if draw(st.integers(0, 4)):
        obj["time"] = draw(st.one_of(st.floats(min_value=0.1, max_value=60.0), json_scalars))
    if draw(st.integers(0, 4)):
        obj["sensor"] = draw(st.one_of(st.sampled_from(SENSORS), json_scalars))
    key = draw(st.sampled_from(["value", "values", "value", None, "both"]))
    val = draw(st.one_of(st.floats(min_value=0.1, max_value=150.0), st.lists(st.floats(min_value=0.1, max_value=150.0), max_size=2), json_values))
    if key == "both":
        obj["value"] = obj["values"] = val
    elif key is not None:
        obj[key] = val
    if draw(st.integers(0, 9)) == 0:
        obj[draw(st.text(max_size=5))] = 1
    return obj


def _num(v, missing_ok):
    if v is None:
        return math.nan if missing_ok else "bad"
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return "bad"
    if isinstance(v, int) and abs(v) > 1e308:
        return "bad"
    f = float(v)
    if math.isnan(f):
        return math.nan if missing_ok else "bad"
    return f if math.isfinite(f) else "bad"


def json_oracle(obj):
    """The record an object should give: "bad", "predict" (time only) or (time, sensor, values)."""
    if set(obj) - {"time", "sensor", "value", "values"} or "time" not in obj:
        return "bad"
    t = _num(obj["time"], False)
    if t == "bad" or ("value" in obj and "values" in obj):
        return "bad"
    has_value = "value" in obj or "values" in obj
    s = obj.get("sensor")
    if s is None:
        return "bad" if has_value else ("predict" if t > 0 else "bad")
    if not isinstance(s, str) or not s.strip() or not has_value:
        return "bad"
    raw = obj.get("value", obj.get("values"))
    items = raw if isinstance(raw, list) else [raw]
    if not items or any(isinstance(v, (list, dict)) for v in items):
        return "bad"
    vals = [_num(v, True) for v in items]
    if "bad" in vals or s.strip() not in SENSORS or len(vals) != 1 or (not math.isnan(vals[0]) and abs(vals[0]) > 1e9):
        return "bad"
    return (t, s.strip(), tuple(vals)) if t > 0 else "bad"


@FUZZ
@given(st.lists(json_objects(), max_size=25))
def test_every_jsonl_object_is_reported_or_read_exactly(objs):
    lines = [json.dumps(o) for o in objs]  # json.dumps writes NaN and Infinity as the reader accepts them
    result = track_records(read_jsonl(io.BytesIO(("\n".join(lines) + "\n").encode())), UNLIMITED)
    expected = _mark_duplicates({i + 1: json_oracle(o) for i, o in enumerate(objs)})
    reported = {p.line for p in result.problems if not p.message.startswith("rejected at time")}
    assert reported == {ln for ln, r in expected.items() if r == "bad"}
    times = sorted({r[0] for r in expected.values() if isinstance(r, tuple)} | {objs[ln - 1]["time"] for ln, r in expected.items() if r == "predict"})
    if not any(p.message.startswith("rejected at time") for p in result.problems):
        assert [e.time for e in result.estimates] == [float(t) for t in times]
    for est in result.estimates:
        assert np.all(np.isfinite(est.mean)) and np.all(est.var > 0)


# --------------------------------------------------------------------------
# the command
# --------------------------------------------------------------------------
@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture])
@given(st.lists(csv_lines(), max_size=15), st.booleans(), st.booleans())
def test_the_command_never_raises_and_writes_all_or_nothing(tmp_path_factory, lines, skip_bad, as_stream):
    d = tmp_path_factory.mktemp("fuzz")
    data = d / "data.csv"
    data.write_text("time,sensor,value\n" + "\n".join(lines) + "\n")
    out = d / "est.csv"
    argv = ["track", str(data), "-c", str(EXAMPLES / "wsn-range.toml"), "-o", str(out)]
    argv += ["--skip-bad"] if skip_bad else []
    argv += ["--stream", "--out-of-order", "drop"] if as_stream else []
    old_err = sys.stderr
    sys.stderr = io.StringIO()
    try:
        code = main(argv)
        err = sys.stderr.getvalue()
    finally:
        sys.stderr = old_err
    assert code in (0, 2)
    assert "Traceback" not in err
    bad = [ln for ln, r in ((i + 2, oracle(t)) for i, t in enumerate(lines)) if r == "bad"]
    good = [r for r in map(oracle, lines) if isinstance(r, tuple)]
    if code == 2:
        assert err
        assert not skip_bad or (not good and "nothing to track" in err)  # --skip-bad fails only with nothing left
        if not as_stream:
            assert not out.exists()  # nothing written
    if not good:  # only the header (and records that are bad or skipped): nothing to track
        assert code == 2
    if out.exists():
        rows = out.read_text().splitlines()
        assert rows[0].startswith("time,x,vx,y,vy")
        for row in rows[1:]:
            assert all(math.isfinite(float(v)) for v in row.split(",")[:9])
    if bad and not skip_bad and not as_stream:
        assert code == 2
