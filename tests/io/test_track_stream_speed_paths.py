"""The fast paths of ``pursuit track --stream``: blocks of steps, chunked lines, the one-run streak.

Every fast path is checked against the exact reference it replaces: the
block (one compiled call) against stepping the same records one at a time,
the chunked line reader against ``readline``, the scalar streak against
:class:`pursuit.divergence.DivergenceMonitor`, and the stream output against
the batch output, byte for byte, for both backends.
"""

from __future__ import annotations

import io
import json
import sys

import numpy as np
import pytest

from pursuit.cli import main
from pursuit.divergence import DivergenceMonitor, DivergenceTest
from pursuit.io import lines as lines_mod
from pursuit.io import tracker as tracker_mod
from pursuit.io.lines import ChunkedLines

MODEL = """\
[motion]
type = "cv"
ndim = 2
q = {q}
dt = 1.0

[[sensors]]
id = "gps"
type = "position"
sigma = 5.0

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


def _records(n: int = 600, seed: int = 1, turn_at: int | None = None) -> list[tuple[float, float, float]]:
    """Position fixes of a CV target at t = 1, 2, ...; from ``turn_at`` on it turns hard (the KF diverges)."""
    rng = np.random.default_rng(seed)
    t = np.arange(1, n + 1, dtype=float)
    x, y = 1.0 * t, 0.5 * t
    if turn_at is not None:
        late = t > turn_at
        y = np.where(late, y + 0.5 * (t - turn_at) ** 2, y)
    return list(zip(t.tolist(), np.round(x + rng.normal(0, 5, n), 3).tolist(), np.round(y + rng.normal(0, 5, n), 3).tolist()))


def _csv(rows, *, missing=(), empty=(), gap_after=None, bad_line=None) -> str:
    """CSV text; ``missing`` row indices lose their y, ``empty`` ones both x and y (a prediction at a regular time);
    after row ``gap_after`` the times jump by 37.25 s."""
    out = ["time,sensor,x,y"]
    shift = 0.0
    for i, (t, x, y) in enumerate(rows):
        if gap_after is not None and i == gap_after + 1:
            shift = 37.25
        xs = "" if i in empty else repr(x)
        out.append(f"{t + shift!r},gps,{xs},{'' if i in missing or i in empty else repr(y)}")
        if bad_line is not None and len(out) == bad_line - 1:
            out.append(f"{t + shift + 0.5!r},gps,{x!r},12..5")
    return "\n".join(out) + "\n"


def _jsonl(rows, *, predict_every: int = 0) -> str:
    out = []
    for i, (t, x, y) in enumerate(rows):
        out.append(json.dumps({"time": t, "sensor": "gps", "value": [x, y]}))
        if predict_every and i % predict_every == predict_every - 1:
            out.append(json.dumps({"time": t + 0.5}))  # an estimate request without a measurement
    return "\n".join(out) + "\n"


def _run(tmp_path, text: str, fmt: str, backend: str, mode: str, *, q: float = 0.01, name: str = "out"):
    model = tmp_path / f"model-{backend}-{q}.toml"
    model.write_text(MODEL.format(backend=backend, q=q))
    data = tmp_path / f"data.{fmt}"
    data.write_text(text)
    out = tmp_path / f"{name}-{mode}.{fmt}"
    code = main(["track", str(data), "--config", str(model), f"--{mode}", "-o", str(out)])
    return code, (out.read_bytes() if out.exists() else None)


@pytest.fixture
def small_chunks(monkeypatch):
    """Many blocks: chunks of 700 bytes and blocks of at most 64 steps."""
    monkeypatch.setattr(lines_mod, "CHUNK_BYTES", 700)
    monkeypatch.setattr(tracker_mod, "BLOCK_STEPS", 64)


def _stepped(monkeypatch) -> None:
    """The reference: every step by Tracker.update, as before blocks existed (neither compiled path applies)."""
    monkeypatch.setattr(tracker_mod.Tracker, "update_sequence", lambda self, steps: None)
    monkeypatch.setattr(tracker_mod.Tracker, "update_block", lambda self, times, zs, lines: None)


# --------------------------------------------------------------------------
# stream = batch = stepped, byte for byte
# --------------------------------------------------------------------------
@pytest.mark.parametrize("backend", ["numpy", "numba"])
@pytest.mark.parametrize("case", ["regular", "missing+gap", "diverging", "predictions+diverging"])
def test_stream_equals_batch_and_the_stepped_reference_csv(tmp_path, monkeypatch, small_chunks, backend, case):
    _backend_available(backend)
    q = 1e-4 if "diverging" in case else 0.01
    rows = _records(500, turn_at=250 if "diverging" in case else None)
    text = _csv(rows, missing={3, 70, 71, 300}, gap_after=140) if case == "missing+gap" else _csv(rows)
    if case == "predictions+diverging":  # rows with nothing measured, at regular times: "predict" inside blocks
        text = _csv(rows, missing={20}, empty={10, 11, 120, 400, 401, 499})
    code_s, stream = _run(tmp_path, text, "csv", backend, "stream", q=q)
    code_b, batch = _run(tmp_path, text, "csv", backend, "batch", q=q)
    with monkeypatch.context() as m:
        _stepped(m)
        code_r, ref = _run(tmp_path, text, "csv", backend, "stream", q=q, name="ref")
    assert code_s == code_b == code_r == 0
    assert stream == batch == ref
    body = stream.decode().splitlines()
    assert len(body) == 1 + len(rows)
    if "diverging" in case:
        assert "diverged" in body[-1] and "diverged" not in body[200]
    if case == "predictions+diverging":
        assert [i for i, line in enumerate(body[1:]) if "predict" in line] == [10, 11, 120, 400, 401, 499]
        assert body[401].endswith("predict;diverged")
    if case == "missing+gap":
        assert body[1 + 141].startswith(repr(rows[141][0] + 37.25) + ",")


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_stream_equals_batch_jsonl_with_prediction_requests(tmp_path, monkeypatch, small_chunks, backend):
    _backend_available(backend)
    text = _jsonl(_records(400), predict_every=97)
    code_s, stream = _run(tmp_path, text, "jsonl", backend, "stream")
    code_b, batch = _run(tmp_path, text, "jsonl", backend, "batch")
    with monkeypatch.context() as m:
        _stepped(m)
        _, ref = _run(tmp_path, text, "jsonl", backend, "stream", name="ref")
    assert code_s == code_b == 0
    assert stream == batch == ref
    objs = [json.loads(line) for line in stream.decode().splitlines()]
    assert len(objs) == 400 + 4 and sum("predict" in o["flags"] for o in objs) == 4


def test_the_numba_block_path_is_taken(tmp_path, monkeypatch, small_chunks):
    """With regular times, a compiled KF steps once per block from Python, not once per record."""
    _backend_available("numba")
    calls = []
    original = tracker_mod.Tracker.update
    monkeypatch.setattr(tracker_mod.Tracker, "update", lambda self, step: calls.append(step.time) or original(self, step))
    code, out = _run(tmp_path, _csv(_records(500)), "csv", "numba", "stream")
    assert code == 0 and len(out.decode().splitlines()) == 501
    assert len(calls) == 1  # the first step (it tells the flags); every later one in blocks


# --------------------------------------------------------------------------
# a malformed line in the middle
# --------------------------------------------------------------------------
@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_a_malformed_line_in_the_middle(tmp_path, capsys, small_chunks, backend):
    _backend_available(backend)
    rows = _records(300)
    text = _csv(rows, bad_line=151)
    code_b, batch = _run(tmp_path, text, "csv", backend, "batch")
    err = capsys.readouterr().err
    assert code_b == 2 and batch is None  # all or nothing: no file
    assert f"data.csv:151: value: not a number: '12..5'" in err and "nothing written" in err
    code_s, stream = _run(tmp_path, text, "csv", backend, "stream")
    err = capsys.readouterr().err
    assert code_s == 2 and "data.csv:151: value: not a number: '12..5'" in err and "after 149 estimates" in err
    # a stream writes the estimates before the bad record: those of the batch run on the lines before it
    _, prefix = _run(tmp_path, "\n".join(text.splitlines()[:150]) + "\n", "csv", backend, "batch", name="prefix")
    assert stream == prefix


# --------------------------------------------------------------------------
# ChunkedLines against readline
# --------------------------------------------------------------------------
@pytest.mark.parametrize("chunk", [1, 2, 3, 7, 64, 1 << 16])
@pytest.mark.parametrize("tail", [b"", b"no newline at the end"])
def test_chunked_lines_split_as_readline(chunk, tail):
    rng = np.random.default_rng(chunk)
    pieces = [b"a,b,c\n", b"\n", b"x\r\n", b"\rcarriage\rinside\n", b"\xff\xfe bytes\n", b"long" * 50 + b"\n"]
    data = b"".join(pieces[i] for i in rng.integers(0, len(pieces), 200)) + tail
    expected = list(iter(io.BytesIO(data).readline, b""))
    waits = []
    got = list(ChunkedLines(io.BufferedReader(io.BytesIO(data)), before_wait=lambda: waits.append(1), chunk=chunk))
    assert got == expected
    assert len(waits) >= len(data) // chunk  # before every read, the last one (end of input) included


def test_chunked_lines_ready_only_when_a_line_is_at_hand():
    src = ChunkedLines(io.BytesIO(b"1\n2\n3"), chunk=4)
    it = iter(src)
    assert not src.ready()  # nothing read yet: taking a line would read
    assert next(it) == b"1\n" and src.ready()  # "2\n" came with it
    assert next(it) == b"2\n" and not src.ready()  # "3" is unfinished: more must be read
    assert next(it) == b"3" and src.ready()  # the input ended
    assert list(it) == []
    with pytest.raises(ValueError, match="chunk"):
        ChunkedLines(io.BytesIO(b""), chunk=0)


def test_stdin_stream_equals_batch(tmp_path, monkeypatch, capsys):
    text = _jsonl(_records(200))
    model = tmp_path / "model.toml"
    model.write_text(MODEL.format(backend="numpy", q=0.01))
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(text.encode())))
    assert main(["track", "-", "--config", str(model)]) == 0
    live = capsys.readouterr().out
    data = tmp_path / "data.jsonl"
    data.write_text(text)
    assert main(["track", str(data), "--config", str(model), "--batch"]) == 0
    assert capsys.readouterr().out == live


# --------------------------------------------------------------------------
# the one-run streak against DivergenceMonitor
# --------------------------------------------------------------------------
@pytest.mark.parametrize("seed", range(5))
def test_streak_equals_the_divergence_monitor(seed):
    rng = np.random.default_rng(seed)
    test = DivergenceTest(streak=5)
    mon, streak = DivergenceMonitor((1,), test), tracker_mod._Streak(test)
    K = 400
    dof = rng.choice([0, 1, 2, 3, 70], size=K, p=[0.1, 0.3, 0.4, 0.1, 0.1])
    # NIS around the threshold, so streaks start and break; some NaN (nothing measured) and +inf
    nis = rng.chisquare(np.maximum(dof, 1)) * rng.choice([1.0, 1e3], size=K, p=[0.5, 0.5])
    nis[rng.random(K) < 0.05] = np.nan
    nis[rng.random(K) < 0.02] = np.inf
    mean, cov = np.zeros((1, 2)), np.eye(2)[None]
    got = [streak.update(float(nis[i]), int(dof[i])) for i in range(K)]
    want = [bool(mon.update(nis[i : i + 1], dof[i : i + 1], mean, cov)[0]) for i in range(K)]
    assert got == want
    assert any(want) and not all(want)  # it was flagged during the run, not from the start


@pytest.mark.parametrize("seed", range(5))
def test_streak_of_a_block_equals_step_by_step(seed):
    # update_many (array operations, used per block) against update (one step at a time), over blocks of random
    # sizes, so a streak runs across a block's edge and a block starts flagged
    rng = np.random.default_rng(seed)
    test = DivergenceTest(streak=4)
    one, many = tracker_mod._Streak(test), tracker_mod._Streak(test)
    K = 600
    dof = rng.choice([0, 1, 2, 3], size=K, p=[0.15, 0.3, 0.45, 0.1])
    nis = rng.chisquare(np.maximum(dof, 1)) * rng.choice([1.0, 1e3], size=K, p=[0.6, 0.4])
    nis[rng.random(K) < 0.05] = np.nan
    nis[rng.random(K) < 0.02] = np.inf
    want = [one.update(float(nis[i]), int(dof[i])) for i in range(K)]
    cuts = np.sort(rng.choice(np.arange(1, K), size=40, replace=False)).tolist()
    got = []
    for a, b in zip([0, *cuts], [*cuts, K]):
        got.extend(many.update_many(nis[a:b], dof[a:b].tolist()).tolist())
        assert (many.length, many.flagged) == _streak_after(test, nis[:b], dof[:b])  # the state carried to the next block
    assert got == want
    assert any(want) and not all(want)
    assert many.update_many(np.empty(0), []).tolist() == []


def _streak_after(test, nis, dof):
    s = tracker_mod._Streak(test)
    for a, b in zip(nis.tolist(), dof.tolist()):
        s.update(a, b)
    return s.length, s.flagged


# --------------------------------------------------------------------------
# the benchmark's input
# --------------------------------------------------------------------------
def test_the_stream_benchmark_input_reads_without_a_bad_record(tmp_path):
    import importlib.util
    from pathlib import Path

    from pursuit.io import load_track_model, read_records, track_records

    path = Path(__file__).resolve().parents[2] / "benchmarks" / "bench_stream.py"
    spec = importlib.util.spec_from_file_location("bench_stream", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    inputs = bench.write_inputs(tmp_path, 300)
    model_path = tmp_path / "model.toml"
    model_path.write_text(bench.MODEL.format(backend="numpy"))
    model = load_track_model(model_path)
    results = {}
    for fmt, data in inputs.items():
        with open(data, "rb") as f:
            results[fmt] = track_records(read_records(f, fmt), model)
        assert not results[fmt].problems and len(results[fmt].estimates) == 300
    assert [e.mean.tolist() for e in results["csv"].estimates] == [e.mean.tolist() for e in results["jsonl"].estimates]


# --------------------------------------------------------------------------
# a live input: nothing complete is held back while the input waits
# --------------------------------------------------------------------------
class _PausingInput:
    """Serves ``chunks`` one ``read1`` at a time (a live input that pauses between them).

    At every read it records how many estimates the consumer had received by
    then: what a reader of the output would have seen while the input waited.
    """

    def __init__(self, chunks: list[bytes], emitted: list) -> None:
        self.chunks, self.emitted, self.seen = list(chunks), emitted, []

    def read1(self, n: int) -> bytes:
        self.seen.append(len(self.emitted))
        return self.chunks.pop(0) if self.chunks else b""


@pytest.mark.parametrize("backend", ["numpy", "numba"])
def test_a_live_stream_hands_out_every_complete_step_before_it_waits(tmp_path, backend):
    """Two records of t = 2 arrive last: t = 1 is complete and must come out before the input waits."""
    _backend_available(backend)
    from pursuit.io.model import load_track_model
    from pursuit.io.records import read_records

    model_path = tmp_path / "model.toml"
    model_path.write_text(MODEL.format(backend=backend, q=0.01) + '\n[[sensors]]\nid = "gps2"\ntype = "position"\nsigma = 5.0\n')
    model = load_track_model(model_path)
    emitted: list[float] = []
    src = _PausingInput([b"time,sensor,x,y\n1,gps,1,0.5\n2,gps,2,1\n2,gps2,2,1\n", b"3,gps,3,1.5\n"], emitted)
    lines = ChunkedLines(src)
    records = read_records(lines, "csv", unterminated="reject", layout=model.input)
    for event in tracker_mod.stream_records(records, model, ready=lines.ready):
        emitted.append(event.time)
    assert emitted == [1.0, 2.0, 3.0]
    assert src.seen == [0, 1, 2]  # read 2 waited with t = 1 out; read 3 (the end) with t = 2 out too (t = 3 had come)
