"""Metric definitions on hand-made arrays."""

import json

import numpy as np
import pytest
from scipy import stats

import pursuit as pu
from pursuit import metrics
from pursuit.engine import monte_carlo
from pursuit.scenarios import LinearCV


def test_rmse_definitions():
    truth = np.zeros((2, 2, 2))
    est = np.array([[[3.0, 4.0], [0.0, 0.0]], [[1.0, 0.0], [0.0, 1.0]]])  # (K=2, M=2, n=2)
    sq = metrics.squared_error(est, truth)
    np.testing.assert_array_equal(sq, [[25.0, 0.0], [1.0, 1.0]])
    np.testing.assert_allclose(metrics.rmse_per_step(sq), [np.sqrt(12.5), 1.0])
    assert metrics.rmse_pooled(sq) == pytest.approx(np.sqrt(27 / 4))
    np.testing.assert_allclose(metrics.rmse_per_run(sq), [np.sqrt(13), np.sqrt(0.5)])
    np.testing.assert_array_equal(metrics.squared_error(est, truth, [1]), [[16.0, 0.0], [0.0, 1.0]])


def test_nees_on_hand_values():
    e = np.array([[[1.0, 2.0]]])
    P = np.array([[[[2.0, 0.0], [0.0, 4.0]]]])
    assert metrics.nees(e, P, np.zeros_like(e))[0, 0] == pytest.approx(0.5 + 1.0)
    bad = np.array([[[[1.0, 0.0], [0.0, -1.0]]]])
    assert np.isnan(metrics.nees(e, bad, np.zeros_like(e))[0, 0])


def test_chi2_bounds_and_averages():
    lo, hi = metrics.chi2_bounds(2, 50)
    assert lo == pytest.approx(stats.chi2.ppf(0.025, 100) / 50)
    assert hi == pytest.approx(stats.chi2.ppf(0.975, 100) / 50)
    vals = np.array([[1.0, np.nan, 3.0], [np.nan, np.nan, np.nan]])
    avg, dof, count = metrics.average_consistency(vals, np.array([[2, 0, 2], [0, 0, 0]]))
    assert avg[0] == 2.0 and np.isnan(avg[1])
    assert dof[0] == 2.0 and count.tolist() == [2, 0]


def test_result_summary_and_files(tmp_path):
    sc = LinearCV(ndim=2, steps=10)
    res = monte_carlo(sc, [pu.KalmanFilter(sc.motion, sc.measurement)], runs=5, seed=1, config={"a": 1})
    row = res.summary()[0]
    assert row["filter"] == "KF"
    assert row["rmse_position"] == pytest.approx(res.rmse("KF", "position"))
    assert row["rms_x"] == pytest.approx(np.sqrt(np.mean((res.filters["KF"].estimates[..., 0] - res.truth[..., 0]) ** 2)))
    assert res.rmse("KF", "position", average="per-run") <= res.rmse("KF", "position") + 1e-12  # Jensen
    assert {"anees", "anees_low", "anees_high", "anis", "wall_time_s"} <= set(row)
    csv_path = res.to_csv(tmp_path / "s.csv")
    assert csv_path.read_text().startswith("filter,")
    doc = json.loads(res.to_json(tmp_path / "s.json").read_text())
    assert doc["seed"] == 1 and doc["config"] == {"a": 1} and doc["filters"] == ["KF"]
    with pytest.raises(KeyError, match="no filter"):
        res.rmse("UKF")
    with pytest.raises(KeyError, match="component"):
        res.rmse("KF", "jerk")
    with pytest.raises(ValueError, match="average"):
        res.rmse("KF", average="median")
