"""Fading strategies (TFMKF, EWFMKF, STF, IFMKF) through the Gaussian filters' fading hook."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import pursuit as pu
from pursuit.filters.fading import CONDITION_LIMIT, FadingContext
from pursuit.filters.fading_adaptive import diag_sandwich
from pursuit.models import ConstantVelocity, LinearGaussian
from pursuit.rng import run_streams
from pursuit.scenarios import LinearCV, UnderwaterTOA, WSNRange

FILTERS = {
    "kf": pu.KalmanFilter,
    "ekf": pu.ExtendedKalmanFilter,
    "ukf": pu.UnscentedKalmanFilter,
    "ckf": pu.CubatureKalmanFilter,
}

# Strategies whose parameters make λ = 1 at every step.
NEUTRAL = {
    "constant": pu.Constant(1.0),
    "ewfmkf-capped": pu.ExponentiallyWeighted(b=0.9, lam_max=1.0),
    "stf-capped": pu.StrongTracking(lam_max=1.0),
    "stf-weak": pu.StrongTracking(beta=1.0e12),
    "ifmkf-never-diverges": pu.Improved(beta=1.0e9),
    "ifmkf-capped": pu.Improved(lam_max=1.0, gate=False, test="instant"),
}


def _sim(scenario, runs, seed=3):
    return scenario.simulate(run_streams(seed, range(runs), 0), runs)


@pytest.mark.parametrize("strategy", list(NEUTRAL), ids=list(NEUTRAL))
@pytest.mark.parametrize("kind", list(FILTERS))
def test_lambda_one_equals_the_plain_filter_exactly(kind, strategy):
    scenario = LinearCV(ndim=2, steps=30, q=0.05, sigma=1.0) if kind == "kf" else WSNRange(steps=30)
    sim = _sim(scenario, 6)
    cls = FILTERS[kind]
    plain = pu.run(cls(scenario.motion, scenario.measurement), sim.measurements, sim.prior)
    faded = pu.run(cls(scenario.motion, scenario.measurement, fading=NEUTRAL[strategy]), sim.measurements, sim.prior)
    assert np.all(faded.info["fading"] == 1.0)
    assert not faded.info["faded"].any()
    assert np.array_equal(plain.mean, faded.mean)
    assert np.array_equal(plain.cov, faded.cov)
    for key in ("innovation", "S", "nis", "loglik"):
        assert np.array_equal(plain.info[key], faded.info[key]), key


@pytest.mark.parametrize("kind", ["ekf", "ukf", "ckf"])
def test_every_strategy_runs_in_every_filter_and_records_lambda(kind):
    scenario = UnderwaterTOA(condition="actual", steps=25)
    sim = _sim(scenario, 5)
    for strategy in (pu.Constant(1.23), pu.ExponentiallyWeighted(), pu.StrongTracking(), pu.Improved()):
        track = pu.run(FILTERS[kind](scenario.motion, scenario.measurement, fading=strategy), sim.measurements, sim.prior)
        lam = track.info["fading"]
        assert lam.shape == (25, 5)
        assert np.array_equal(track.info["faded"], lam > 1.0)
        assert np.all(np.isfinite(track.mean))
        # the unknown drift makes every adaptive strategy fade at some point
        assert track.info["faded"].any()


@pytest.mark.parametrize("kind", list(FILTERS))
@settings(max_examples=25)
@given(
    b=st.floats(0.05, 0.99),
    rho=st.floats(0.05, 1.0),
    beta_s=st.floats(1.0, 5.0),
    beta=st.floats(0.5, 6.0),
    lam_max=st.floats(1.0, 1.0e5),
    seed=st.integers(0, 2**16),
)
def test_lambda_is_never_below_one_nor_above_its_cap(kind, b, rho, beta_s, beta, lam_max, seed):
    # The KF gets the position fix (a linear measurement), the others the ranges.
    mode = "position" if kind == "kf" else "ranges"
    scenario = UnderwaterTOA(condition="abnormal", steps=20, mismatch=(-0.5, 1.0), mode=mode)
    sim = _sim(scenario, 4, seed)
    for strategy in (
        pu.ExponentiallyWeighted(b=b, lam_max=lam_max),
        pu.StrongTracking(rho=rho, beta=beta_s, lam_max=lam_max),
        pu.Improved(beta=beta, lam_max=lam_max),
    ):
        filt = FILTERS[kind](scenario.motion, scenario.measurement, fading=strategy)
        lam = pu.run(filt, sim.measurements, sim.prior).info["fading"]
        assert np.all(lam >= 1.0)
        assert np.all(lam <= lam_max)


@pytest.mark.parametrize("strategy", [pu.ExponentiallyWeighted(), pu.StrongTracking(), pu.Improved()], ids=["ewfmkf", "stf", "ifmkf"])
def test_kf_with_an_adaptive_strategy_fades_and_equals_the_ekf_on_a_linear_model(strategy):
    # The position fix of the TOA scenario is a linear measurement: the KF
    # applies, and with the unknown drift every adaptive strategy fades.
    sc = UnderwaterTOA(condition="actual", mode="position")
    sim = _sim(sc, 10)
    kf = pu.run(pu.KalmanFilter(sc.motion, sc.measurement, fading=strategy), sim.measurements, sim.prior)
    ekf = pu.run(pu.ExtendedKalmanFilter(sc.motion, sc.measurement, fading=strategy), sim.measurements, sim.prior)
    lam = kf.info["fading"]
    assert kf.info["faded"].mean() > 0.2
    assert np.unique(lam[lam > 1.0]).size > 10  # λ differs between runs and steps
    np.testing.assert_allclose(lam, ekf.info["fading"], rtol=1e-9)
    np.testing.assert_allclose(kf.mean, ekf.mean, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(kf.cov, ekf.cov, rtol=1e-7, atol=1e-15)
    assert np.all(np.isfinite(kf.mean))


def _reference_trace_factor(track, motion, measurement, prior, rule, weakening=1.0):
    """λ_k of EWFMKF / STF from the spec's formulas, one run at a time, with full matrices."""
    K, M, m = track.info["innovation"].shape
    F, Q, R = motion.transition_matrix(), motion.cov(), measurement.cov()
    out = np.empty((K, M))
    for i in range(M):
        C = None
        for k in range(K):
            P_prev = prior.cov if k == 0 else track.cov[k - 1, i]
            P_bar = F @ P_prev @ F.T
            H = measurement.jacobian(track.info["pred_mean"][k, i])
            nu = track.info["innovation"][k, i][:, None]
            C = rule(C, nu @ nu.T, k)
            N = C - H @ Q @ H.T - weakening * R
            Mk = H @ P_bar @ H.T
            out[k, i] = max(1.0, np.trace(N) / np.trace(Mk))
    return out


def test_ewfmkf_matches_the_spec_formula_run_by_run():
    scenario = UnderwaterTOA(condition="actual", steps=30)
    sim = _sim(scenario, 3)
    b = 0.9
    filt = pu.ExtendedKalmanFilter(scenario.motion, scenario.measurement, fading=pu.ExponentiallyWeighted(b=b))
    track = pu.run(filt, sim.measurements, sim.prior, store_predictions=True)

    def rule(C, outer, k):
        d = (1 - b) / (1 - b ** (k + 1))
        return outer if C is None else (1 - d) * C + d * outer

    ref = _reference_trace_factor(track, scenario.motion, scenario.measurement, sim.prior, rule)
    np.testing.assert_allclose(track.info["fading"], ref, rtol=1e-9)
    assert (ref > 1).mean() > 0.5  # the comparison covers real fading, not only λ = 1


def test_stf_matches_the_spec_formula_run_by_run():
    scenario = UnderwaterTOA(condition="actual", steps=30)
    sim = _sim(scenario, 3)
    rho, beta = 0.8, 1.5
    filt = pu.ExtendedKalmanFilter(scenario.motion, scenario.measurement, fading=pu.StrongTracking(rho=rho, beta=beta))
    track = pu.run(filt, sim.measurements, sim.prior, store_predictions=True)

    def rule(V, outer, k):
        return outer if V is None else (rho * V + outer) / (1 + rho)

    ref = _reference_trace_factor(track, scenario.motion, scenario.measurement, sim.prior, rule, weakening=beta)
    np.testing.assert_allclose(track.info["fading"], ref, rtol=1e-9)
    assert (ref > 1).mean() > 0.5


def test_sigma_point_linearisation_is_the_jacobian_for_linear_h():
    motion = ConstantVelocity(ndim=2, q=0.05)
    meas = LinearGaussian.position(4, motion.position_indices, 0.5)
    sc = LinearCV(ndim=2, steps=40, q=0.05, sigma=0.5)
    sim = _sim(sc, 4)
    # a strong model mismatch so that STF fades
    zs = sim.measurements + 0.05 * np.arange(40)[:, None, None] ** 2
    ref = pu.run(pu.KalmanFilter(motion, meas, fading=pu.StrongTracking()), zs, sim.prior)
    assert ref.info["faded"].mean() > 0.3
    for cls in (pu.UnscentedKalmanFilter, pu.CubatureKalmanFilter):
        other = pu.run(cls(motion, meas, fading=pu.StrongTracking()), zs, sim.prior)
        np.testing.assert_allclose(other.info["fading"], ref.info["fading"], rtol=1e-7)
        np.testing.assert_allclose(other.mean, ref.mean, rtol=1e-7, atol=1e-8)


def test_adaptive_fading_leaves_the_kf_shared_covariance_path():
    sc = LinearCV(ndim=1, steps=10)
    sim = _sim(sc, 3)
    filt = pu.KalmanFilter(sc.motion, sc.measurement, fading=pu.StrongTracking())
    state = filt.init(sim.prior, batch=(3,))
    for k in range(10):
        state, info = filt.step(state, sim.measurements[k])
    assert state.cov.strides[0] != 0  # one covariance per run
    assert info["fading"].shape == (3,)


def test_diag_sandwich_is_the_diagonal_of_h_a_ht(rng):
    H = rng.standard_normal((5, 3, 4))
    A = rng.standard_normal((5, 4, 4))
    np.testing.assert_allclose(diag_sandwich(H, A), np.diagonal(H @ A @ np.swapaxes(H, -1, -2), axis1=-2, axis2=-1))


@pytest.mark.parametrize(
    "factory,message",
    [
        (lambda: pu.ExponentiallyWeighted(b=1.0), "b: must lie in"),
        (lambda: pu.ExponentiallyWeighted(b=0.0), "b: must lie in"),
        (lambda: pu.ExponentiallyWeighted(lam_max=0.5), "lam_max: must be at least 1"),
        (lambda: pu.StrongTracking(rho=0.0), "rho: must lie in"),
        (lambda: pu.StrongTracking(beta=0.9), "beta: must lie in"),
        (lambda: pu.StrongTracking(lam_max=float("nan")), "lam_max"),
        (lambda: pu.Improved(beta=0.0), "beta: must be positive"),
        (lambda: pu.Improved(window=0), "window: must be at least 1"),
        (lambda: pu.Improved(test="median"), "test: must be one of"),
        (lambda: pu.Improved(search="newton"), "search: must be one of"),
        (lambda: pu.Improved(lam_max=0.5), "lam_max: must lie in"),
        (lambda: pu.Improved(grid=1), "grid: must be an integer of at least 2"),
        (lambda: pu.Improved(gate_factor=0.5), "gate_factor: must lie in"),
        (lambda: pu.Improved(gate_max=0), "gate_max: must be at least 1"),
        (lambda: pu.Improved(gate="yes"), "gate: expected true or false"),
    ],
)
def test_impossible_parameters_are_refused_naming_the_field(factory, message):
    with pytest.raises(ValueError, match=message):
        factory()


def _context(z, pbar, r, q=0.0):
    """A fading context for a direct measurement of the state (H = I), prediction 0."""
    z = np.asarray(z, dtype=float)
    m = z.shape[-1]
    return FadingContext(
        k=1,
        pred_mean=np.zeros(z.shape),
        propagated_cov=np.diag(pbar),
        process_cov=q * np.eye(m),
        z=z,
        measurement=LinearGaussian(np.eye(m), np.diag(r)),
        trial_update=lambda lam: (_ for _ in ()).throw(AssertionError("not needed")),
    )


def test_lam_ceiling_is_kappa_times_tr_r_over_tr_hph_over_every_component():
    # The second component is missing, yet its block of P̄ counts: it must not
    # grow unbounded now and meet a precise measurement later.
    ctx = _context([[1.0e3, np.nan]], pbar=[1e-6, 1.0], r=[1e-6, 1e-6])
    expected = CONDITION_LIMIT * 2e-6 / (1e-6 + 1.0)
    np.testing.assert_allclose(ctx.lam_ceiling, [expected], rtol=1e-12)
    assert CONDITION_LIMIT == pytest.approx(1 / np.sqrt(np.finfo(float).eps))
    # never below 1, infinite without propagated uncertainty
    assert _context([[1.0]], pbar=[1e3], r=[1e-6]).lam_ceiling[0] == 1.0
    assert _context([[1.0]], pbar=[0.0], r=[1e-6]).lam_ceiling[0] == np.inf


@pytest.mark.parametrize("lam_max,expected", [(np.inf, "ceiling"), (1.0e4, 1.0e4)])
def test_trace_ratio_strategies_stop_at_the_ceiling(lam_max, expected):
    # First innovation 1e3 against P̄ = R = 1e-6: the trace ratio is ~1e12.
    ctx = _context([[1.0e3]], pbar=[1e-6], r=[1e-6])
    ceiling = float(ctx.lam_ceiling[0])
    assert ceiling == pytest.approx(CONDITION_LIMIT)
    want = ceiling if expected == "ceiling" else expected
    for strategy in (pu.ExponentiallyWeighted(lam_max=lam_max), pu.StrongTracking(lam_max=lam_max)):
        fade, _ = strategy.factor(strategy.init((1,)), _context([[1.0e3]], pbar=[1e-6], r=[1e-6]))
        assert float(fade.lam[0]) == want


def test_default_lambda_cap_of_the_adaptive_strategies_is_spec_03s_lam_max():
    for strategy in (pu.ExponentiallyWeighted(), pu.StrongTracking(), pu.Improved()):
        assert strategy.lam_max == 1.0e4
