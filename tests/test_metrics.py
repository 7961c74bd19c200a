"""Metric definitions on hand-made arrays."""

import csv
import dataclasses
import json

import numpy as np
import pytest
from scipy import stats

import pursuit as pu
from pursuit import metrics
from pursuit.engine import monte_carlo
from pursuit.scenarios import LinearCV
from pursuit.storage import write_per_step_csv


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


@pytest.mark.slow
def test_reported_chi2_bounds_have_their_stated_coverage_on_a_matched_kf():
    # 400 independent Monte Carlo experiments (seeds) of a matched KF, 20 runs each.  The reported
    # anees_low/high (anis_*) are per-step 95 % bounds, so at every step the step's ANEES (ANIS) must lie
    # inside them in about 95 % of the seeds: the count is Binomial(400, 0.95), and each step's count must
    # lie inside its central 99.99 % range (about 364..392).  The old overall bounds, which treated the K*M
    # NEES values as independent, covered the overall ANEES in only about 70 % of seeds.
    sc = LinearCV(ndim=1, steps=8, q=0.05, sigma=1.0)
    kf = pu.KalmanFilter(sc.motion, sc.measurement)
    seeds, runs = 400, 20
    inside = {"anees": np.zeros(sc.steps, int), "anis": np.zeros(sc.steps, int)}
    overall_outside = {"anees": 0, "anis": 0}
    for seed in range(seeds):
        res = monte_carlo(sc, [kf], runs=runs, seed=seed)
        c = res.consistency("KF")
        for what in inside:
            lo, hi = c[f"{what}_low"], c[f"{what}_high"]
            assert (lo, hi) == pytest.approx(stats.chi2.ppf([0.025, 0.975], runs * 2 if what == "anees" else runs) / runs)
            per_step = getattr(res, what)("KF")
            inside[what] += (per_step >= lo) & (per_step <= hi)
            overall_outside[what] += not lo <= c[what] <= hi
    band = stats.binom.ppf([0.00005, 0.99995], seeds, 0.95)
    for what, counts in inside.items():
        assert np.all((counts >= band[0]) & (counts <= band[1])), (what, counts, band)
    # the all-step average spreads no more than one step's value: outside the per-step bounds at most as
    # often as a single step is (5 %), here in far fewer seeds
    assert max(overall_outside.values()) <= stats.binom.ppf(0.99995, seeds, 0.05), overall_outside


class _Dropouts:
    """LinearCV whose runs 0..5 have no measurement at step 3."""

    def __init__(self, inner):
        self.inner = inner

    def __getattr__(self, key):
        return getattr(self.inner, key)

    def simulate(self, rng, runs=None):
        sim = self.inner.simulate(rng, runs)
        zs = sim.measurements.copy()
        zs[2, :6] = np.nan
        return dataclasses.replace(sim, measurements=zs)


def test_per_step_bounds_follow_the_number_of_values(tmp_path):
    # NIS is missing at steps without a measurement: each step's bounds use its own count, the summary
    # gives the widest, and per_step.csv carries them step by step
    sc = _Dropouts(LinearCV(ndim=1, steps=6, q=0.05, sigma=1.0))
    res = monte_carlo(sc, [pu.KalmanFilter(sc.motion, sc.measurement)], runs=10, seed=2)
    lo, hi = res.consistency_bounds("KF", "nis")
    assert (lo[0], hi[0]) == pytest.approx(stats.chi2.ppf([0.025, 0.975], 10) / 10)
    assert (lo[2], hi[2]) == pytest.approx(stats.chi2.ppf([0.025, 0.975], 4) / 4)
    c = res.consistency("KF")
    assert (c["anis_low"], c["anis_high"]) == pytest.approx((lo[2], hi[2]))
    assert (c["anees_low"], c["anees_high"]) == pytest.approx(stats.chi2.ppf([0.025, 0.975], 20) / 10)
    with pytest.raises(ValueError, match="what"):
        res.consistency_bounds("KF", "rmse")
    write_per_step_csv(tmp_path / "p.csv", "exp", {"result": res})
    rows = list(csv.DictReader((tmp_path / "p.csv").open()))
    assert [float(r["anis_low"]) for r in rows] == lo.tolist()
    assert [float(r["anees_high"]) for r in rows] == res.consistency_bounds("KF")[1].tolist()
