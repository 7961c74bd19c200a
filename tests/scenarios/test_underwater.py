"""Paper P2's underwater TOA scenario: geometry, conditions, measurement modes, seeding."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import stats

import pursuit as pu
from pursuit.models import trilaterate
from pursuit.rng import run_streams
from pursuit.scenarios import UnderwaterTOA


def _sim(sc, runs, seed=1, start=0):
    return sc.simulate(run_streams(seed, range(start, start + runs), 0), runs)


def test_conditions_set_the_papers_defaults():
    ideal, actual, abnormal = (UnderwaterTOA(condition=c) for c in ("ideal", "actual", "abnormal"))
    s0 = np.array([10.0, 20.0, 0.5, 0.4])
    assert np.array_equal(ideal.initial_estimate, s0)
    np.testing.assert_allclose(actual.initial_estimate, 1.06 * s0)
    np.testing.assert_allclose(abnormal.initial_estimate, 1.20 * s0)
    assert ideal.mismatch == (0.0, 0.0) and actual.mismatch == (1.0, 2.0) and abnormal.mismatch == (0.0, 0.0)
    assert ideal.outlier_step is None and actual.outlier_step is None and abnormal.outlier_step == 15
    assert abnormal.events == ((15.0, "outlier"),)
    assert np.array_equal(ideal.anchors, [[0, 0], [0, 50], [50, 0]])
    # an explicit value overrides the condition
    assert UnderwaterTOA(condition="abnormal", outlier_size=0.0).outlier_step is None
    assert UnderwaterTOA(condition="actual", mismatch=[0.0, 0.0]).mismatch == (0.0, 0.0)


def test_ranges_carry_the_stated_noise():
    sc = UnderwaterTOA(condition="ideal", steps=20)
    sim = _sim(sc, 200)
    true_r = np.linalg.norm(sim.truth[..., None, :2] - sc.anchors, axis=-1)
    noise = sim.measurements - true_r
    n = noise.size
    # the sum of squares of n N(0, σ²) values, standardised, is χ²_n
    lo, hi = stats.chi2.ppf([0.0005, 0.9995], n) / n
    assert lo <= np.mean(noise**2) / sc.sigma_r**2 <= hi
    assert abs(noise.mean()) < 4 * sc.sigma_r / np.sqrt(n)


def test_outlier_adds_to_every_range_at_its_step_only():
    sc = UnderwaterTOA(condition="abnormal", outlier_size=1.0)
    sim = _sim(sc, 50)
    true_r = np.linalg.norm(sim.truth[..., None, :2] - sc.anchors, axis=-1)
    excess = sim.measurements - true_r
    k = sc.outlier_step - 1
    np.testing.assert_allclose(excess[k], 1.0, atol=10 * sc.sigma_r)
    others = np.delete(excess, k, axis=0)
    assert np.abs(others).max() < 10 * sc.sigma_r


def test_actual_condition_drifts_the_truth_by_the_unknown_term():
    sc = UnderwaterTOA(condition="actual")
    sim = _sim(sc, 100)
    prev = np.concatenate([np.broadcast_to(sc.x0, (1, 100, 4)), sim.truth[:-1]])
    step = sim.truth - sc.motion.f(prev)
    # position increments are B ~ U[1, 2] plus N(0, 0.01²); velocities get only the noise
    assert step[..., :2].min() > 1.0 - 6 * 0.01 and step[..., :2].max() < 2.0 + 6 * 0.01
    assert abs(step[..., :2].mean() - 1.5) < 0.01
    assert np.abs(step[..., 2:]).max() < 6 * 0.01


def test_measurement_modes_agree():
    base = dict(condition="abnormal", steps=20)
    ranges = _sim(UnderwaterTOA(mode="ranges", **base), 5)
    times = _sim(UnderwaterTOA(mode="times", **base), 5)
    fix_sc = UnderwaterTOA(mode="position", **base)
    fixes = _sim(fix_sc, 5)
    assert np.array_equal(ranges.truth, times.truth) and np.array_equal(ranges.truth, fixes.truth)
    np.testing.assert_allclose(times.measurements * 1500.0, ranges.measurements, rtol=1e-15)
    np.testing.assert_allclose(fixes.measurements, trilaterate(fix_sc.anchors, ranges.measurements), rtol=1e-13)
    assert UnderwaterTOA(mode="times").measurement.R[0, 0] == pytest.approx((0.002 / 1500.0) ** 2)


def test_position_fix_covariance_matches_the_fix_errors_near_the_nominal_path():
    sc = UnderwaterTOA(condition="ideal", mode="position", steps=3, q=1e-12)
    sim = _sim(sc, 4000)
    err = sim.measurements - sim.truth[..., :2]
    for k in range(3):
        C = np.cov(err[k].T)
        R = sc.measurement.cov(k + 1)
        # 4000 draws: relative standard error of a variance about sqrt(2/4000) = 2.2 %
        np.testing.assert_allclose(np.diag(C), np.diag(R), rtol=0.1)


def test_kf_runs_on_the_position_fix_and_ekf_on_ranges_and_times():
    for mode, cls in (("position", pu.KalmanFilter), ("ranges", pu.ExtendedKalmanFilter), ("times", pu.ExtendedKalmanFilter)):
        sc = UnderwaterTOA(condition="ideal", mode=mode, steps=30)
        sim = _sim(sc, 20)
        track = pu.run(cls(sc.motion, sc.measurement), sim.measurements, sim.prior)
        err = np.linalg.norm(track.mean[..., :2] - sim.truth[..., :2], axis=-1)
        assert np.sqrt(np.mean(err[5:] ** 2)) < 10 * sc.sigma_r  # millimetre-level positioning


def test_position_only_state():
    sc = UnderwaterTOA(condition="actual", state="position")
    sim = _sim(sc, 3)
    assert sim.truth.shape == (60, 3, 2) and sc.state_labels == ("x", "y") and sc.velocity_indices == ()
    np.testing.assert_allclose(sim.prior.mean, np.tile(1.06 * np.array([10.0, 20.0]), (3, 1)))


def test_a_run_does_not_depend_on_its_batch():
    sc = UnderwaterTOA(condition="actual")
    whole = _sim(sc, 6)
    part = _sim(sc, 2, start=3)
    assert np.array_equal(whole.truth[:, 3:5], part.truth)
    assert np.array_equal(whole.measurements[:, 3:5], part.measurements)


@pytest.mark.parametrize(
    "kwargs,message",
    [
        (dict(condition="normal"), "condition: must be one of"),
        (dict(mode="bearings"), "mode: must be one of"),
        (dict(state="ca"), "state: must be one of"),
        (dict(d=-1.0), "d: must be positive"),
        (dict(sigma_r=0.0), "sigma_r: must be positive"),
        (dict(x0=[1.0, 2.0]), "x0: expected length 4"),
        (dict(mismatch=[2.0, 1.0]), "mismatch: high must be at least low"),
        (dict(initial_error=-0.1), "initial_error: must be non-negative"),
        (dict(outlier_time=-3.0), "outlier_time: must be positive"),
        (dict(P0=[[1.0, 2.0], [2.0, 1.0]]), "P0: expected a 4x4"),
    ],
)
def test_bad_parameters_are_refused_naming_the_field(kwargs, message):
    with pytest.raises(ValueError, match=message):
        UnderwaterTOA(**kwargs)


def test_travel_times_and_ranges_give_the_same_ekf_estimates():
    # times = ranges / c and σ_t = σ_r / c: the EKF is invariant to that scaling
    for condition in ("ideal", "abnormal"):
        est = {}
        for mode in ("ranges", "times"):
            sc = UnderwaterTOA(condition=condition, mode=mode, steps=30)
            sim = _sim(sc, 10)
            est[mode] = pu.run(pu.ExtendedKalmanFilter(sc.motion, sc.measurement, fading=pu.Improved()), sim.measurements, sim.prior).mean
        np.testing.assert_allclose(est["times"], est["ranges"], rtol=1e-9, atol=1e-9)
