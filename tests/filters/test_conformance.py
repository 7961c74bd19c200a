"""The conformance suite: every filter in ``cases.CASES`` must pass all of these."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

import pursuit as pu
from pursuit.rng import RunStreams, run_streams

from .cases import CASES, LINEAR, NONLINEAR, NONLINEAR_CASES

STANDARD_KEYS = ("innovation", "S", "nis", "dof", "loglik")


def _simulate(scenario, runs, seed=7):
    return scenario.simulate(run_streams(seed, range(runs), 0), runs)


def _run(filt, sim, runs, seed=7, zs=None, **kw):
    zs = sim.measurements if zs is None else zs
    return pu.run(filt, zs, sim.prior, rng=run_streams(seed, range(runs), 1), **kw)


def _scenarios(case):
    if case.scenario is not None:
        return [case.scenario]
    return [LINEAR] if case not in NONLINEAR_CASES else [LINEAR, NONLINEAR]


def _pairs(cases):
    return [pytest.param(c, s, id=f"{c.id}-{s.name}") for c in cases for s in _scenarios(c)]


ALL = _pairs(CASES)


@pytest.mark.parametrize("case,scenario", ALL)
def test_output_shapes(case, scenario):
    runs = 5
    sim = _simulate(scenario, runs)
    filt = case.build(scenario)
    track = _run(filt, sim, runs)
    K, n, m = scenario.steps, sim.truth.shape[-1], sim.measurements.shape[-1]
    assert track.mean.shape == (K, runs, n)
    assert track.cov.shape == (K, runs, n, n)
    assert track.info["innovation"].shape == (K, runs, m)
    assert track.info["S"].shape == (K, runs, m, m)
    for key in ("nis", "dof", "loglik"):
        assert track.info[key].shape == (K, runs)
    assert np.all(np.isfinite(track.mean))
    assert isinstance(filt.name, str) and filt.name


@pytest.mark.parametrize("case,scenario", ALL)
def test_batch_equals_one_run_at_a_time(case, scenario):
    runs = 4
    sim = _simulate(scenario, runs)
    filt = case.build(scenario)
    batch = _run(filt, sim, runs)
    for i in range(runs):
        prior = pu.Gaussian(sim.prior.mean[i : i + 1], sim.prior.cov)
        streams = RunStreams(run_streams(7, range(runs), 1).generators[i : i + 1])
        single = pu.run(filt, sim.measurements[:, i : i + 1], prior, rng=streams)
        np.testing.assert_allclose(single.mean[:, 0], batch.mean[:, i], rtol=1e-12, atol=1e-12)
        np.testing.assert_allclose(single.cov[:, 0], batch.cov[:, i], rtol=1e-12, atol=1e-12)
        for key in STANDARD_KEYS:
            np.testing.assert_allclose(single.info[key][:, 0], batch.info[key][:, i], rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("case,scenario", ALL)
def test_same_seed_same_bits(case, scenario):
    runs = 3
    a = _run(case.build(scenario), _simulate(scenario, runs), runs)
    b = _run(case.build(scenario), _simulate(scenario, runs), runs)
    assert np.array_equal(a.mean, b.mean)
    assert np.array_equal(a.cov, b.cov)
    for key in a.info:
        assert np.array_equal(a.info[key], b.info[key], equal_nan=True), key


@pytest.mark.parametrize("case,scenario", ALL)
def test_nan_measurement_means_predict_only(case, scenario):
    runs = 4
    sim = _simulate(scenario, runs)
    zs = sim.measurements.copy()
    zs[5] = np.nan  # nothing measured at step 6, in any run
    zs[8, 1, 0] = np.nan  # one component missing in one run
    filt = case.build(scenario)
    track = _run(filt, sim, runs, zs=zs, store_predictions=True)
    m = zs.shape[-1]
    assert np.all(np.isfinite(track.mean))
    assert np.all(track.info["dof"][5] == 0)
    assert np.all(np.isnan(track.info["nis"][5]))
    assert np.all(track.info["loglik"][5] == 0.0)
    assert np.all(np.isnan(track.info["innovation"][5]))
    assert track.info["dof"][8, 1] == m - 1
    assert np.isfinite(track.info["nis"][8, 1])
    assert np.all(track.info["dof"][8, [0, 2, 3]] == m)
    if "pred_mean" in track.info:
        # predict only: the estimate is the prediction itself
        np.testing.assert_array_equal(track.mean[5], track.info["pred_mean"][5])
        np.testing.assert_allclose(track.cov[5], track.info["pred_cov"][5], rtol=1e-12, atol=1e-14)


@pytest.mark.parametrize("case,scenario", ALL)
def test_a_measurement_too_large_to_square_is_refused_naming_its_step(case, scenario):
    # A 1e300 measurement used to turn the EKF's estimate into NaN from that step on, unflagged.
    runs = 3
    sim = _simulate(scenario, runs)
    zs = sim.measurements[:4].copy()
    zs[2, 1, 0] = 1e300
    filt = case.build(scenario)
    with pytest.raises(ValueError, match=r"^step 3: measurement z\[1, 0\] = 1e\+300 is beyond ±2\^500"):
        _run(filt, sim, runs, zs=zs)


@pytest.mark.parametrize("case,scenario", ALL)
def test_nis_and_loglik_mean_the_same_thing(case, scenario):
    runs = 3
    sim = _simulate(scenario, runs)
    track = _run(case.build(scenario), sim, runs)
    nu, S = track.info["innovation"], track.info["S"]
    nis = np.einsum("...i,...i->...", nu, np.linalg.solve(S, nu[..., None])[..., 0])
    np.testing.assert_allclose(track.info["nis"], nis, rtol=1e-9)
    m = nu.shape[-1]
    assert np.all(track.info["dof"] == m)
    assert np.all(np.isfinite(track.info["loglik"]))
    if case.gaussian_loglik:
        logdet = np.linalg.slogdet(S)[1]
        expected = -0.5 * (nis + logdet + m * np.log(2 * np.pi))
        np.testing.assert_allclose(track.info["loglik"], expected, rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("case", [c for c in CASES if c.exact_on_linear], ids=lambda c: c.id)
def test_nis_is_chi2_on_a_matched_linear_model(case):
    runs = 400
    sim = _simulate(LINEAR, runs, seed=11)
    track = _run(case.build(LINEAR), sim, runs, seed=11)
    nis = track.info["nis"]
    m = sim.measurements.shape[-1]
    # Innovations of an optimal filter are white, so all K*M values are independent.
    lo, hi = stats.chi2.ppf([0.0005, 0.9995], nis.size * m) / nis.size
    assert lo <= nis.mean() <= hi


@pytest.mark.parametrize("case", [c for c in CASES if c.nis_tolerance > 0], ids=lambda c: c.id)
def test_mean_nis_near_the_measurement_dimension_for_approximate_filters(case):
    runs = 200
    sim = _simulate(LINEAR, runs, seed=11)
    track = _run(case.build(LINEAR), sim, runs, seed=11)
    m = sim.measurements.shape[-1]
    assert abs(np.mean(track.info["nis"]) / m - 1.0) <= case.nis_tolerance
