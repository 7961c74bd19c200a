"""``pursuit track`` on the command line: outputs, exit codes, all-or-nothing files, live streams."""

from __future__ import annotations

import io
import json
import os
import subprocess
import sys
import threading
from datetime import datetime, timedelta, timezone
from pathlib import Path

import numpy as np
import pytest

from pursuit.cli import main
from pursuit.io import load_track_model, read_records, track_records

from .conftest import EXAMPLES, ROOT, read_truth

WSN_MODEL = str(EXAMPLES / "wsn-range.toml")
WSN_CSV = str(EXAMPLES / "data" / "wsn-range.csv")
WSN_JSONL = str(EXAMPLES / "data" / "wsn-range.jsonl")


def _stdin(monkeypatch, data: bytes) -> None:
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(data)))


def _api_estimates(model_path=WSN_MODEL, data=WSN_CSV, fmt="csv"):
    with open(data, "rb") as f:
        return track_records(read_records(f, fmt), load_track_model(model_path)).estimates


def test_csv_file_to_stdout_equals_the_api(capsys):
    assert main(["track", WSN_CSV, "--config", WSN_MODEL]) == 0
    out = capsys.readouterr().out.splitlines()
    assert out[0] == "time,x,vx,y,vy,var_x,var_vx,var_y,var_vy,nis,dof,flags"
    rows = [line.split(",") for line in out[1:]]
    est = _api_estimates()
    assert len(rows) == len(est)
    for row, e in zip(rows, est):
        assert float(row[0]) == e.time
        assert [float(v) for v in row[1:5]] == e.mean.tolist()  # repr round-trips exactly
        assert [float(v) for v in row[5:9]] == e.var.tolist()
        assert int(row[10]) == e.dof and row[11] == ";".join(e.flags)


def test_jsonl_output_to_a_file(tmp_path, capsys):
    out = tmp_path / "est.jsonl"
    assert main(["track", WSN_CSV, "-c", WSN_MODEL, "-o", str(out)]) == 0
    assert capsys.readouterr().out == ""
    objs = [json.loads(line) for line in out.read_text().splitlines()]
    est = _api_estimates()
    assert [o["time"] for o in objs] == [e.time for e in est]
    assert list(objs[0]["state"]) == ["x", "vx", "y", "vy"]
    assert [list(o["state"].values()) for o in objs] == [e.mean.tolist() for e in est]
    assert set(objs[0]) == {"time", "state", "var", "nis", "dof", "flags"}


BAD_CSV = "time,sensor,value\n1.0,A1,40\n2.0,A9,50\n3.0,A2,inf\n4.0,A3\n5.0,A1,41\n"


def test_bad_records_exit_2_list_every_problem_and_write_nothing(tmp_path, capsys):
    data = tmp_path / "bad.csv"
    data.write_text(BAD_CSV)
    out = tmp_path / "est.csv"
    out.write_text("previous results\n")
    assert main(["track", str(data), "-c", WSN_MODEL, "-o", str(out)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err[:3] == [
        f"pursuit track: error: {data}:3: sensor: unknown sensor 'A9' (known: A1, A2, A3, A4)",
        f"pursuit track: error: {data}:4: value: 'inf' is not finite (write nan or leave it empty for a missing value)",
        f"pursuit track: error: {data}:5: record: expected at least 3 fields (time, sensor, value), got 2",
    ]
    assert "3 bad records" in err[3] and "nothing written" in err[3]
    assert out.read_text() == "previous results\n"  # untouched
    assert [p.name for p in tmp_path.iterdir() if p.name.startswith(".est")] == []  # no temporary left
    # to standard output: nothing either
    assert main(["track", str(data), "-c", WSN_MODEL]) == 2
    assert capsys.readouterr().out == ""


def test_skip_bad_writes_the_good_records(tmp_path, capsys):
    data = tmp_path / "bad.csv"
    data.write_text(BAD_CSV)
    assert main(["track", str(data), "-c", WSN_MODEL, "--skip-bad"]) == 0
    cap = capsys.readouterr()
    assert [line.split(",")[0] for line in cap.out.splitlines()[1:]] == ["1.0", "5.0"]
    assert cap.err.count("pursuit track: skipped: ") == 3
    assert "skipped 3 bad record(s)" in cap.err


@pytest.mark.parametrize(
    "argv,message",
    [
        (["track", "missing.csv", "-c", WSN_MODEL], "missing.csv: cannot read"),
        (["track", WSN_CSV, "-c", "missing.toml"], "missing.toml: file not found"),
        (["track", str(EXAMPLES / "wsn-range.toml"), "-c", WSN_MODEL], "cannot tell the format"),
        (["track", "-", "-c", WSN_MODEL, "--out-of-order", "sort"], "--out-of-order sort needs the whole input"),
        (["track", WSN_CSV, "-c", WSN_MODEL, "-o", "/nonexistent-dir/x.csv"], "cannot write"),
    ],
)
def test_argument_and_file_problems_exit_2(argv, message, capsys, monkeypatch):
    _stdin(monkeypatch, b"")
    assert main(argv) == 2
    assert message in capsys.readouterr().err


def test_a_bad_model_file_exits_2_naming_line_and_field(tmp_path, capsys):
    bad = tmp_path / "m.toml"
    bad.write_text(Path(WSN_MODEL).read_text().replace("sigma = 1.0          # m", "sigma = -1.0"))
    assert main(["track", WSN_CSV, "-c", str(bad)]) == 2
    assert f"{bad}:15: sensors[0].sigma: noise standard deviations must be positive" in capsys.readouterr().err


@pytest.mark.parametrize(
    "old,new,message",
    [
        ("sigma = 1.0          # m", "sigma = 1e200", ":15: sensors[0].sigma: 1e+200 is outside [2^-537, 2^500]"),
        ("sigma = 1.0          # m", "sigma = 1e-300", ":15: sensors[0].sigma: 1e-300 is outside [2^-537, 2^500]"),
        ("q = 0.01 ", "q = 1e308 ", ":8: motion.q: the process noise of one 1 s step is too large"),
        ("mean = [10.0,", "mean = [1e308,", ": prior.mean: 1e+308 is beyond ±2^500"),
        ("cov = [4.0, 0.25, 4.0, 0.25]", "cov = 1e20", ": prior.cov: too large for the measurement noise"),
        ('type = "ekf"', 'type = "ekf"\nfading = 1e300', ": filter.fading: 1e+300 is beyond 2^13"),
    ],
)
def test_a_model_file_value_too_large_or_small_for_float64_is_a_bad_model_file_not_bad_records(tmp_path, capsys, old, new, message):
    # These used to pass the loader and then reject every record ("199 bad records"), or with a prior
    # covariance of 1e20 write estimates with a negative NIS.
    bad = tmp_path / "m.toml"
    text = Path(WSN_MODEL).read_text()
    assert old in text
    bad.write_text(text.replace(old, new, 1))
    out = tmp_path / "est.csv"
    assert main(["track", WSN_CSV, "-c", str(bad), "-o", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"pursuit: error: {bad}:") and message in err and len(err.splitlines()) == 1
    assert "bad records" not in err and "Traceback" not in err and not out.exists()


def test_stdin_is_a_stream_with_jsonl_by_default(capsys, monkeypatch):
    _stdin(monkeypatch, Path(WSN_JSONL).read_bytes())
    assert main(["track", "-", "-c", WSN_MODEL]) == 0
    objs = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [list(o["state"].values()) for o in objs] == [e.mean.tolist() for e in _api_estimates()]


def test_a_bad_record_mid_stream_stops_after_the_estimates_before_it(capsys, monkeypatch):
    lines = Path(WSN_JSONL).read_text().splitlines()
    lines.insert(10, '{"time": 4.0, "sensor": "A1", "value": "far"}')
    _stdin(monkeypatch, ("\n".join(lines) + "\n").encode())
    assert main(["track", "-", "-c", WSN_MODEL]) == 2
    cap = capsys.readouterr()
    times = [json.loads(line)["time"] for line in cap.out.splitlines()]
    before = sorted({json.loads(line)["time"] for line in lines[:10]})
    assert times == before  # every step before the bad record, including the one it interrupted
    assert "<stdin>:11: value: expected a number" in cap.err
    assert f"after {len(before)} estimates" in cap.err
    _stdin(monkeypatch, ("\n".join(lines) + "\n").encode())
    assert main(["track", "-", "-c", WSN_MODEL, "--skip-bad"]) == 0
    assert len(capsys.readouterr().out.splitlines()) == len(_api_estimates())


def test_stream_to_csv_file(tmp_path, monkeypatch):
    _stdin(monkeypatch, Path(WSN_JSONL).read_bytes())
    out = tmp_path / "est.csv"
    assert main(["track", "-", "-c", WSN_MODEL, "-o", str(out)]) == 0
    assert len(out.read_text().splitlines()) == 1 + len(_api_estimates())


def _reader(stream, lines):
    for line in iter(stream.readline, ""):
        lines.append(line)


def _terminal_sigint() -> None:
    """In the child: SIGINT as a terminal's Ctrl-C finds it (default action, not blocked).

    A child inherits its parent's signal mask and ignored signals; under a test runner started in
    the background (or from a thread that blocks SIGINT) the stream would never see the signal.
    """
    import signal

    signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _start_stream():
    """A real ``pursuit track -`` process and the list its output lines are appended to."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "pursuit.cli", "track", "-", "-c", WSN_MODEL],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=ROOT,
        preexec_fn=_terminal_sigint,
    )
    lines: list[str] = []
    reader = threading.Thread(target=_reader, args=(proc.stdout, lines), daemon=True)
    reader.start()
    return proc, lines, reader


def test_a_live_stream_gets_each_estimate_as_soon_as_its_step_is_complete():
    # A real process: records go in one at a time, and the estimate for time t comes out
    # once a record with a later time arrives, before standard input is closed.
    proc, lines, reader = _start_stream()

    def send(obj):
        proc.stdin.write(json.dumps(obj) + "\n")
        proc.stdin.flush()

    def wait_for(n, timeout=60.0):
        import time

        end = time.monotonic() + timeout
        while len(lines) < n and time.monotonic() < end and proc.poll() is None:
            time.sleep(0.02)
        return len(lines)

    try:
        send({"time": 1.0, "sensor": "A1", "value": 41.5})
        send({"time": 1.0, "sensor": "A2", "value": 98.3})
        send({"time": 2.0, "sensor": "A1", "value": 42.0})
        assert wait_for(1) == 1, proc.stderr.read() if proc.poll() is not None else "no estimate"
        first = json.loads(lines[0])
        assert first["time"] == 1.0 and first["dof"] == 2
        send({"time": 3.0})  # a time-only record closes step 2 and asks for a prediction at 3
        assert wait_for(2) == 2
        assert json.loads(lines[1])["time"] == 2.0
    finally:
        proc.stdin.close()
        proc.wait(timeout=60)
    reader.join(timeout=10)
    assert proc.returncode == 0
    assert [json.loads(line)["time"] for line in lines] == [1.0, 2.0, 3.0]
    assert json.loads(lines[2])["flags"] == ["predict"]


def test_ctrl_c_ends_a_live_stream_cleanly():
    import signal
    import time

    proc, lines, reader = _start_stream()
    for obj in ({"time": 1.0, "sensor": "A1", "value": 41.5}, {"time": 2.0, "sensor": "A1", "value": 42.0}):
        proc.stdin.write(json.dumps(obj) + "\n")
    proc.stdin.flush()
    end = time.monotonic() + 60
    while not lines and time.monotonic() < end and proc.poll() is None:
        time.sleep(0.02)
    proc.send_signal(signal.SIGINT)
    proc.wait(timeout=60)
    reader.join(timeout=10)
    err = proc.stderr.read()
    proc.stdin.close()
    assert proc.returncode == 130
    assert "Traceback" not in err and "interrupted" in err
    assert [json.loads(line)["time"] for line in lines] == [1.0]


def test_a_particle_filter_whose_weights_all_underflow_recovers_and_says_so(tmp_path, capsys):
    # Sensor A1 claims a noise of 1e-160 m: every particle's likelihood underflows to zero
    # whenever A1 reports.  The particle filter's recovery rule (issue 3) keeps the predictive
    # weights; pursuit track writes finite estimates and flags those steps weights_reset.
    text = Path(WSN_MODEL).read_text().replace("sigma = 1.0          # m", "sigma = 1e-160")
    text = text.replace('type = "ekf"', 'type = "pf"\nparticles = 300') + "\n[track]\nseed = 3\n"
    model = tmp_path / "pf.toml"
    model.write_text(text)
    assert main(["track", WSN_CSV, "-c", str(model)]) == 0
    rows = [line.split(",") for line in capsys.readouterr().out.splitlines()[1:]]
    with open(WSN_CSV) as f:
        a1_times = {float(line.split(",")[0]) for line in f if ",A1," in line}
    assert len(rows) == len(_api_estimates())
    for row in rows:
        assert all(np.isfinite(float(v)) for v in row[:9])
        assert ("weights_reset" in row[11].split(";")) == (float(row[0]) in a1_times)


@pytest.mark.parametrize("text", ["", "# no records yet\n\n"])
def test_an_empty_csv_file_is_an_error_and_nothing_is_written(tmp_path, capsys, text):
    data = tmp_path / "empty.csv"
    data.write_text(text)
    out = tmp_path / "est.csv"
    assert main(["track", str(data), "-c", WSN_MODEL, "-o", str(out)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith(f"pursuit track: error: {data}:") and ": header: missing: the input " in err[0]
    assert "nothing written" in err[1]
    assert not out.exists()


def test_time_and_value_infinities_are_reported_alike(tmp_path, capsys):
    data = tmp_path / "inf.csv"
    data.write_text("time,sensor,value\ninf,A1,40\n2.0,A1,inf\n")
    assert main(["track", str(data), "-c", WSN_MODEL]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err[:2] == [
        f"pursuit track: error: {data}:2: time: 'inf' is not finite (a time must be a finite number of seconds)",
        f"pursuit track: error: {data}:3: value: 'inf' is not finite (write nan or leave it empty for a missing value)",
    ]


def test_a_huge_gap_names_the_time_field(tmp_path, capsys):
    data = tmp_path / "gap.csv"
    data.write_text("time,sensor,value\n1.0,A1,40\n1e300,A1,41\n")
    assert main(["track", str(data), "-c", WSN_MODEL]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith(f"pursuit track: error: {data}:3: time: 1e+300 is 1e+300 s after time 1.0 (line 2), more than the largest gap")
    # without a max_gap the filter's own guard refuses it
    model = tmp_path / "unlimited.toml"
    model.write_text(Path(WSN_MODEL).read_text() + "\n[input]\nmax_gap = inf\n")
    assert main(["track", str(data), "-c", str(model)]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err[0] == (
        f"pursuit track: error: {data}:3: time: rejected at time 1e+300: 1e+300 s after the previous step at 1.0 "
        "is a gap the filter cannot predict across (the filter failed: ValueError: step 2: dt: 1e+300 s is beyond 2^200 ≈ 1.61e+60 s, "
        "the longest step whose fifth power (the motion models' process noise) float64 holds)"
    )
    assert "Numerical result out of range" not in "\n".join(err)


@pytest.mark.parametrize("skip_bad", [False, True])
@pytest.mark.parametrize("body", ["", "# a comment\n\n", "1.0,nosuchsensor,3.0\n"])
def test_a_csv_with_nothing_to_track_is_an_error_and_nothing_is_written(tmp_path, capsys, body, skip_bad):
    data = tmp_path / "header-only.csv"
    data.write_text("time,sensor,value\n" + body)
    out = tmp_path / "est.csv"
    argv = ["track", str(data), "-c", WSN_MODEL, "-o", str(out)] + (["--skip-bad"] if skip_bad else [])
    assert main(argv) == 2
    err = capsys.readouterr().err.splitlines()
    assert not out.exists()
    if body.startswith("1.0") and not skip_bad:  # the bad record itself is the error
        assert "bad record" in err[-1]
    else:
        assert err[-1].startswith(f"pursuit track: error: {data}: nothing to track: ") and err[-1].endswith("nothing written")


def test_a_stream_with_nothing_to_track_exits_2(capsys, monkeypatch):
    _stdin(monkeypatch, b"")
    assert main(["track", "-", "-c", WSN_MODEL]) == 2
    err = capsys.readouterr().err.splitlines()
    assert err[-1] == "pursuit track: error: <stdin>: nothing to track: it held no measurement records"


@pytest.mark.parametrize("how", ["same", "symlink", "hardlink"])
@pytest.mark.parametrize("stream", [False, True])
def test_an_output_that_is_the_input_is_refused_and_the_input_kept(tmp_path, capsys, how, stream):
    data = tmp_path / "data.csv"
    data.write_bytes(Path(WSN_CSV).read_bytes())
    out = data
    if how == "symlink":
        out = tmp_path / "out.csv"
        out.symlink_to(data)
    elif how == "hardlink":
        out = tmp_path / "out.csv"
        os.link(data, out)
    argv = ["track", str(data), "-c", WSN_MODEL, "-o", str(out)] + (["--stream"] if stream else [])
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert f"{out}: the output is the input file {data}; choose another output" in err
    assert data.read_bytes() == Path(WSN_CSV).read_bytes()


def test_stdin_redirected_from_the_output_file_is_refused(tmp_path, capsys, monkeypatch):
    data = tmp_path / "data.jsonl"
    data.write_bytes(Path(WSN_JSONL).read_bytes())
    with open(data, "rb") as fh:
        monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(fh))
        assert main(["track", "-", "-c", WSN_MODEL, "-o", str(data)]) == 2
    assert "the output is the input file <stdin>" in capsys.readouterr().err
    assert data.read_bytes() == Path(WSN_JSONL).read_bytes()


def test_the_batch_output_keeps_the_mode_of_the_file_it_replaces_and_writes_through_a_link(tmp_path, capsys):
    target = tmp_path / "estimates.csv"
    target.write_text("old\n")
    target.chmod(0o640)
    link = tmp_path / "latest.csv"
    link.symlink_to(target)
    assert main(["track", WSN_CSV, "-c", WSN_MODEL, "-o", str(link)]) == 0
    assert link.is_symlink()
    assert target.read_text().startswith("time,") and (target.stat().st_mode & 0o777) == 0o640


def test_a_stream_cut_off_inside_its_last_record_reports_it_instead_of_reading_a_shorter_number(capsys, monkeypatch):
    lines = Path(WSN_CSV).read_bytes().splitlines(keepends=True)
    cut = lines[6].rstrip(b"\n")[:-3]  # the last record, cut inside its value ("41.53" read as "41.5"), no newline
    assert cut.count(b",") == 2 and cut[-1:].isdigit()  # still a well-formed CSV record
    _stdin(monkeypatch, b"".join(lines[:6]) + cut)
    assert main(["track", "-", "-c", WSN_MODEL, "--format", "csv"]) == 2
    err = capsys.readouterr().err
    assert "<stdin>:7: record: incomplete: the input ended inside this record" in err


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="no /dev/full")
@pytest.mark.parametrize("stream", [False, True])
@pytest.mark.parametrize("to_stdout", [False, True])
def test_an_output_that_cannot_be_written_is_one_line_and_exit_2(stream, to_stdout):
    # a subprocess, so that standard output really is /dev/full
    argv = [sys.executable, "-m", "pursuit", "track", WSN_CSV, "-c", WSN_MODEL] + (["--stream"] if stream else [])
    with open("/dev/full", "w") as full:
        done = subprocess.run(argv + ([] if to_stdout else ["-o", "/dev/full"]), stdout=full if to_stdout else None,
                              stderr=subprocess.PIPE, text=True, timeout=120)
    where = "standard output" if to_stdout else "/dev/full"
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [f"pursuit track: error: {where}: cannot write: No space left on device"]


# --------------------------------------------------------------------------
# a corrupt time in a stream; real-data inputs (issues 16 and 17)
# --------------------------------------------------------------------------
def test_one_absurd_time_in_a_live_stream_is_a_bad_record_and_the_stream_goes_on(capsys, monkeypatch):
    lines = Path(WSN_JSONL).read_text().splitlines(keepends=True)
    spoiled = json.loads(lines[9])
    spoiled["time"] = 1e15
    data = "".join(lines[:9] + [json.dumps(spoiled) + "\n"] + lines[10:]).encode()
    _stdin(monkeypatch, data)
    assert main(["track", "-", "-c", WSN_MODEL, "--skip-bad"]) == 0
    cap = capsys.readouterr()
    assert cap.err.splitlines() == [
        "pursuit track: skipped: <stdin>:10: time: 1000000000000000.0 is 1e+15 s after time 4.0 (line 8), more than "
        "the largest gap the model predicts across (input.max_gap = 141421 s): a corrupt time?",
        "pursuit track: skipped 1 bad record(s) in <stdin>",
    ]
    _stdin(monkeypatch, "".join(lines[:9] + lines[10:]).encode())
    assert main(["track", "-", "-c", WSN_MODEL]) == 0
    assert cap.out == capsys.readouterr().out  # the estimates of the stream without the bad line
    _stdin(monkeypatch, data)  # without --skip-bad: a bad record stops a stream, as any other
    assert main(["track", "-", "-c", WSN_MODEL]) == 2
    assert "<stdin>:10: time: 1000000000000000.0 is 1e+15 s after" in capsys.readouterr().err


@pytest.mark.parametrize("extra", [[], ["--skip-bad"], ["--stream"], ["--stream", "--skip-bad"]])
def test_the_truth_file_gives_one_header_error_not_one_per_row(tmp_path, capsys, extra):
    out = tmp_path / "est.csv"
    argv = ["track", str(EXAMPLES / "data" / "wsn-range-truth.csv"), "-c", WSN_MODEL, "-o", str(out)] + extra
    assert main(argv) == 2
    err = capsys.readouterr().err.splitlines()
    assert len(err) == 2, err
    assert err[0].startswith(
        f"pursuit track: error: {EXAMPLES / 'data' / 'wsn-range-truth.csv'}:1: header: expected the columns "
        "time,sensor and the value column(s) (value, or one per component such as x,y); found 'time,x,vx,y,vy' (missing sensor)"
    )
    assert err[1].startswith("pursuit track: error: ") and "no usable header, so no record was read" in err[1]
    assert out.exists() == ("--stream" in extra)  # a stream has written its header line only


GPS_MODEL = """
[motion]
type = "cv"
q = 0.01
[[sensors]]
id = "gps"
type = "position"
sigma = 2.0
[prior]
time = 0.0
mean = [10.0, 0.5, 40.0, 0.8]
cov = [4.0, 0.25, 4.0, 0.25]
[filter]
type = "kf"
"""


def _gps_rows(n=20):
    t, states = read_truth_file()
    rng = np.random.default_rng(3)
    xy = states[:n, [0, 2]] + rng.normal(0.0, 2.0, (n, 2))
    return t[:n].tolist(), xy.tolist()  # Python floats: repr writes them as plain numbers


def read_truth_file():
    return read_truth(EXAMPLES / "data" / "wsn-range-truth.csv")


def _track(tmp_path, capsys, model_text, data_text, name):
    model, data = tmp_path / f"{name}.toml", tmp_path / f"{name}.csv"
    model.write_text(model_text)
    data.write_text(data_text)
    code = main(["track", str(data), "-c", str(model)])
    cap = capsys.readouterr()
    assert code == 0, cap.err
    assert cap.err == ""
    return cap.out


def test_a_time_sensor_x_y_file_wide_columns_and_iso_times_all_give_the_same_estimates(tmp_path, capsys):
    t, xy = _gps_rows()
    long = "time,sensor,value\n" + "".join(f"{a!r},gps,{x!r},{y!r}\n" for a, (x, y) in zip(t, xy))
    ref = _track(tmp_path, capsys, GPS_MODEL, long, "long")
    assert len(ref.splitlines()) == len(t) + 1
    # time,sensor,x,y: no option needed
    named = "time,sensor,x,y\n" + long.split("\n", 1)[1]
    assert _track(tmp_path, capsys, GPS_MODEL, named, "named") == ref
    # a wide file with renamed columns (and one the model does not use)
    wide_model = GPS_MODEL + '[input]\ntime_column = "t"\ncolumns = {gps = ["east", "north"]}\n'
    wide = "north,t,hdop,east\n" + "".join(f"{y!r},{a!r},0.9,{x!r}\n" for a, (x, y) in zip(t, xy))
    assert _track(tmp_path, capsys, wide_model, wide, "wide") == ref
    # ISO 8601 times, counted from the model's time origin
    iso_model = GPS_MODEL + "[input]\ntime_origin = 2026-07-01T12:00:00+02:00\n"
    start = datetime(2026, 7, 1, 10, tzinfo=timezone.utc)
    iso = "time,sensor,x,y\n" + "".join(
        f"{(start + timedelta(seconds=float(a))).isoformat().replace('+00:00', 'Z')},gps,{x!r},{y!r}\n" for a, (x, y) in zip(t, xy)
    )
    assert all(a == round(a) for a in t)  # whole seconds: the ISO text is exact
    assert _track(tmp_path, capsys, iso_model, iso, "iso") == ref


def test_iso_times_from_the_epoch_with_a_prior_at_zero_name_the_gap(tmp_path, capsys):
    # the prior at t = 0 is 1970: the first record is decades after it, an error that names max_gap
    model, data = tmp_path / "m.toml", tmp_path / "d.csv"
    model.write_text(GPS_MODEL)
    data.write_text("time,sensor,x,y\n2026-07-01T00:00:00Z,gps,10,40\n")
    assert main(["track", str(data), "-c", str(model)]) == 2
    err = capsys.readouterr().err
    assert f"{data}:2: time: 1782864000.0 is 1.78286e+09 s after the prior's time 0.0, more than the largest gap" in err
    assert "input.max_gap" in err
