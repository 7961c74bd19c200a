"""``[prior] from = "measurements"`` (or no [prior]): the track starts from its first positions."""

from __future__ import annotations

import io

import numpy as np
import pytest

from pursuit.cli import main
from pursuit.experiment import ConfigError
from pursuit.io import load_track_model, read_records, track_records
from pursuit.io.initiate import NoFix, position_from_step
from pursuit.io.steps import Step

from .conftest import EXAMPLES, csv_text, read_truth

GPS = """\
[motion]
type = "cv"
ndim = 2
q = 0.01

[[sensors]]
id = "gps"
type = "position"
sigma = [2.0, 3.0]

[filter]
type = "kf"
"""


def _model(tmp_path, text):
    p = tmp_path / "model.toml"
    p.write_text(text)
    return load_track_model(p)


def _track(model, rows):
    return track_records(read_records(io.BytesIO(csv_text(rows).encode()), "csv"), model)


def test_without_a_prior_the_first_two_fixes_start_the_track(tmp_path):
    model = _model(tmp_path, GPS)
    assert model.prior is None and model.initiation.velocity_sigma == 10.0
    rows = [(1.0, "gps", 10.0, 20.0), (3.0, "gps", 14.0, 16.0), (4.0, "gps", 16.2, 14.1)]
    est = _track(model, rows).estimates
    assert [e.flags for e in est] == [("init",), ("init",), ()]
    # one point: the fix, velocity unknown (σ = 10 m/s)
    np.testing.assert_array_equal(est[0].mean, [10.0, 0.0, 20.0, 0.0])
    np.testing.assert_array_equal(est[0].var, [4.0, 100.0, 9.0, 100.0])
    # two points: position of the second fix, velocity from the difference, P from R and dt
    np.testing.assert_array_equal(est[1].mean, [14.0, 2.0, 16.0, -2.0])
    np.testing.assert_allclose(est[1].var, [4.0, 8.0 / 4.0, 9.0, 18.0 / 4.0])
    np.testing.assert_allclose(est[1].cov[0, 1], 4.0 / 2.0)
    # then the filter: a KF step from that prior over dt = 1 s
    F = np.kron(np.eye(2), [[1.0, 1.0], [0.0, 1.0]])
    G = np.kron(np.eye(2), [[0.5], [1.0]])
    P = F @ est[1].cov @ F.T + 0.01 * G @ G.T
    H = np.array([[1.0, 0, 0, 0], [0, 0, 1.0, 0]])
    S = H @ P @ H.T + np.diag([4.0, 9.0])
    K = P @ H.T @ np.linalg.inv(S)
    x = F @ est[1].mean
    x = x + K @ (np.array([16.2, 14.1]) - H @ x)
    np.testing.assert_allclose(est[2].mean, x, rtol=1e-12)
    assert est[2].dof == 2 and np.isfinite(est[2].nis)


def test_from_measurements_with_its_own_sigmas(tmp_path):
    model = _model(tmp_path, GPS + '\n[prior]\nfrom = "measurements"\nvelocity_sigma = 3.0\n')
    est = _track(model, [(1.0, "gps", 10.0, 20.0)]).estimates
    assert est[0].var[1] == 9.0


@pytest.mark.parametrize(
    "table, message",
    [
        ('from = "guess"', "prior.from"),
        ('from = "measurements"\nvelocity_sigma = -1.0', "prior.velocity_sigma: must be a positive number"),
        ('from = "measurements"\nmean = [0.0, 0.0, 0.0, 0.0]', "prior.mean"),
    ],
)
def test_bad_initiation_tables_name_the_field(tmp_path, table, message):
    with pytest.raises(ConfigError, match=message):
        _model(tmp_path, GPS + "\n[prior]\n" + table + "\n")


def test_range_only_multilateration_starts_the_wsn_example(tmp_path, capsys):
    text = (EXAMPLES / "wsn-range.toml").read_text()
    start = text.index("[prior]")
    model_path = tmp_path / "wsn.toml"
    model_path.write_text(text[:start] + text[text.index("[filter]"):])
    assert main(["track", str(EXAMPLES / "data" / "wsn-range.csv"), "-c", str(model_path)]) == 0
    captured = capsys.readouterr()
    rows = [line.split(",") for line in captured.out.splitlines()[1:]]
    # t = 1 s has three ranges (a fix), t = 2 and 3 s only two (warned, not used), t = 4 s the second fix
    assert [float(r[0]) for r in rows[:3]] == [1.0, 4.0, 5.0]
    assert [r[-1] for r in rows[:3]] == ["init", "init", ""]
    assert "wsn-range.csv:5: time: not used to start the track" in captured.err
    assert "ranges to 2 anchor(s) (a position in 2-D needs 3)" in captured.err
    times, truth = read_truth(EXAMPLES / "data" / "wsn-range-truth.csv")
    at4 = truth[times == 4.0][0]
    est = np.array([float(v) for v in rows[1][1:5]])
    var = np.array([float(v) for v in rows[1][5:9]])
    assert np.all(np.abs(est - at4) < 4.0 * np.sqrt(var))


def test_a_range_and_a_bearing_from_one_site(tmp_path):
    text = GPS.replace(
        'id = "gps"\ntype = "position"\nsigma = [2.0, 3.0]',
        'id = "r"\ntype = "range"\nposition = [5.0, 5.0]\nsigma = 1.0\n\n[[sensors]]\nid = "b"\ntype = "bearing"\nposition = [5.0, 5.0]\nsigma = 0.01',
    ).replace('"kf"', '"ekf"')
    model = _model(tmp_path, text)
    z = np.array([100.0, 0.0])
    p, C = position_from_step(Step(1.0, z, (2, 3), ("r", "b")), model)
    np.testing.assert_allclose(p, [105.0, 5.0])
    np.testing.assert_allclose(C, np.diag([1.0, 1.0]), atol=1e-12)
    with pytest.raises(NoFix, match="no range and bearing from one site"):
        position_from_step(Step(1.0, np.array([100.0, np.nan]), (2,), ("r",)), model)


def test_toa_times_become_ranges(tmp_path):
    model = load_track_model(EXAMPLES / "underwater-toa.toml")
    sensors = list(model.sensors.values())
    truth = np.array([12.0, 30.0])
    z = np.full(model.measurement_dim, np.nan)
    for s in sensors:
        z[s.block] = np.linalg.norm(truth - np.array(s.position)) / s.c
    p, C = position_from_step(Step(1.0, z, (2,), tuple(model.sensors)), model)
    np.testing.assert_allclose(p, truth, atol=1e-8)
    assert np.all(np.linalg.eigvalsh(C) > 0)


def test_an_input_that_never_fixes_a_position_is_nothing_to_track(tmp_path, capsys, monkeypatch):
    import sys

    data = tmp_path / "d.csv"
    data.write_text(csv_text([(1.0, "A1", 40.0), (1.0, "A2", 70.0), (2.0, "A1", 41.0)]))
    text = (EXAMPLES / "wsn-range.toml").read_text()
    model_path = tmp_path / "wsn.toml"
    model_path.write_text(text[: text.index("[prior]")] + text[text.index("[filter]"):])
    assert main(["track", str(data), "-c", str(model_path)]) == 2
    err = capsys.readouterr().err
    assert "fixes no position" in err
    assert "nothing to track: no step fixed a position to start the track from (see the warnings; or give a [prior])" in err
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(b'{"time": 1.0, "sensor": "A1", "value": 40.0}\n')))
    assert main(["track", "-", "-c", str(model_path)]) == 2
    assert "nothing to track: no step fixed a position" in capsys.readouterr().err


def test_an_empty_prior_table_says_what_it_needs(tmp_path):
    with pytest.raises(ConfigError, match='prior: empty: give mean and cov, or from = "measurements"'):
        _model(tmp_path, GPS + "\n[prior]\n")


def test_a_live_stream_starts_from_its_first_fixes_and_scores_against_truth(tmp_path, monkeypatch, capsys):
    import json
    import sys

    model_path = tmp_path / "gps.toml"
    model_path.write_text(GPS)
    truth = tmp_path / "truth.csv"
    truth.write_text("time,x,y\n1.0,10.0,20.0\n2.0,12.0,18.0\n3.0,14.0,16.0\n")
    lines = [{"time": 1.0, "sensor": "gps", "value": [10.5, 19.0]}, {"time": 2.0, "sensor": "gps", "value": [12.0, 18.5]},
             {"time": 3.0, "sensor": "gps", "value": [13.5, 16.0]}]
    data = "".join(json.dumps(obj) + "\n" for obj in lines).encode()
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(data)))
    assert main(["track", "-", "-c", str(model_path), "--truth", str(truth)]) == 0
    captured = capsys.readouterr()
    out = [json.loads(line) for line in captured.out.splitlines()]
    assert [o["flags"] for o in out] == [["init"], ["init"], []]
    assert out[1]["state"] == {"x": 12.0, "vx": 1.5, "y": 18.5, "vy": -0.5}
    assert "3 of 3 estimates have a truth row" in captured.err and "RMSE: position" in captured.err


@pytest.mark.parametrize("r", [0.0, -3.0])
def test_a_step_that_gives_no_usable_position_is_not_used(tmp_path, r):
    text = GPS.replace(
        'id = "gps"\ntype = "position"\nsigma = [2.0, 3.0]',
        'id = "r"\ntype = "range"\nposition = [5.0, 5.0]\nsigma = 1.0\n\n[[sensors]]\nid = "b"\ntype = "bearing"\nposition = [5.0, 5.0]\nsigma = 0.01',
    ).replace('"kf"', '"ekf"')
    model = _model(tmp_path, text)
    rows = [(1.0, "r", r), (1.0, "b", 0.3), (2.0, "r", 50.0), (2.0, "b", 0.3), (3.0, "r", 51.0), (3.0, "b", 0.3)]
    result = _track(model, rows)
    if r == 0.0:  # the cross-range variance (r σθ)² is 0: no positive definite covariance
        assert [d.line for d in result.dropped] == [2, 3]
        assert "no position with a positive definite covariance" in result.dropped[0].message
        assert [e.time for e in result.estimates] == [2.0, 3.0]
    else:  # a negative range is still a point (behind the site): the standard conversion takes it
        assert [e.time for e in result.estimates] == [1.0, 2.0, 3.0]


def test_fixes_too_close_in_time_for_two_point_differencing(tmp_path):
    model = _model(tmp_path, GPS)
    rows = [(1e-300, "gps", 10.0, 20.0), (2e-300, "gps", 14.0, 16.0), (3.0, "gps", 14.0, 16.0)]
    result = _track(model, rows)
    assert [e.time for e in result.estimates] == [1e-300, 3.0]
    assert "two-point differencing from time 1e-300 fails" in result.dropped[0].message


def test_the_two_point_prior_from_ranges_is_consistent_over_many_runs():
    """The prior the track model builds from two range-only steps: NEES of the true state in its χ²(4) band."""
    from pursuit.initiation import two_point
    from pursuit.metrics import chi2_bounds, nees

    model = load_track_model(EXAMPLES / "wsn-range.toml")  # four anchors, 1 m range noise
    anchors = np.array([s.position for s in model.sensors.values()])
    rng = np.random.default_rng(21)
    M, dt = 300, 2.0
    x1 = np.column_stack([rng.uniform(20, 80, M), rng.normal(0, 1, M), rng.uniform(20, 80, M), rng.normal(0, 1, M)])
    x2 = model.motion.f(x1, dt=dt)  # no process noise between the two steps, as two-point differencing assumes
    means, covs = [], []
    for a, b in zip(x1, x2):
        fixes = []
        for t, x in ((1.0, a), (1.0 + dt, b)):
            z = np.linalg.norm(x[[0, 2]] - anchors, axis=1) + rng.normal(0, 1.0, len(anchors))
            fixes.append(position_from_step(Step(t, z, (1,), tuple(model.sensors)), model))
        g = two_point(*fixes[0], *fixes[1], dt, model.motion)
        means.append(g.mean)
        covs.append(g.cov)
    e = nees(np.array(means)[None], np.array(covs)[None], x2[None])[0]
    lo, hi = chi2_bounds(4, M, level=0.999)
    assert lo < e.mean() < hi, (e.mean(), lo, hi)


# --------------------------------------------------------------------------
# the limits a [prior] and each step's measurements get hold for a prior built from the data
# (found in review: a traceback, and silent nonsense from 1e300 fixes)
# --------------------------------------------------------------------------
MIXED = """\
[motion]
type = "cv"
ndim = 2
q = 0.01

[[sensors]]
id = "G"
type = "position"
sigma = 1.0e6

[[sensors]]
id = "R"
type = "range"
position = [0.0, 0.0]
sigma = 1.0e-3

[filter]
type = "ekf"
"""


def test_a_two_point_prior_too_wide_for_the_precise_sensors_is_not_used_and_said(tmp_path, capsys):
    # fixes of σ = 1e6 m give a prior 1e18 times the 1 mm range's variance: float64 cannot update with it
    model = tmp_path / "model.toml"
    model.write_text(MIXED)
    data = tmp_path / "d.csv"
    data.write_text("time,sensor,x,y\n0,G,10,20\n1,G,11,21\n2,G,12,22\n")
    assert main(["track", str(data), "--config", str(model)]) == 0  # was a ValueError traceback (exit 1)
    out, err = capsys.readouterr()
    assert "Traceback" not in err
    warned = [line for line in err.splitlines() if "the two-point prior from time 0.0 is unusable: prior.cov: too large" in line]
    assert len(warned) == 2  # lines 3 and 4: each pair with the first fix gives that prior
    assert [row.split(",")[-1] for row in out.splitlines()[1:]] == ["init"]  # only the one-point estimate of the first fix


def test_fixes_beyond_what_the_filters_can_square_do_not_start_a_track(tmp_path):
    model = _model(tmp_path, GPS.replace("sigma = [2.0, 3.0]", "sigma = [2.0, 3.0]\nvalid = [-1e300, 1e300]"))
    rows = [(0.0, "gps", 1e300, 20.0), (1.0, "gps", -1e300, 21.0), (2.0, "gps", 12.0, 22.0), (3.0, "gps", 13.0, 23.0)]
    res = _track(model, rows)
    assert [p.line for p in res.dropped] == [2, 3]
    assert all("beyond ±2^500" in p.message for p in res.dropped)
    assert [e.time for e in res.estimates] == [2.0, 3.0]  # started from the sane fixes
    np.testing.assert_array_equal(res.estimates[-1].mean, [13.0, 1.0, 23.0, 1.0])
