"""Records to steps: the largest believable gap (issue 16 item 4)."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from pursuit.io import BadRecord, Dropped, Record, Step, assemble_steps, load_track_model, read_csv, stream_records, track_records
from pursuit.io.input_spec import InputSpec
from pursuit.io.model import Sensor

from .conftest import EXAMPLES

SENSORS = {"A": Sensor("A", "range", 1, 0, (-1e9, 1e9))}


def _steps(times, after=0.0, max_gap=100.0, policy="drop"):
    records = [Record(i + 1, t, "A", (1.0,)) for i, t in enumerate(times)]
    return list(assemble_steps(records, SENSORS, 1, after=after, policy=policy, max_gap=max_gap))


def test_a_record_far_beyond_the_last_time_is_bad_and_the_records_after_it_go_on():
    out = _steps([1.0, 2.0, 1e15, 3.0, 4.0])
    assert [e.time for e in out if isinstance(e, Step)] == [1.0, 2.0, 3.0, 4.0]  # 3.0 is not "late"
    (bad,) = [e for e in out if isinstance(e, BadRecord)]
    assert (bad.line, bad.field) == (3, "time")
    assert bad.message == (
        "1000000000000000.0 is 1e+15 s after time 2.0 (line 2), more than the largest gap the model predicts "
        "across (input.max_gap = 100 s): a corrupt time?"
    )


def test_the_gap_is_measured_from_the_last_time_reached_and_the_prior():
    out = _steps([100.0, 200.0, 300.5, 300.0])  # max_gap after the last time reached, but 300.5
    assert [e.time for e in out if isinstance(e, Step)] == [100.0, 200.0, 300.0]
    assert [e.line for e in out if isinstance(e, BadRecord)] == [3]
    (bad,) = _steps([100.5], after=0.0)
    assert bad.message.startswith("100.5 is 100.5 s after the prior's time 0.0, more than")
    # with no prior time the first record has nothing to be measured from
    assert [e.time for e in _steps([1e15, 1e15 + 50.0], after=None)] == [1e15, 1e15 + 50.0]


def test_without_a_limit_every_gap_is_accepted():
    assert [e.time for e in _steps([1.0, 1e15], max_gap=math.inf)] == [1.0, 1e15]


def test_a_stream_with_one_absurd_time_goes_on():
    # issue 16 item 4: `time: 1e15` at line 10 used to make every later record "late"
    model = load_track_model(EXAMPLES / "wsn-range.toml")
    with open(EXAMPLES / "data" / "wsn-range.csv", "rb") as f:
        lines = f.read().decode().splitlines(keepends=True)
    spoiled = lines[:9] + ["1e15,A1,40.0\n"] + lines[10:]
    good = lines[:9] + lines[10:]
    events = list(stream_records(_read(spoiled), model, out_of_order="drop"))
    assert not any(isinstance(e, Dropped) for e in events)
    assert [(e.line, e.field) for e in events if isinstance(e, BadRecord)] == [(10, "time")]
    clean = track_records(_read(good), model).estimates
    got = [e for e in events if not isinstance(e, BadRecord)]
    assert [e.time for e in got] == [e.time for e in clean]
    for a, b in zip(got, clean):
        np.testing.assert_array_equal(a.mean, b.mean)


def test_the_model_files_max_gap_is_used():
    model = load_track_model(EXAMPLES / "wsn-range.toml")
    items = [Record(1, 1.0, "A1", (40.0,)), Record(2, 5000.0, "A1", (40.0,))]
    assert track_records(items, model).problems == []  # within the derived 1.4e5 s
    tight = dataclasses.replace(model, input=InputSpec(max_gap=60.0))
    (bad,) = track_records(items, tight).problems
    assert (bad.line, bad.field) == (2, "time") and "input.max_gap = 60 s" in bad.message


def _read(lines):
    return read_csv([line.encode() for line in lines])


@pytest.mark.parametrize("policy", ["drop", "error"])
def test_a_late_record_is_still_late_and_a_rejected_time_is_not_reached(policy):
    out = _steps([1.0, 3.0, 2.0], policy=policy)
    assert [type(e) for e in out] == [Step, Dropped if policy == "drop" else BadRecord, Step]
    assert "earlier than time 3.0" in out[1].message
    # a time rejected as too far is never reached: an earlier record after it is not late
    out = _steps([5.0, 1.0], policy=policy, max_gap=2.0)
    assert [type(e) for e in out] == [BadRecord, Step] and out[1].time == 1.0


def test_each_sensor_of_a_wide_row_is_checked_on_its_own():
    sensors = {"A": Sensor("A", "range", 1, 0, (0.0, 100.0)), "gps": Sensor("gps", "position", 2, 1, (-1e9, 1e9))}
    layout = InputSpec(columns={"gps": ("east", "north"), "A": ("r",)})
    rows = [b"time,east,north,r\n", b"1.0,3.0,4.0,-5.0\n", b"2.0,3.5,4.5,6.0\n"]
    out = list(assemble_steps(read_csv(rows, layout=layout), sensors, 3, after=0.0))
    assert [(e.line, e.field) for e in out if isinstance(e, BadRecord)] == [(2, "value")]  # the range only
    steps = [e for e in out if isinstance(e, Step)]
    assert [(s.time, s.sensors, s.lines) for s in steps] == [(1.0, ("gps",), (2,)), (2.0, ("gps", "A"), (3,))]
    np.testing.assert_array_equal(steps[1].z, [6.0, 3.5, 4.5])
