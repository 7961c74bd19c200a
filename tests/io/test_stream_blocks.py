"""The block lane of ``pursuit track --stream`` against the line-by-line reference, byte for byte.

The reference is the record-by-record path the blocks replace (every chunk
read line by line: ``_plain`` refused), which ``tests/io`` and ``tests/fuzz``
check on their own; the blocks must give the same output bytes, the same
messages on standard error and the same exit code, for inputs that mix plain
runs with everything that is not plain (gaps, missing fields, several
sensors at one time, bad and late lines).  Batch and stream write the same
bytes (docs/cli.md), so the batch output is checked too.
"""

from __future__ import annotations

import io
import json
import math

import numpy as np
import pytest

from pursuit.cli import main
from pursuit.io import lines as lines_mod
from pursuit.io import records as records_mod
from pursuit.io import tracker as tracker_mod
from pursuit.io import writers as writers_mod
from pursuit.io.blocks import EstimateBlock, RecordBlock
from pursuit.io.lines import ChunkedLines
from pursuit.io.records import block_records, read_csv, read_jsonl, read_record_chunks
from pursuit.io.steps import INPUT_WAITS
from pursuit.io.tracker import Estimate, block_estimates
from pursuit.io.writers import make_writer

MODEL = """\
[motion]
type = "cv"
ndim = 2
q = 0.01
dt = 1.0

[[sensors]]
id = "gps"
type = "position"
sigma = 5.0

[[sensors]]
id = "fix"
type = "position"
sigma = 3.0

[prior]
time = 0.0
mean = [0.0, 1.0, 0.0, 0.5]
cov = [100.0, 4.0, 100.0, 4.0]

[filter]
type = "kf"
backend = "{backend}"
"""


def _backend_available(backend: str) -> None:
    if backend == "numba":
        pytest.importorskip("numba")


def _mixed_rows(n: int = 1500, seed: int = 3) -> list[tuple[float, str, str, str]]:
    """(time, sensor, x, y) text fields: long plain runs broken by every kind of record that is not plain."""
    rng = np.random.default_rng(seed)
    rows: list[tuple[float, str, str, str]] = []
    t = 0.0
    for i in range(n):
        t += 1.0
        x, y = repr(round(1.0 * t + rng.normal(0, 5), 3)), repr(round(0.5 * t + rng.normal(0, 5), 3))
        if i == 200:
            t += 6.5  # a gap: an irregular dt
        if i in (300, 301, 302):
            y = ""  # a missing component
        if i == 400:
            rows.append((t, "fix", x, y))  # two sensors at one time
        if i == 500:
            rows.append((t, "gps", x, "12..5"))  # a bad value
        if i == 600:
            rows.append((t - 3.0, "gps", x, y))  # a late record: dropped
        if i == 700:
            rows.append((t, "radar", x, y))  # an unknown sensor
        if i == 800:
            rows.append((t, "gps", x, y))  # the same sensor twice at one time
        if i == 900:
            rows.append((t, "gps", x, "1e999"))  # overflows
        if i == 1000:
            x = " " + x  # spaces: read, but not plain
        if i == 1100:
            rows.append((t, "fix", x, y))  # the other sensor alone
            t += 1.0
        rows.append((t, "gps", x, y))
    return rows


def _csv(rows) -> str:
    return "time,sensor,x,y\n" + "".join(f"{t!r},{s},{x},{y}\n" for t, s, x, y in rows)


def _jsonl(rows) -> str:
    out = []
    for t, s, x, y in rows:
        if "1e999" in y or "12..5" in y:
            out.append(f'{{"time": {t!r}, "sensor": "{s}", "value": [{x.strip()}, "{y}"]}}')
            continue
        value = [float(x), float(y) if y else None]
        out.append(json.dumps({"time": t, "sensor": s, "value": value}))
    out.insert(50, json.dumps({"time": 50.5}))  # an estimate without a measurement
    out.insert(60, '{"time": 60.5, "time": 60.7}')  # a repeated key
    return "\n".join(out) + "\n"


def _run(tmp_path, text: str, fmt: str, backend: str, args: list[str], name: str, capsys):
    model = tmp_path / f"model-{backend}.toml"
    model.write_text(MODEL.format(backend=backend))
    data = tmp_path / f"data.{fmt}"
    data.write_text(text)
    out = tmp_path / f"{name}.{fmt}"
    capsys.readouterr()
    code = main(["track", str(data), "--config", str(model), *args, "-o", str(out)])
    err = capsys.readouterr().err.replace(str(out), "OUT")
    return code, (out.read_bytes() if out.exists() else None), err


def _line_by_line(monkeypatch) -> None:
    """The reference: no chunk is plain, so every line goes through the record-by-record reader."""
    monkeypatch.setattr(records_mod._CsvReader, "_plain", lambda self, raws: None)
    monkeypatch.setattr(records_mod._JsonlReader, "_plain", lambda self, raws: None)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
@pytest.mark.parametrize("fmt", ["csv", "jsonl"])
@pytest.mark.parametrize("chunk", [700, None])
def test_blocks_give_the_bytes_and_messages_of_the_line_by_line_stream(tmp_path, monkeypatch, capsys, backend, fmt, chunk):
    _backend_available(backend)
    if chunk is not None:
        monkeypatch.setattr(lines_mod, "CHUNK_BYTES", chunk)
        monkeypatch.setattr(tracker_mod, "BLOCK_STEPS", 64)
    rows = _mixed_rows()
    text = _csv(rows) if fmt == "csv" else _jsonl(rows)
    taken = []
    original = tracker_mod.Tracker.update_block
    monkeypatch.setattr(tracker_mod.Tracker, "update_block", lambda self, *a: taken.append(1) or original(self, *a))
    got = _run(tmp_path, text, fmt, backend, ["--stream", "--skip-bad"], "blocks", capsys)
    with monkeypatch.context() as m:
        _line_by_line(m)
        ref = _run(tmp_path, text, fmt, backend, ["--stream", "--skip-bad"], "ref", capsys)
    batch = _run(tmp_path, text, fmt, backend, ["--batch", "--skip-bad", "--out-of-order", "drop"], "batch", capsys)
    assert got[0] == ref[0] == batch[0] == 0
    assert got[1] == ref[1] == batch[1]
    assert got[2] == ref[2]
    assert f"skipped {4 if fmt == 'csv' else 5} bad record(s)" in got[2] and "late record dropped" in got[2]
    assert len(got[1].decode().splitlines()) > 1400
    if backend == "numba":
        assert taken  # the block lane ran
    # stopping at the first bad record: the same estimates before it, the same report
    got = _run(tmp_path, text, fmt, backend, ["--stream"], "blocks-stop", capsys)
    with monkeypatch.context() as m:
        _line_by_line(m)
        ref = _run(tmp_path, text, fmt, backend, ["--stream"], "ref-stop", capsys)
    assert got == ref and got[0] == 2


# --------------------------------------------------------------------------
# the chunk readers against the line readers
# --------------------------------------------------------------------------
_CSV_FIELDS = ["1.5", "-2", "+.5", "5.", "1e3", "1E-3", "7.25e+2", "", "nan", "NaN", "inf", "-Infinity", "1e999", "+-1", "1_0",
               " 3", "3 ", "12..5", "e5", ".", "2026-07-01", "0x10", "\uff14", "1e", "-0.0", "3\r"]


def _expand(items) -> list:
    out = []
    for item in items:
        if isinstance(item, RecordBlock):
            out.extend(block_records(item))
        elif item is not INPUT_WAITS:
            out.append(item)
    return out


def _chunks(raws: list[bytes], rng) -> list[list[bytes]]:
    cuts = sorted(set(rng.integers(0, len(raws), 6).tolist()) | {0, len(raws)})
    return [raws[a:b] for a, b in zip(cuts, cuts[1:]) if b > a]


@pytest.fixture
def fine_halving(monkeypatch):
    """Halve a chunk with a line that is not plain down to 4 lines (more halving, more blocks)."""
    monkeypatch.setattr(records_mod, "_SMALLEST_SPLIT", 2)


@pytest.mark.parametrize("seed", range(12))
def test_csv_chunks_read_as_the_lines(seed, fine_halving):
    """Random plain rows with tricky fields here and there: blocks and bad records exactly as read_csv."""
    rng = np.random.default_rng(seed)
    rows = ["time,sensor,x,y"]
    for i in range(400):
        fields = [repr(float(i + 1)), "gps", repr(float(rng.normal())), repr(float(rng.normal()))]
        if rng.random() < 0.02:
            fields[int(rng.integers(0, 4))] = _CSV_FIELDS[int(rng.integers(0, len(_CSV_FIELDS)))]
        if rng.random() < 0.01:
            fields.append("9")  # a field beyond the header
        line = ",".join(fields)
        if rng.random() < 0.01:
            line = rng.choice(["", "# a comment", '1,"gps",2,3', "1,gps", "  "])
        rows.append(line)
    data = ("\n".join(rows) + ("\n" if seed % 3 else "")).encode()
    raws = list(iter(io.BytesIO(data).readline, b""))
    for unterminated in ("accept", "reject"):
        expected = list(read_csv(raws, unterminated))
        got = list(read_record_chunks(_chunks(raws, rng), "csv", unterminated))
        assert _expand(got) == expected
        assert any(isinstance(item, RecordBlock) for item in got)


@pytest.mark.parametrize(
    "body",
    [
        ["1,1,3,4,5", "2,1,3"],  # one field too many, then one too few: as many fields in all as plain rows would have
        ["1,1,3", "2,1,3,4,5"],
        ["1,1,3,4", "2,1,3,4,5", "3,1,3"],
        ["1,1,3,4", "2,1,3,4"],  # plain (numeric sensor ids): one block
    ],
)
def test_csv_chunk_of_rows_of_unequal_width_reads_as_the_lines(body):
    # the chunk is split once for all its rows: rows of unequal width must not shift the columns of the rows after them
    raws = [line.encode() + b"\n" for line in ["time,sensor,x,y", *body * 20]]
    expected = list(read_csv(raws))
    got = list(read_record_chunks([raws], "csv"))
    assert _expand(got) == expected
    assert any(isinstance(item, RecordBlock) for item in got) == (len(body) == 2 and body[0].count(",") == body[1].count(","))


_JSON_LINES = [
    '{"time": 1, "time": 2, "sensor": "gps"}',
    '{"time": 1.0, "sensor": "gps", "value": [1, NaN]}',
    '{"time": 1.0, "sensor": "gps", "value": [1, Infinity]}',
    '{"time": 1.0, "sensor": "gps", "value": [true, 2]}',
    '{"time": 1.0, "sensor": "gps", "value": [1e400, 2]}',
    '{"time": 1.0, "sensor": "gps", "value": [%d, 2]}' % (10**400),
    '{"time": "2026-07-01T00:00:00Z", "sensor": "gps", "value": [1, 2]}',
    '{"time": 1.0, "sensor": " gps", "value": [1, 2]}',
    '{"time": 1.0, "sensor": "", "value": [1, 2]}',
    '{"time": 1.0, "sensor": "gps", "values": [1, 2]}',
    '{"time": 1.0, "sensor": "gps", "value": 1}',
    '{"time": 1.0, "sensor": "gps", "value": [[1], 2]}',
    '{"time": 1.0, "sensor": "gps", "value": [null, 2]}',
    '{"time": 1.0, "sensor": "gps", "value": []}',
    '{"time": 1.0}',
    '{"time": 1.0, "sensor": "gps", "value": [1, 2]} {"time": 2.0, "sensor": "gps", "value": [1, 2]}',
    '{"time": 1.0, "sensor": "gps", "value": [1,',
    '2]}',
    '[1, 2]',
    '"just a string"',
    '',
    '{"time": 1.0, "sensor": "gps", "value": [1, 2], "x": 1}',
    '{"time": 1.0, "sensor": "g\\"ps", "value": [1, 2]}',
    '{"time": 1.0, "\\u0074ime": 2.0, "sensor": "gps"}',
]


@pytest.mark.parametrize("seed", range(12))
def test_jsonl_chunks_read_as_the_lines(seed, fine_halving):
    rng = np.random.default_rng(seed)
    lines = []
    for i in range(400):
        if rng.random() < 0.03:
            lines.append(_JSON_LINES[int(rng.integers(0, len(_JSON_LINES)))])
        else:
            value = [float(rng.normal()), int(rng.integers(-5, 5))]
            lines.append(json.dumps({"sensor": "gps", "value": value, "time": float(i + 1)} if i % 7 else {"time": i + 1, "sensor": "gps", "value": value}))
    data = ("\n".join(lines) + ("\n" if seed % 3 else "")).encode()
    raws = list(iter(io.BytesIO(data).readline, b""))
    for unterminated in ("accept", "reject"):
        expected = list(read_jsonl(raws, unterminated))
        got = list(read_record_chunks(_chunks(raws, rng), "jsonl", unterminated))
        assert _expand(got) == expected
        if sum(isinstance(r, records_mod.Record) for r in expected) > 300:  # not an input of ISO times
            assert any(isinstance(item, RecordBlock) for item in got)


def test_chunk_reader_marks_each_wait_before_a_chunk():
    src = ChunkedLines(io.BytesIO(b"time,sensor,x\n1,a,2\n2,a,3\n"), chunk=14)
    items = list(read_record_chunks(src.chunks(), "csv", ready=src.ready))
    assert items[0] is INPUT_WAITS and items[-1] is INPUT_WAITS
    assert [r.time for r in _expand(items)] == [1.0, 2.0]


def test_chunks_give_the_lines_of_iteration():
    data = b"".join(b"%d,a,%d\n" % (i, i) for i in range(3000)) + b"tail"
    chunks = list(ChunkedLines(io.BytesIO(data), chunk=1000).chunks())
    assert len(chunks) > 10
    assert [line for c in chunks for line in c] == list(ChunkedLines(io.BytesIO(data), chunk=1000))


# --------------------------------------------------------------------------
# the block writers against the row writers
# --------------------------------------------------------------------------
@pytest.mark.parametrize("fmt", ["csv", "jsonl"])
def test_write_block_writes_the_rows_of_write(fmt):
    rng = np.random.default_rng(5)
    n, d = 50, 3
    means = rng.normal(size=(n, d)) * 10.0 ** rng.integers(-300, 300, size=(n, d))
    means[0, 0], means[1, 1] = -0.0, 0.1 + 0.2
    var = rng.random((n, d)) + 1e-12
    covs = np.zeros((n, d, d))
    nis = rng.random(n) * 3.0
    nis[[2, 7]] = math.nan
    dof = [2] * n
    dof[2] = dof[7] = 0
    flags: list[tuple[str, ...]] = [()] * n
    flags[2], flags[7], flags[9] = ("predict",), ("gated", "predict", "diverged"), ("diverged",)
    times = np.cumsum(rng.random(n)) + 1e9 / 3.0
    block = EstimateBlock(times, means, var, nis, dof, flags, np.arange(n) + 2, covs)
    labels = ["x", 'q"uote', "\u00e9t\u00e9"]
    rows, whole = io.StringIO(), io.StringIO()
    writer = make_writer(fmt, rows, labels)
    for i in range(n):
        writer.write(Estimate(float(times[i]), means[i], var[i], float(nis[i]), dof[i], flags[i], (i + 2,), covs[i]))
    make_writer(fmt, whole, labels).write_block(block)
    assert whole.getvalue() == rows.getvalue()
    assert [e.flags for e in block_estimates(block)] == flags


AWKWARD = [-0.0, 0.0, 1e-300, -1e-300, 1e300, 5e-324, 2.2250738585072014e-308, 3.0, -7.0, 2.0**53, 2.0**53 + 2, 1e16, 1e15, 1e-4, 1e-5,
           0.1 + 0.2, 1 / 3, 123456789.0, 1.7976931348623157e308]


@pytest.mark.parametrize("fmt", ["csv", "jsonl"])
def test_write_block_writes_the_rows_of_write_on_awkward_values(fmt):
    # the values whose text is easiest to get wrong (signed zero, subnormals, the edges of repr's exponent
    # notation, integral floats), runs of rows that differ in dof, flags and a NaN NIS, and '%' in a label
    # and in a flag (the block's row format must write them as text)
    rng = np.random.default_rng(11)
    n, d = 400, 2
    means = rng.choice(AWKWARD, size=(n, d)) * rng.choice([1.0, -1.0], size=(n, d))
    var = rng.choice([v for v in AWKWARD if v > 0], size=(n, d))
    nis = rng.choice(AWKWARD, size=n)
    nis[rng.random(n) < 0.1] = math.nan
    if fmt == "csv":  # CSV writes repr of any float (JSON Lines refuses these in _format, and a block never holds them)
        means[5, 0], var[6, 1], nis[8] = math.inf, math.nan, -math.inf
    times = np.cumsum(rng.choice([1e-300, 5e-324, 3.0, 1 / 3, 0.1 + 0.2, 1e-5, 1e15, 2.0**53], size=n)) + 0.5
    times[:3] = [1e-300, 1.0, 3.0]
    dof = rng.choice([0, 1, 2, 2, 2, 2], size=n).tolist()
    names = [(), (), (), ("predict",), ("gated", "diverged"), ("10%",), ("%s%%",)]
    flags = [names[k] for k in rng.choice(len(names), size=n)]
    flags[100:250] = [("diverged",)] * 150  # a long run of flagged rows
    dof[100:250] = [2] * 150
    block = EstimateBlock(times, means, var, nis, dof, flags, np.arange(n) + 2, np.zeros((n, d, d)))
    labels = ["x%", "%(y)s"]
    rows, whole = _row_by_row_and_whole(fmt, block, labels)
    assert whole.getvalue() == rows.getvalue()
    assert "-0.0" in whole.getvalue() and "5e-324" in whole.getvalue() and "1e+300" in whole.getvalue()
    # one row and no rows: the header (CSV) and that row, the header alone
    head = io.StringIO()
    make_writer(fmt, head, labels).start()
    first = rows.getvalue()[len(head.getvalue()) :].splitlines(keepends=True)[0]
    for k, want in [(1, head.getvalue() + first), (0, head.getvalue())]:
        out = io.StringIO()
        part = EstimateBlock(times[:k], means[:k], var[:k], nis[:k], dof[:k], flags[:k], block.lines[:k], block.covs[:k])
        make_writer(fmt, out, labels).write_block(part)
        assert out.getvalue() == want


def _row_by_row_and_whole(fmt: str, block: EstimateBlock, labels: list[str]) -> tuple[io.StringIO, io.StringIO]:
    """The block written row by row (``write`` of each Estimate, the reference) and whole (``write_block``)."""
    rows, whole = io.StringIO(), io.StringIO()
    writer = make_writer(fmt, rows, labels)
    for i in range(len(block.times)):
        writer.write(Estimate(float(block.times[i]), block.means[i], block.var[i], float(block.nis[i]), block.dof[i],
                              block.flags[i], (int(block.lines[i]),), block.covs[i]))
    make_writer(fmt, whole, labels).write_block(block)
    return rows, whole


@pytest.mark.parametrize("fmt", ["csv", "jsonl"])
def test_write_block_writes_the_rows_of_write_on_repeated_values(fmt):
    # columns that repeat their value over runs of rows (a converged covariance) are written as text made once per
    # run: equal bits only, so -0.0 next to 0.0 and NaNs of another payload are runs of their own
    rng = np.random.default_rng(12)
    n, d = 400, 3
    positive = [v for v in AWKWARD if v > 0]
    var = np.column_stack([np.repeat(rng.choice(positive, 20), 20), np.full(n, 1e-300), rng.random(n) + 1.0])
    var[37, 1] = 5e-324  # one change in a constant column
    means = np.column_stack([np.tile(np.repeat([-0.0, 0.0], 25), n // 50), np.repeat(rng.choice(AWKWARD, 8), 50), rng.normal(size=n)])
    nis = np.repeat(rng.choice([5e-324, 2.0**53, math.nan, 0.5], 10), 40)
    if fmt == "csv":  # NaNs of two payloads, one run each (both write 'nan')
        other_nan = np.array([0x7FF8000000000001], dtype=np.int64).view(float)[0]
        means[100:150, 1], means[150:200, 1] = math.nan, other_nan
    times = np.arange(n) + 0.5
    dof = [2] * n
    dof[200:220] = [0] * 20
    flags: list[tuple[str, ...]] = [()] * n
    flags[200:220] = [("predict",)] * 20
    flags[300] = ("diverged",)
    block = EstimateBlock(times, means, var, nis, dof, flags, np.arange(n) + 2, np.zeros((n, d, d)))
    labels = ["x", "y", "z"]
    rows, whole = _row_by_row_and_whole(fmt, block, labels)
    assert whole.getvalue() == rows.getvalue()
    codes = [writers_mod._repeated_as_text(np.column_stack([times, means, var, nis]), j, [None] * (n * 8)) for j in range(8)]
    assert codes == ["%r", "%s", "%s", "%r", "%s", "%s", "%r", "%s"]  # the path under test was taken
