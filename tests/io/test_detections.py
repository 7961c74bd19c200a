"""Detection files: round trips through CSV and JSON Lines, streaming equals batch, and every bad input
named by file, line and field."""

from __future__ import annotations

import io
import json

import numpy as np
import pytest

from pursuit.io.detections import (
    DetectionFileError,
    DetectionScan,
    group_scans,
    iter_detections,
    read_detection_records,
    read_detections,
)
from pursuit.io.records import BadRecord
from pursuit.io.steps import Dropped
from pursuit.multitarget import pad_scans
from pursuit.rng import run_streams
from pursuit.scenarios import crossing, maneuvering_radar


def _write_csv(path, scans, columns=("x", "y"), sensor=True):
    lines = [",".join(["time", *(["sensor"] if sensor else []), *columns, "snr"])]  # an ignored extra column
    for k in range(scans.steps):
        t = repr(float(scans.times[k]))
        z = scans.per_run(k, 0)
        if len(z) == 0:
            lines.append(",".join([t, *(["radar"] if sensor else []), *([""] * len(columns)), "0"]))
        for row in z:
            lines.append(",".join([t, *(["radar"] if sensor else []), *map(repr, map(float, row)), "12.5"]))
    path.write_text("\n".join(lines) + "\n")
    return path


def _write_jsonl(path, scans, columns=("x", "y"), sensor=True):
    lines = []
    for k in range(scans.steps):
        t = float(scans.times[k])
        z = scans.per_run(k, 0)
        if len(z) == 0:
            lines.append(json.dumps({"time": t}))
        for row in z:
            obj = {"time": t, **({"sensor": "radar"} if sensor else {}), **dict(zip(columns, map(float, row)))}
            lines.append(json.dumps(obj))
    path.write_text("\n".join(lines) + "\n")
    return path


def _one_run(scenario, seed=0):
    _, scans = scenario.simulate(run_streams(seed, [0], 0))
    return scans


@pytest.mark.parametrize("fmt", ["csv", "jsonl"])
@pytest.mark.parametrize("sensor", [True, False])
def test_round_trip_crossing(tmp_path, fmt, sensor):
    scans = _one_run(crossing(p_detect=0.5, clutter_rate=0.5))  # some scans are empty
    assert (scans.count == 0).any()
    write = _write_csv if fmt == "csv" else _write_jsonl
    path = write(tmp_path / f"d.{fmt}", scans, sensor=sensor)
    back = read_detections(path, ["x", "y"])
    np.testing.assert_array_equal(back.times, scans.times)
    np.testing.assert_array_equal(back.count, scans.count)
    np.testing.assert_array_equal(back.z, scans.select_runs([0]).z)  # file order = row order; repr round-trips
    assert back.origin is None


@pytest.mark.parametrize("fmt", ["csv", "jsonl"])
def test_round_trip_range_bearing_and_streaming_equals_batch(tmp_path, fmt):
    scans = _one_run(maneuvering_radar())
    write = _write_csv if fmt == "csv" else _write_jsonl
    path = write(tmp_path / f"r.{fmt}", scans, columns=("range", "bearing"))
    batch = read_detections(path, ["range", "bearing"])
    streamed = list(iter_detections(path, ["range", "bearing"]))
    assert all(isinstance(s, DetectionScan) for s in streamed)
    assert all(s.sensors == ("radar",) * len(s.z) for s in streamed)
    again = pad_scans([[s.z] for s in streamed], [s.time for s in streamed], dim=2)
    np.testing.assert_array_equal(again.z, batch.z)
    np.testing.assert_array_equal(again.times, batch.times)
    np.testing.assert_array_equal(batch.z, scans.select_runs([0]).z)
    # a binary stream (a pipe) gives the same scans
    with open(path, "rb") as fh:
        piped = list(iter_detections(fh, ["range", "bearing"], fmt=fmt))
    assert [s.time for s in piped] == [s.time for s in streamed]
    for a, b in zip(piped, streamed):
        np.testing.assert_array_equal(a.z, b.z)


class _CountingStream:
    """A binary stream that counts the lines read from it."""

    def __init__(self, lines):
        self.lines = iter(lines)
        self.read = 0
        self.name = "<counting>"

    def readline(self):
        self.read += 1
        return next(self.lines, b"")


def test_streaming_reads_one_scan_ahead_not_the_whole_input():
    def lines():
        yield b"time,x,y\n"
        for k in range(10**6):  # a million records, never materialised
            yield f"{k},{k}.5,1\n".encode()

    stream = _CountingStream(lines())
    scans = iter_detections(stream, ["x", "y"], fmt="csv")
    first = [next(scans) for _ in range(3)]
    assert [s.time for s in first] == [0.0, 1.0, 2.0]
    np.testing.assert_array_equal(first[2].z, [[2.5, 1.0]])
    assert stream.read <= 6  # header, three scans, and the record that closed the third


CSV_HEADER = "time,sensor,x,y\n"


@pytest.mark.parametrize(
    "body,line,field",
    [
        ('1.0,a,1,2\n1.0,a,"3,4\n', 3, "record"),
        ("1.0,a,1,2\n2.0,a,1\n", 3, "record"),
        ("1.0,a,1,2\n2.0,a,nan,1\n", 3, "x"),
        ("1.0,a,1,2\n2.0,a,1,inf\n", 3, "y"),
        ("1.0,a,1,2\n2.0,a,1,1e999\n", 3, "y"),
        ("1.0,a,1,2\n2.0,a,1,\n", 3, "y"),
        ("1.0,a,1,2\n2.0,a,one,2\n", 3, "x"),
        ("1.0,a,1,2\n2.0,,1,2\n", 3, "sensor"),
        ("1.0,a,1,2\n,a,1,2\n", 3, "time"),
        ("1.0,a,1,2\nnan,a,1,2\n", 3, "time"),
        ("2.0,a,1,2\n2.0,a,3,4\n1.0,a,1,2\n", 4, "time"),
        ("1.0,a,1,2\n2026-01-01T00:00:00Z,a,1,2\n", 3, "time"),
    ],
    ids=["bad-quote", "few-fields", "nan", "inf", "overflow", "half-missing", "not-a-number", "no-sensor", "no-time",
         "nan-time", "decreasing-time", "mixed-time-kinds"],
)
def test_bad_csv_names_file_line_and_field(tmp_path, body, line, field):
    path = tmp_path / "bad.csv"
    path.write_text(CSV_HEADER + body)
    for read in (lambda: read_detections(path, ["x", "y"]), lambda: list(iter_detections(path, ["x", "y"]))):
        with pytest.raises(DetectionFileError) as info:
            read()
        e = info.value
        assert (e.path, e.line, e.field) == (str(path), line, field)
        assert str(e).startswith(f"{path}:{line}: {field}: ")


@pytest.mark.parametrize(
    "text,line,field",
    [
        ("time,sensor,x\n1.0,a,2\n", 1, "header"),
        ("time,x,x,y\n1.0,1,2,3\n", 1, "header"),
        ("", 1, "header"),
        ("# only a comment\n\n", 2, "header"),
    ],
)
def test_bad_csv_header(tmp_path, text, line, field):
    path = tmp_path / "h.csv"
    path.write_text(text)
    with pytest.raises(DetectionFileError, match=f"^{path}:{line}: {field}: ") as info:
        read_detections(path, ["x", "y"])
    if "x,x" not in text and text.startswith("time"):
        assert "missing y" in str(info.value)


@pytest.mark.parametrize(
    "body,line,field",
    [
        ('{"time": 1, "x": 1, "y": 2}\n{"time": 2, "x": 1, "y": 2\n', 2, "record"),
        ('{"time": 1, "x": 1, "y": 2}\n[1, 2]\n', 2, "record"),
        ('{"time": 1, "x": 1, "y": 2}\n{"time": 2, "x": 1, "y": 2, "target": 3}\n', 2, "target"),
        ('{"time": 1, "x": 1, "y": 2}\n{"time": 2, "x": null, "y": 2}\n', 2, "x"),
        ('{"time": 1, "x": 1, "y": 2}\n{"time": 2, "x": NaN, "y": 2}\n', 2, "x"),
        ('{"time": 1, "x": 1, "y": 2}\n{"time": 2, "x": 1, "y": Infinity}\n', 2, "y"),
        ('{"time": 1, "x": 1, "y": 2}\n{"time": 2, "x": "1", "y": 2}\n', 2, "x"),
        ('{"time": 1, "x": 1, "y": 2}\n{"time": 2, "x": 1}\n', 2, "y"),
        ('{"time": 1, "x": 1, "y": 2}\n{"x": 1, "y": 2}\n', 2, "time"),
        ('{"time": 1, "x": 1, "y": 2}\n{"time": 2, "x": 1, "x": 3, "y": 2}\n', 2, "x"),
        ('{"time": 1, "x": 1, "y": 2}\n{"time": 2, "sensor": 7, "x": 1, "y": 2}\n', 2, "sensor"),
        ('{"time": 3, "x": 1, "y": 2}\n{"time": 2, "x": 1, "y": 2}\n', 2, "time"),
    ],
    ids=["bad-json", "not-an-object", "unknown-key", "null", "nan", "inf", "string", "half-missing", "no-time",
         "repeated-key", "sensor-not-string", "decreasing-time"],
)
def test_bad_jsonl_names_file_line_and_field(tmp_path, body, line, field):
    path = tmp_path / "bad.jsonl"
    path.write_text(body)
    for read in (lambda: read_detections(path, ["x", "y"]), lambda: list(iter_detections(path, ["x", "y"]))):
        with pytest.raises(DetectionFileError) as info:
            read()
        assert (info.value.line, info.value.field) == (line, field)
        assert str(info.value).startswith(f"{path}:{line}: {field}: ")


def test_batch_reports_the_first_bad_line(tmp_path):
    path = tmp_path / "two.csv"
    path.write_text(CSV_HEADER + "1.0,a,1,2\n2.0,a,x,2\n0.5,a,1,2\n3.0,a,1,\n")
    with pytest.raises(DetectionFileError, match=r":3: x: "):
        read_detections(path, ["x", "y"])


def test_out_of_order_sort_and_drop(tmp_path):
    path = tmp_path / "late.csv"
    path.write_text(CSV_HEADER + "1.0,a,1,1\n3.0,a,3,3\n2.0,a,2,2\n3.0,b,4,4\n")
    with pytest.raises(DetectionFileError, match=r":4: time: out of order"):
        read_detections(path, ["x", "y"])
    s = read_detections(path, ["x", "y"], out_of_order="sort")
    np.testing.assert_array_equal(s.times, [1.0, 2.0, 3.0])
    np.testing.assert_array_equal(s.z[2, 0], [[3.0, 3.0], [4.0, 4.0]])  # equal times keep their file order
    d = read_detections(path, ["x", "y"], out_of_order="drop")
    np.testing.assert_array_equal(d.times, [1.0, 3.0])
    np.testing.assert_array_equal(d.z[1, 0], [[3.0, 3.0], [4.0, 4.0]])
    with pytest.raises(ValueError, match="^out_of_order"):
        list(iter_detections(path, ["x", "y"], out_of_order="sort"))


def test_group_scans_low_level_never_raises():
    records = read_detection_records(["time,x", "1,1", "1,2", "0,3", "2,bad", "2,", "3,4"], "csv", ["x"])
    events = list(group_scans(records, out_of_order="drop", dim=1))
    kinds = [type(e).__name__ for e in events]
    # notes and bad records come as they are read, a scan once a later time closes it
    assert kinds == ["Dropped", "BadRecord", "DetectionScan", "DetectionScan", "DetectionScan"]
    assert isinstance(events[0], Dropped) and events[0].line == 4
    assert isinstance(events[1], BadRecord) and (events[1].line, events[1].field) == (5, "x")
    np.testing.assert_array_equal(events[2].z, [[1.0], [2.0]])
    assert events[3].z.shape == (0, 1) and events[3].time == 2.0  # a scan with no detection
    assert events[4].lines == (7,)


def test_a_stream_cut_mid_record_is_not_read():
    stream = io.BytesIO(b"time,x,y\n0.5,0,0\n1.0,1,2\n1.0,3,4")
    stream.name = "<pipe>"
    scans = iter_detections(stream, ["x", "y"], fmt="csv")
    assert next(scans).time == 0.5
    # the scan at 1.0 is not given out: the cut record may have belonged to it
    with pytest.raises(DetectionFileError, match=r"^<pipe>:4: record: incomplete"):
        next(scans)


def test_a_file_whose_last_line_lacks_a_newline_is_read(tmp_path):
    path = tmp_path / "t.csv"
    path.write_text("time,x,y\n1.0,1,2\n2.0,3,4")
    assert read_detections(path, ["x", "y"]).steps == 2


def test_arguments_are_checked(tmp_path):
    path = tmp_path / "a.csv"
    path.write_text("time,x\n1,2\n")
    for values in ([], "x", ["x", "X"], ["time"], ["sensor", "x"], [""]):
        with pytest.raises(ValueError, match="^values"):
            read_detections(path, values)
    with pytest.raises(ValueError, match="^fmt"):
        read_detections(tmp_path / "a.txt", ["x"])
    with pytest.raises(DetectionFileError, match="missing.csv: file: cannot read"):
        read_detections(tmp_path / "missing.csv", ["x"])
    with pytest.raises(DetectionFileError, match="missing.csv: file: cannot read"):
        list(iter_detections(tmp_path / "missing.csv", ["x"]))
    empty = tmp_path / "e.jsonl"
    empty.write_text("\n")
    with pytest.raises(DetectionFileError, match=r"e.jsonl:1: record: no detection"):
        read_detections(empty, ["x"])


def test_custom_time_and_sensor_columns_and_iso_times(tmp_path):
    path = tmp_path / "c.csv"
    path.write_text("t,id,range,bearing\n2026-01-01T00:00:00Z,r1,100,0.5\n2026-01-01T00:00:01.5Z,r2,200,-0.5\n")
    streamed = list(iter_detections(path, ["range", "bearing"], time_column="t", sensor_column="id"))
    assert [s.sensors for s in streamed] == [("r1",), ("r2",)]
    assert streamed[1].time - streamed[0].time == 1.5
