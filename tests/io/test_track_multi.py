"""``pursuit track --multi``: detection files tracked by GNN/JPDA, batch and stream, bad input, and ``track_stream``.

The detections come from a seeded ``crossing()`` simulation (two targets,
P_D = 0.9, 5 false alarms per scan) written to CSV and JSON Lines.  The
references are exact: the command's rows must be those of
:func:`pursuit.multitarget.track_scans` on the same detections, bit for bit
(numbers are written with ``repr``), and the stream those of the batch.
"""

from __future__ import annotations

import io
import json
import sys
from pathlib import Path

import numpy as np
import pytest

import pursuit as pu
from pursuit.cli import main
from pursuit.io.detections import read_detections
from pursuit.io.multi_model import load_multi_model
from pursuit.multitarget import GNNTracker, JPDATracker, track_scans, track_stream
from pursuit.scenarios.multitarget import crossing

MODEL = """\
[motion]
type = "cv"
ndim = 2
q = 0.005
noise = "continuous"

[[sensors]]
id = "radar"
type = "position"
sigma = {sigma!r}

[tracker]
type = "{kind}"
filter = {{type = "kf"}}
p_detect = 0.9
clutter_density = {density!r}
max_speed = 5.0
"""

SCENARIO = crossing()
TRACKERS = {"gnn": GNNTracker, "jpda": JPDATracker}


def _model_text(kind: str) -> str:
    return MODEL.format(kind=kind, sigma=float(np.sqrt(0.75)), density=SCENARIO.clutter_density)


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    """A seeded crossing run as det.csv and det.jsonl (an empty scan written as a time alone), and the two model files."""
    root = tmp_path_factory.mktemp("multi")
    _, scans = SCENARIO.simulate(np.random.default_rng(3), runs=1)
    csv, jsonl = ["time,sensor,x,y"], []
    for k, t in enumerate(scans.times.tolist()):
        rows = scans.per_run(k, 0)
        if not len(rows):
            csv.append(f"{t!r},radar,,")
            jsonl.append(json.dumps({"time": t}))
        for x, y in rows.tolist():
            csv.append(f"{t!r},radar,{x!r},{y!r}")
            jsonl.append(json.dumps({"time": t, "sensor": "radar", "x": x, "y": y}))
    out = {"csv": root / "det.csv", "jsonl": root / "det.jsonl"}
    out["csv"].write_text("\n".join(csv) + "\n")
    out["jsonl"].write_text("\n".join(jsonl) + "\n")
    for kind in TRACKERS:
        out[kind] = root / f"{kind}.toml"
        out[kind].write_text(_model_text(kind))
    return out


def _rows(text: str) -> list[list[str]]:
    lines = text.splitlines()
    assert lines[0] == "time,label,x,vx,y,vy,var_x,var_vx,var_y,var_vy"
    return [line.split(",") for line in lines[1:]]


def _expected(tracker, det: Path) -> list[list[float]]:
    """(time, label, state, variances) of every confirmed track per scan from track_scans, in label order."""
    scans = read_detections(det, ["x", "y"])
    res = track_scans(tracker, scans.z, times=scans.times)
    out = []
    for k, t in enumerate(scans.times.tolist()):
        slots = np.nonzero(res.confirmed[k, 0])[0]
        for s in slots[np.argsort(res.label[k, 0, slots])]:
            out.append([t, int(res.label[k, 0, s]), *res.mean[k, 0, s].tolist(), *np.diag(res.cov[k, 0, s]).tolist()])
    return out


# --------------------------------------------------------------------------
# batch output = track_scans
# --------------------------------------------------------------------------
@pytest.mark.parametrize("kind", list(TRACKERS))
def test_batch_rows_equal_track_scans_with_a_tracker_built_in_python(kind, files, tmp_path, capsys):
    out = tmp_path / "tracks.csv"
    assert main(["track", "--multi", str(files["csv"]), "-c", str(files[kind]), "-o", str(out)]) == 0
    assert capsys.readouterr().out == ""
    got = [[float(r[0]), int(r[1]), *map(float, r[2:])] for r in _rows(out.read_text())]
    # The same tracker made by hand from the scenario's own models: the model file builds exactly it.
    tracker = TRACKERS[kind](
        pu.KalmanFilter(SCENARIO.motion, SCENARIO.measurement), 0.9, SCENARIO.clutter_density, max_speed=5.0
    )
    want = _expected(tracker, files["csv"])
    assert got == want  # repr round-trips: bit for bit
    assert len({r[1] for r in got}) >= 2  # both crossing targets are tracked: the comparison is not vacuous
    assert len(got) >= 25


@pytest.mark.parametrize("kind", list(TRACKERS))
def test_jsonl_input_and_output_carry_the_same_tracks_as_csv(kind, files, tmp_path):
    csv_out, jsonl_out = tmp_path / "t.csv", tmp_path / "t.jsonl"
    assert main(["track", "--multi", str(files["csv"]), "-c", str(files[kind]), "-o", str(csv_out)]) == 0
    assert main(["track", "--multi", str(files["jsonl"]), "-c", str(files[kind]), "-o", str(jsonl_out)]) == 0
    rows = _rows(csv_out.read_text())
    objs = [json.loads(line) for line in jsonl_out.read_text().splitlines()]
    assert len(objs) == len(rows)
    for obj, row in zip(objs, rows):
        assert set(obj) == {"time", "label", "state", "var"}
        assert list(obj["state"]) == ["x", "vx", "y", "vy"]
        assert [obj["time"], obj["label"]] == [float(row[0]), int(row[1])]
        assert list(obj["state"].values()) == [float(v) for v in row[2:6]]
        assert list(obj["var"].values()) == [float(v) for v in row[6:10]]


def test_no_var_leaves_the_covariance_out(files, capsys):
    assert main(["track", "--multi", str(files["csv"]), "-c", str(files["gnn"]), "--no-var"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert lines[0] == "time,label,x,vx,y,vy"
    assert all(len(line.split(",")) == 6 for line in lines[1:])


# --------------------------------------------------------------------------
# stream = batch
# --------------------------------------------------------------------------
@pytest.mark.parametrize("kind", list(TRACKERS))
@pytest.mark.parametrize("fmt", ["csv", "jsonl"])
def test_stream_writes_the_bytes_of_batch(kind, fmt, files, tmp_path):
    batch, stream = tmp_path / "batch.csv", tmp_path / "stream.csv"
    assert main(["track", "--multi", str(files[fmt]), "-c", str(files[kind]), "-o", str(batch)]) == 0
    assert main(["track", "--multi", str(files[fmt]), "-c", str(files[kind]), "-o", str(stream), "--stream"]) == 0
    assert stream.read_bytes() == batch.read_bytes()


def test_standard_input_is_a_stream(files, tmp_path, capsys, monkeypatch):
    batch = tmp_path / "batch.jsonl"
    assert main(["track", "--multi", str(files["jsonl"]), "-c", str(files["gnn"]), "-o", str(batch)]) == 0
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(files["jsonl"].read_bytes())))
    assert main(["track", "--multi", "-", "-c", str(files["gnn"]), "--to", "jsonl"]) == 0
    assert capsys.readouterr().out == batch.read_text()


@pytest.mark.parametrize("cls", list(TRACKERS.values()))
def test_track_stream_equals_track_scans_bit_for_bit_and_reads_one_scan_at_a_time(cls):
    """Several runs, and the stream's scans padded differently (3 more NaN rows): the same bits."""
    _, scans = SCENARIO.simulate(np.random.default_rng(5), runs=4)
    tracker = cls(pu.KalmanFilter(SCENARIO.motion, SCENARIO.measurement), 0.9, SCENARIO.clutter_density, max_speed=5.0)
    whole = track_scans(tracker, scans.z, times=scans.times)
    pulled = []

    def feed():
        for k, t in enumerate(scans.times.tolist()):
            pulled.append(k)
            yield t, np.concatenate([scans.z[k], np.full((scans.runs, 3, 2), np.nan)], axis=1)

    for k, tracks in enumerate(track_stream(tracker, feed())):
        assert len(pulled) == k + 1  # lazily: scan k+1 is read only after scan k's tracks were taken
        assert tracks.time == scans.times[k]
        for name in ("mean", "cov", "label", "confirmed", "dropped"):
            assert np.array_equal(getattr(tracks, name), getattr(whole, name)[k], equal_nan=True), name
    assert whole.confirmed.sum() > 100


def test_track_stream_refuses_bad_scans_naming_the_field():
    tracker = GNNTracker(pu.KalmanFilter(SCENARIO.motion, SCENARIO.measurement), 0.9, 0.01, max_speed=5.0)
    z = np.zeros((1, 1, 2))
    with pytest.raises(ValueError, match="time: scan 2 at 1.0 is not after the previous scan's time 1.0"):
        list(track_stream(tracker, [(1.0, z), (1.0, z)]))
    with pytest.raises(ValueError, match="z: scan 2: expected 1 runs of 2-component detections"):
        list(track_stream(tracker, [(1.0, z), (2.0, np.zeros((1, 1, 3)))]))
    with pytest.raises(ValueError, match="z: scan 1: a detection row must be all finite or all NaN"):
        list(track_stream(tracker, [(1.0, np.array([[[1.0, np.nan]]]))]))
    assert list(track_stream(tracker, [])) == []


# --------------------------------------------------------------------------
# bad detections: one line naming file, line and field; exit 2; no file
# --------------------------------------------------------------------------
def _detections(tmp_path: Path, name: str, text: str) -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


GOOD = "time,sensor,x,y\n1.0,radar,0.0,0.0\n"  # the bad record comes before this first scan is complete
BAD_DETECTIONS = [
    ("malformed.csv", GOOD + "1.0,radar,2.0\n", 3, "record", "expected 4 fields"),
    ("nan.csv", GOOD + "1.0,radar,nan,2.0\n", 3, "x", "NaN is not a detection"),
    ("half.csv", GOOD + "1.0,radar,2.0,\n", 3, "y", "missing"),
    ("column.csv", "time,sensor,x\n1.0,radar,0.0\n", 1, "header", "missing y"),
    ("backwards.csv", GOOD + "0.5,radar,2.0,2.0\n", 3, "time", "out of order"),
    ("sensor.csv", GOOD + "1.0,sonar,2.0,2.0\n", 3, "sensor", "unknown sensor 'sonar'"),
    ("word.jsonl", '{"time": 1.0, "x": 0.0, "y": 0.0}\n{"time": 1.0, "x": "a", "y": 0.0}\n', 2, "x", "expected a number"),
    ("key.jsonl", '{"time": 1.0, "x": 0.0, "y": 0.0, "z": 1.0}\n', 1, "z", "unknown key"),
    ("gap.csv", GOOD + "1e12,radar,2.0,2.0\n", 3, "time", "beyond input.max_gap"),
]


@pytest.mark.parametrize("stream", [False, True], ids=["batch", "stream"])
@pytest.mark.parametrize("name, text, line, field, message", BAD_DETECTIONS, ids=[b[0] for b in BAD_DETECTIONS])
def test_a_bad_detection_file_exits_2_naming_file_line_field_and_writes_nothing(
    name, text, line, field, message, stream, files, tmp_path, capsys
):
    det = _detections(tmp_path, name, text)
    out = tmp_path / "tracks.csv"
    argv = ["track", "--multi", str(det), "-c", str(files["gnn"]), "-o", str(out)] + (["--stream"] if stream else [])
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert f"{det}:{line}: {field}: " in err and message in err
    assert err.splitlines()[0].startswith(f"pursuit track: error: {det}:{line}: {field}: ")
    if not stream and field != "header":  # (a header that does not fit adds "no usable header ...; nothing written")
        assert len(err.splitlines()) == 1  # one bad record, one line
    # not even a stream has begun its file: the bad record came before its first scan was complete
    assert [p.name for p in tmp_path.iterdir()] == [name]


def test_a_bad_record_keeps_an_existing_output_whole(files, tmp_path, capsys):
    out = tmp_path / "tracks.csv"
    out.write_text("old\n")
    det = _detections(tmp_path, "nan.csv", GOOD + "2.0,radar,1.0,1.0\n3.0,radar,nan,2.0\n")
    assert main(["track", "--multi", str(det), "-c", str(files["gnn"]), "-o", str(out)]) == 2
    assert out.read_text() == "old\n"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["nan.csv", "tracks.csv"]  # no temporary file left


def test_skip_bad_skips_and_tracks_the_rest(files, tmp_path, capsys):
    text = files["csv"].read_text().splitlines()
    text.insert(5, "3.0,radar,nan,1.0")
    det = _detections(tmp_path, "skip.csv", "\n".join(text) + "\n")
    ref, out = tmp_path / "ref.csv", tmp_path / "out.csv"
    assert main(["track", "--multi", str(files["csv"]), "-c", str(files["gnn"]), "-o", str(ref)]) == 0
    assert main(["track", "--multi", str(det), "-c", str(files["gnn"]), "-o", str(out), "--skip-bad"]) == 0
    err = capsys.readouterr().err
    assert f"pursuit track: skipped: {det}:6: x: NaN" in err
    assert out.read_bytes() == ref.read_bytes()


def test_a_stream_stops_at_a_late_bad_record_keeping_the_scans_before_it(files, tmp_path, capsys):
    lines = files["csv"].read_text().splitlines()
    cut = next(i for i, line in enumerate(lines) if line.startswith("10.0,"))
    det = _detections(tmp_path, "late.csv", "\n".join([*lines[:cut], "10.0,radar,x,1.0", *lines[cut:]]) + "\n")
    batch, stream = tmp_path / "batch.csv", tmp_path / "stream.csv"
    assert main(["track", "--multi", str(files["csv"]), "-c", str(files["gnn"]), "-o", str(batch)]) == 0
    assert main(["track", "--multi", str(det), "-c", str(files["gnn"]), "-o", str(stream), "--stream"]) == 2
    assert f"{det}:{cut + 1}: x: not a number" in capsys.readouterr().err
    # scan 9 was still being assembled when the bad record came (its end shows only when a later time arrives)
    before = [line for line in batch.read_text().splitlines() if line.startswith("time") or float(line.split(",")[0]) < 9.0]
    assert len(before) > 5
    assert stream.read_text().splitlines() == before
    assert main(["track", "--multi", str(det), "-c", str(files["gnn"]), "-o", str(tmp_path / "b.csv")]) == 2
    assert not (tmp_path / "b.csv").exists()


def test_an_empty_file_is_nothing_to_track_and_no_track_is_not_an_error(files, tmp_path, capsys):
    empty = _detections(tmp_path, "empty.csv", "time,sensor,x,y\n")
    assert main(["track", "--multi", str(empty), "-c", str(files["gnn"]), "-o", str(tmp_path / "o.csv")]) == 2
    assert "nothing to track: it holds no detection records" in capsys.readouterr().err
    assert not (tmp_path / "o.csv").exists()
    one = _detections(tmp_path, "one.csv", "time,x,y\n1.0,5.0,5.0\n2.0,,\n")
    assert main(["track", "--multi", str(one), "-c", str(files["gnn"]), "-o", str(tmp_path / "o.csv")]) == 0
    assert (tmp_path / "o.csv").read_text() == "time,label,x,vx,y,vy,var_x,var_vx,var_y,var_vy\n"
    assert "no track was confirmed in 2 scans" in capsys.readouterr().err


# --------------------------------------------------------------------------
# bad model files and arguments
# --------------------------------------------------------------------------
BAD_MODELS = [
    ("unknown-key", ("max_speed = 5.0\n", "max_speed = 5.0\nspeed = 3.0\n"), "tracker.speed", "unknown key"),
    ("gate", ("max_speed = 5.0\n", "max_speed = 5.0\ngate = 1.5\n"), "tracker.gate", "must lie in"),
    ("p-detect", ("p_detect = 0.9", "p_detect = 0.0"), "tracker.p_detect", "must lie in (0, 1]"),
    ("clutter", ("clutter_density = ", "clutter_density = -"), "tracker.clutter_density", "must be positive"),
    ("no-clutter", ("clutter_density = ", "# clutter_density = "), "tracker.p_detect", None),
    ("confirm", ("max_speed = 5.0\n", "max_speed = 5.0\nconfirm = [3, 2]\n"), "tracker.confirm", "M must not exceed N"),
    ("type", ('type = "gnn"', 'type = "mht"'), "tracker.type", "mht"),
    ("pmht", ('type = "gnn"', 'type = "pmht"'), "tracker.type", "runs gnn or jpda, got 'pmht'"),
    ("gmphd", ('type = "gnn"', 'type = "gmphd"'), "tracker.type", "runs gnn or jpda, got 'gmphd'"),
    ("filter", ('{type = "kf"}', '{type = "pf"}'), "tracker.filter", None),
    ("sensor", ('type = "position"', 'type = "range"\nposition = [0.0, 0.0]'), "sensors[0].type", "position detections"),
    ("prior", ("[tracker]", "[prior]\nmean = [0.0, 0.0, 0.0, 0.0]\ncov = 1.0\n\n[tracker]"), "prior", "two-point initiation"),
]


@pytest.mark.parametrize("change, field, message", [b[1:] for b in BAD_MODELS], ids=[b[0] for b in BAD_MODELS])
def test_a_bad_model_file_exits_2_naming_file_line_and_field(change, field, message, files, tmp_path, capsys):
    text = _model_text("gnn")
    assert change[0] in text
    text = text.replace(change[0], change[1], 1)
    if field == "tracker.p_detect" and message is None:  # clutter_density commented out: it is required
        field, message = "tracker.clutter_density", "required for recorded detections"
    model = tmp_path / "model.toml"
    model.write_text(text)
    out = tmp_path / "tracks.csv"
    assert main(["track", "--multi", str(files["csv"]), "-c", str(model), "-o", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1
    key = field.split(".")[-1].split("[")[0]
    lines = [i for i, line in enumerate(text.splitlines(), start=1) if line.startswith(key) or line.startswith(f"[{key}")]
    if message == "required for recorded detections":  # a missing key: the line of its table
        lines = [i for i, line in enumerate(text.splitlines(), start=1) if line == "[tracker]"]
    assert any(err.startswith(f"pursuit: error: {model}:{n}: {field}") for n in lines), err
    if message:
        assert message in err
    assert not out.exists()


def test_truth_and_plot_are_refused_with_multi_and_no_var_without_it(files, tmp_path, capsys):
    assert main(["track", "--multi", str(files["csv"]), "-c", str(files["gnn"]), "--truth", str(files["csv"])]) == 2
    assert "--truth is not available with --multi" in capsys.readouterr().err
    assert main(["track", str(files["csv"]), "-c", str(files["gnn"]), "--no-var"]) == 2
    assert "--no-var is an option of --multi" in capsys.readouterr().err


def test_the_spelling_model_and_out_works_too(files, tmp_path):
    a, b = tmp_path / "a.csv", tmp_path / "b.csv"
    assert main(["track", "--multi", str(files["csv"]), "-c", str(files["gnn"]), "-o", str(a)]) == 0
    assert main(["track", "--multi", str(files["csv"]), "--model", str(files["gnn"]), "--out", str(b)]) == 0
    assert a.read_bytes() == b.read_bytes()


def test_the_model_builds_the_documented_defaults(files):
    model = load_multi_model(files["jpda"])
    assert isinstance(model.tracker, JPDATracker)
    assert (model.tracker.gate, model.tracker.confirm, model.tracker.max_misses, model.tracker.capacity) == (0.99, (2, 3), 3, 32)
    assert model.values == ("x", "y") and model.state_labels == ("x", "vx", "y", "vy")
