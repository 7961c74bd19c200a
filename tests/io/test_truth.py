"""``pursuit track --truth FILE``: reading a truth file, scoring estimates, and the command line."""

from __future__ import annotations

import numpy as np
import pytest

from pursuit.cli import main
from pursuit.io.tracker import Estimate
from pursuit.io.truth import TruthError, format_score, read_truth, score

from .conftest import EXAMPLES

LABELS = ("x", "vx", "y", "vy")
KINDS = {"position": (0, 2), "velocity": (1, 3)}
WSN_MODEL = str(EXAMPLES / "wsn-range.toml")
WSN_CSV = str(EXAMPLES / "data" / "wsn-range.csv")
WSN_TRUTH = str(EXAMPLES / "data" / "wsn-range-truth.csv")


def _file(tmp_path, text, name="truth.csv"):
    p = tmp_path / name
    p.write_text(text)
    return p


def test_a_truth_file_with_some_columns_in_any_order(tmp_path):
    p = _file(tmp_path, "# made by hand\ntime,y,x\n\n2.0,5.0,1.0\n1.0,4.0,0.5\n")
    t = read_truth(p, LABELS)
    assert t.labels == ("y", "x") and t.indices == (2, 0)
    np.testing.assert_array_equal(t.times, [1.0, 2.0])  # sorted by time
    np.testing.assert_array_equal(t.states, [[4.0, 0.5], [5.0, 1.0]])


@pytest.mark.parametrize(
    "text, message",
    [
        ("", "truth.csv: header: missing: the file is empty"),
        ("x,y\n1,2\n", "truth.csv:1: header: the first column must be time, got 'x'"),
        ("time\n1\n", "truth.csv:1: header: no state columns after time"),
        ("time,x,speed\n1,2,3\n", "truth.csv:1: header: 'speed' is not a state component of the model (known: x, vx, y, vy)"),
        ("time,x,x\n1,2,3\n", "truth.csv:1: header: column 'x' is given twice"),
        ("time,x,y\n1,2,3\n2,3\n", "truth.csv:3: record: expected 3 fields (time,x,y), got 2"),
        ("time,x,y\n1,2,3\n2,abc,3\n", "truth.csv:3: x: not a number: 'abc'"),
        ("time,x,y\n1,2,\n", "truth.csv:2: y: missing"),
        ("time,x,y\n1,2,1e999\n", "truth.csv:2: y: '1e999' is too large"),
        ("time,x,y\n1,2,3\n# gap\n1.0,2,3\n", "truth.csv:4: time: 1.0 is already given on line 2"),
        ("time,x,y\n", "truth.csv: record: no truth rows after the header"),
    ],
)
def test_bad_truth_files_name_file_line_and_field(tmp_path, text, message):
    with pytest.raises(TruthError) as e:
        read_truth(_file(tmp_path, text), LABELS)
    assert str(e.value).endswith(message) or message in str(e.value), str(e.value)


def test_unreadable_and_non_utf8_truth_files(tmp_path):
    with pytest.raises(TruthError, match="nothing.csv: cannot read"):
        read_truth(tmp_path / "nothing.csv", LABELS)
    p = tmp_path / "latin.csv"
    p.write_bytes(b"time,x\n1,2\n2,\xe93\n")
    with pytest.raises(TruthError, match="latin.csv:3: record: not UTF-8"):
        read_truth(p, LABELS)


def _est(t, mean, cov):
    mean = np.asarray(mean, dtype=float)
    return Estimate(t, mean, np.diagonal(cov).copy(), np.nan, 0, (), (1,), np.asarray(cov, dtype=float))


def test_score_matches_times_and_computes_rmse_and_nees(tmp_path):
    truth = read_truth(_file(tmp_path, "time,x,vx,y,vy\n1,0,0,0,0\n2,10,1,10,1\n"), LABELS)
    P = np.diag([4.0, 1.0, 4.0, 1.0])
    est = [_est(1.0, [2, 1, 0, 0], P), _est(1.5, [99, 99, 99, 99], P), _est(2.0 + 1e-12, [10, 1, 6, 0], P)]
    s = score(est, truth, KINDS)
    assert (s.matched, s.total, s.dof) == (2, 3, 4)  # 1.5 s has no row; 2 + 1e-12 s matches 2 s
    np.testing.assert_allclose(s.rmse["position"][0], np.sqrt((4 + 16) / 2))
    np.testing.assert_allclose(s.rmse["velocity"][0], np.sqrt((1 + 1) / 2))
    np.testing.assert_allclose(s.nees, [4 / 4 + 1, 16 / 4 + 1])
    lines = format_score(s, truth)
    assert "2 of 3 estimates" in lines[0] and "position 3.16228 m (x, y)" in lines[1]


def test_nees_of_consistent_estimates_lies_in_its_bounds_and_of_overconfident_ones_does_not(tmp_path):
    rng = np.random.default_rng(11)
    K = 500
    times = np.arange(1.0, K + 1)
    truth_states = rng.normal(size=(K, 4)) * 50
    text = "time,x,vx,y,vy\n" + "".join(f"{float(t)!r}," + ",".join(repr(float(v)) for v in row) + "\n" for t, row in zip(times, truth_states))
    truth = read_truth(_file(tmp_path, text), LABELS)
    P = np.array([[4.0, 1.0, 0, 0], [1.0, 1.0, 0, 0], [0, 0, 9.0, 2.0], [0, 0, 2.0, 1.0]])
    errors = rng.multivariate_normal(np.zeros(4), P, size=K)
    good = score([_est(t, x + e, P) for t, x, e in zip(times, truth_states, errors)], truth, KINDS)
    lo, hi = good.mean_bounds
    assert lo < good.nees_mean < hi
    assert 0.9 < good.inside / K
    bad = score([_est(t, x + e, P / 2) for t, x, e in zip(times, truth_states, errors)], truth, KINDS)
    assert bad.nees_mean > bad.mean_bounds[1]


def test_no_estimate_at_a_truth_time_is_an_error(tmp_path):
    truth = read_truth(_file(tmp_path, "time,x\n100,0\n"), LABELS)
    with pytest.raises(TruthError, match="truth.csv: time: no truth row at the time of any of the 1 estimates"):
        score([_est(1.0, [0, 0, 0, 0], np.eye(4))], truth, KINDS)


def test_track_truth_prints_the_score_on_stderr(capsys):
    assert main(["track", WSN_CSV, "-c", WSN_MODEL]) == 0
    plain = capsys.readouterr().out
    assert main(["track", WSN_CSV, "-c", WSN_MODEL, "--truth", WSN_TRUTH]) == 0
    captured = capsys.readouterr()
    assert captured.out == plain  # the estimates are unchanged
    err = captured.err.splitlines()
    assert err[0] == f"pursuit track: truth {WSN_TRUTH}: 59 of 59 estimates have a truth row at their time"
    assert err[1].startswith("pursuit track: RMSE: position 0.8") and "velocity" in err[1]
    assert "NEES on x, vx, y, vy (chi-square, 4 dof): mean " in err[2] and "95% bounds for the mean" in err[2]


def test_a_bad_truth_file_stops_before_anything_is_written(tmp_path, capsys):
    bad = _file(tmp_path, "time,x,speed\n1,2,3\n")
    out = tmp_path / "est.csv"
    assert main(["track", WSN_CSV, "-c", WSN_MODEL, "--truth", str(bad), "-o", str(out)]) == 2
    assert not out.exists()
    assert capsys.readouterr().err.strip() == (
        f"pursuit track: error: {bad}:1: header: 'speed' is not a state component of the model (known: x, vx, y, vy)"
    )


def test_a_truth_file_at_other_times_is_an_error_after_the_estimates(tmp_path, capsys):
    other = _file(tmp_path, "time,x,y\n1000,2,3\n")
    assert main(["track", WSN_CSV, "-c", WSN_MODEL, "--truth", str(other)]) == 2
    captured = capsys.readouterr()
    assert captured.out.startswith("time,x,vx")
    assert "time: no truth row at the time of any of the 59 estimates" in captured.err


def test_estimates_are_kept_only_when_truth_or_plot_asks_for_them():
    from argparse import Namespace

    from pursuit.io import load_track_model
    from pursuit.io.extras import Extras

    model = load_track_model(WSN_MODEL)
    assert Extras.prepare(Namespace(truth=None, plot=None), model).sink is None  # a live stream keeps nothing
    assert Extras.prepare(Namespace(truth=WSN_TRUTH, plot=None), model).sink == []
