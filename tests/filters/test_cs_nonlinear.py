"""NonlinearCSFilter: reductions to the per-axis CS and APCS filters, ANEES on a matched case, angle wrap, adaptation bounds."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import stats

import pursuit as pu
from pursuit.filters import AdaptiveCSFilter, CurrentStatisticalFilter, NonlinearCSFilter
from pursuit.gaussian import Gaussian
from pursuit.models import LinearGaussian, ObserverBearings, Singer
from pursuit.rng import run_streams
from pursuit.scenarios import ManeuveringTarget

SCENARIO = ManeuveringTarget(horizon=60)
ONE_AXIS = ManeuveringTarget(
    horizon=60, position=(200e3,), velocity=(400.0,), maneuvers=[{"axis": "x", "start": 20, "stop": 35, "accel": 40.0}]
)


def _sim(scenario, runs, seed=5):
    return scenario.simulate(run_streams(seed, range(runs), 0), runs)


def _both(a, b, sim):
    ta = pu.run(a, sim.measurements, sim.prior)
    tb = pu.run(b, sim.measurements, sim.prior)
    return ta, tb


# --------------------------------------------------------------------------
# where the joint filter meets the per-axis ones
# --------------------------------------------------------------------------
def test_fixed_cs_with_position_measurements_equals_the_per_axis_cs_filter():
    # Where the assumptions meet: each axis measured in position with diagonal R, so the joint
    # covariance stays block diagonal and the joint Kalman update splits into the per-axis ones.
    sim = _sim(SCENARIO, 8)
    per_axis = CurrentStatisticalFilter(SCENARIO.measurement, alpha=0.02, a_max=80.0)
    joint = NonlinearCSFilter(SCENARIO.measurement, adaptation="none", alpha0=0.02, a_max=80.0, sigma_min=0.0)
    ta, tb = _both(per_axis, joint, sim)
    np.testing.assert_allclose(tb.mean, ta.mean, rtol=1e-10, atol=1e-6)
    np.testing.assert_allclose(tb.cov, ta.cov, rtol=1e-9, atol=1e-8)


@pytest.mark.parametrize(
    "options",
    [
        dict(fading="stf", alpha_rule="ratio", variance="displacement"),
        dict(fading="ratio", alpha_rule="fading", variance="linear"),
        dict(fading="none", alpha_rule="none", variance="rayleigh"),
        dict(fading="stf", alpha_rule="fading", variance="fixed", sigma_a=3.0, mean="zero"),
    ],
)
def test_apcs_adaptation_on_one_axis_equals_the_per_axis_apcs_filter(options):
    # One axis measured in position: the joint residual test D is the per-axis one, and so are λ, α and σ_a².
    sim = _sim(ONE_AXIS, 12)
    kw = dict(alpha0=0.01, a_max=100.0, threshold=3.0, sigma_min=0.1, **options)
    ta, tb = _both(AdaptiveCSFilter(ONE_AXIS.measurement, **kw), NonlinearCSFilter(ONE_AXIS.measurement, adaptation="apcs", **kw), sim)
    assert ta.info["maneuver"].any()  # the adaptation acted
    np.testing.assert_array_equal(tb.info["maneuver"], ta.info["maneuver"])
    np.testing.assert_allclose(tb.info["alpha"], ta.info["alpha"], rtol=1e-10)
    np.testing.assert_allclose(tb.info["fading"], ta.info["fading"], rtol=1e-9)
    np.testing.assert_allclose(tb.mean, ta.mean, rtol=1e-9, atol=1e-6)
    np.testing.assert_allclose(tb.cov, ta.cov, rtol=1e-8, atol=1e-8)


def test_limit_rule_with_no_room_to_adapt_is_the_fixed_filter():
    sim = _sim(SCENARIO, 5)
    fixed = NonlinearCSFilter(SCENARIO.measurement, adaptation="none", alpha0=0.05, a_max=30.0)
    pinned = NonlinearCSFilter(
        SCENARIO.measurement, adaptation="limit", alpha0=0.05, a_max=30.0, a_max_cap=30.0, alpha_cap=0.05, fading="none"
    )
    ta, tb = _both(fixed, pinned, sim)
    assert tb.info["maneuver"].any()
    np.testing.assert_array_equal(tb.mean, ta.mean)
    np.testing.assert_array_equal(tb.cov, ta.cov)


def test_ukf_update_equals_ekf_for_a_linear_measurement():
    sim = _sim(SCENARIO, 5)
    kw = dict(adaptation="limit", alpha0=0.05, a_max=10.0, a_max_cap=60.0, fading="stf")
    ta, tb = _both(NonlinearCSFilter(SCENARIO.measurement, update="ekf", **kw), NonlinearCSFilter(SCENARIO.measurement, update="ukf", **kw), sim)
    np.testing.assert_allclose(tb.mean, ta.mean, rtol=1e-8, atol=1e-5)


# --------------------------------------------------------------------------
# bearings
# --------------------------------------------------------------------------
def _weave(K: int, dims: int = 2, amplitude: float = 2000.0) -> np.ndarray:
    t = np.arange(1, K + 1, dtype=float)
    obs = np.zeros((K, dims))
    obs[:, 0] = amplitude * np.sin(2 * np.pi * t / 50.0)
    obs[:, 1] = 300.0 * t
    return obs


def _matched_bearings(dims: int, runs: int, K: int, seed: int):
    """Truth drawn from the Singer model the filter assumes; angles from a weaving observer."""
    alpha, sigma = 0.05, 0.3
    motion = Singer(alpha=alpha, sigma=sigma, ndim=dims, dt=1.0)
    sensor = ObserverBearings(_weave(K, dims), 1e-3)
    rng = np.random.default_rng(seed)
    n = 3 * dims
    x0 = np.zeros(n)
    x0[0], x0[3] = 7000.0, 7000.0
    x0[4] = 300.0
    if dims == 3:
        x0[6] = 2000.0
    P0 = np.diag(np.tile([100.0**2, 10.0**2, 0.5**2], dims))
    truth0 = x0 + rng.standard_normal((runs, n)) @ np.linalg.cholesky(P0).T
    x, xs, zs = truth0, [], []
    for k in range(1, K + 1):
        x = motion.sample(x, k, rng)
        xs.append(x)
        zs.append(sensor.sample(x, k, rng))
    return motion, sensor, Gaussian(np.broadcast_to(x0, (runs, n)).copy(), P0), np.array(xs), np.array(zs)


@pytest.mark.parametrize("dims,update", [(2, "ekf"), (2, "ukf"), (3, "ekf")])
def test_anees_on_a_matched_non_maneuvering_case_is_in_its_chi2_band(dims, update):
    # Matched: the APCS options that leave the model fixed (no fading, α = α0, σ_a fixed, ā = 0)
    # make the filter the Singer EKF/UKF of the truth's own model.
    runs, K = 300, 60
    motion, sensor, prior, truth, zs = _matched_bearings(dims, runs, K, seed=11 + dims)
    filt = NonlinearCSFilter(
        sensor, update=update, adaptation="apcs", alpha0=motion.alpha, variance="fixed", sigma_a=motion.sigma,
        sigma_min=0.0, fading="none", alpha_rule="none", mean="zero",
    )
    track = pu.run(filt, zs, prior)
    e = track.mean - truth
    nees = np.einsum("kmi,kmij,kmj->km", e, np.linalg.inv(track.cov), e)
    n = 3 * dims
    anees = nees.mean(axis=1)  # (K,)
    # The band of one step's ANEES (χ²(runs·n)/runs, two-sided 99 %); the time average lies inside it
    # when the filter is consistent (averaging only narrows its spread).
    lo, hi = stats.chi2.ppf([0.005, 0.995], runs * n) / runs
    assert lo < anees.mean() < hi, (anees.mean(), lo, hi)
    # and most single steps lie in it too
    assert np.mean((anees > lo) & (anees < hi)) > 0.9


def test_azimuth_residual_wraps_for_a_target_crossing_the_pi_line():
    # Observer near the origin, target on the −x side crossing y = 0 downwards: the azimuth jumps from
    # +π to −π.  Unwrapped residuals would be ±2π and ruin the update.
    K = 60
    obs = np.zeros((K, 2))
    obs[:, 1] = 400.0 * np.sin(2 * np.pi * np.arange(1, K + 1) / 30.0)  # a small weave for observability
    sensor = ObserverBearings(obs, 1e-3)
    x0 = np.array([-10000.0, 0.0, 0.0, 3000.0, -100.0, 0.0])
    truth = np.array([[x0[0], 0.0, 0.0, x0[3] - 100.0 * k, -100.0, 0.0] for k in range(1, K + 1)])
    z_clean = np.stack([sensor.h(truth[k], k + 1) for k in range(K)])
    assert z_clean[0, 0] > 2.8 and z_clean[-1, 0] < -2.8  # it does cross
    rng = np.random.default_rng(3)
    runs = 20
    zs = z_clean[:, None, :] + 1e-3 * rng.standard_normal((K, runs, 1))
    zs = (zs + np.pi) % (2 * np.pi) - np.pi
    prior = Gaussian(np.broadcast_to(x0, (runs, 6)).copy(), np.diag([200.0**2, 10.0**2, 1.0, 200.0**2, 10.0**2, 1.0]))
    for update in ("ekf", "ukf"):
        filt = NonlinearCSFilter(sensor, update=update, adaptation="limit", alpha0=0.05, a_max=2.0, fading="none")
        track = pu.run(filt, zs, prior, keep_info=["innovation", "nis"])
        assert np.all(np.abs(track.info["innovation"]) < 0.01), update  # never ±2π
        err = np.abs(track.mean[:, :, 3] - truth[:, None, 3])
        assert np.all(err[-10:] < 500.0), update
        assert np.nanmean(track.info["nis"]) < 3.0, update


# --------------------------------------------------------------------------
# adaptation bounds (property)
# --------------------------------------------------------------------------
@settings(max_examples=25, deadline=None)
@given(
    alpha0=st.floats(1e-3, 0.2),
    alpha_span=st.floats(1.0, 50.0),
    a_max=st.floats(0.5, 30.0),
    cap_span=st.floats(1.0, 10.0),
    threshold=st.floats(0.5, 10.0),
    jump=st.floats(0.0, 0.05),
    fading=st.sampled_from(["stf", "ratio", "none"]),
    alpha_rule=st.sampled_from(["ratio", "fading", "none"]),
    adaptation=st.sampled_from(["limit", "apcs"]),
    seed=st.integers(0, 2**16),
)
def test_adaptation_never_leaves_its_bounds(alpha0, alpha_span, a_max, cap_span, threshold, jump, fading, alpha_rule, adaptation, seed):
    K, runs = 25, 6
    sensor = ObserverBearings(_weave(K), 1e-3)
    rng = np.random.default_rng(seed)
    # angles with outliers and jumps of up to 0.05 rad: residual tests far beyond any threshold
    base = np.arctan2(7000.0 - 300.0 * np.arange(1, K + 1), 7000.0)[:, None, None]
    zs = base + 1e-3 * rng.standard_normal((K, runs, 1)) + jump * (rng.random((K, runs, 1)) < 0.3)
    filt = NonlinearCSFilter(
        sensor, adaptation=adaptation, alpha0=alpha0, alpha_cap=alpha0 * alpha_span, a_max=a_max, a_max_cap=a_max * cap_span,
        threshold=threshold, fading=fading, alpha_rule=alpha_rule, sigma_min=0.2, sigma_max=40.0,
    )
    x0 = np.array([7000.0, 0.0, 0.0, 7000.0, 0.0, 0.0])
    prior = Gaussian(np.broadcast_to(x0, (runs, 6)).copy(), np.diag(np.tile([300.0**2, 30.0**2, 4.0], 2)))
    track = pu.run(filt, zs, prior, keep_info=["alpha", "a_limit", "sigma_a2", "fading"], divergence=None)
    alpha, limit = track.info["alpha"], track.info["a_limit"]
    assert np.all(alpha >= filt.alpha0) and np.all(alpha <= filt.alpha_cap)
    assert np.all(limit >= filt.a_max) and np.all(limit <= filt.a_max_cap)
    assert np.all(track.info["fading"] >= 1.0)
    if adaptation == "apcs":
        s2 = track.info["sigma_a2"]
        assert np.all(s2 >= 0.2**2 - 1e-12) and np.all(s2 <= 40.0**2 + 1e-9)


# --------------------------------------------------------------------------
# input checks
# --------------------------------------------------------------------------
@pytest.mark.parametrize(
    "kw,field",
    [
        (dict(update="pf"), "update"),
        (dict(adaptation="fast"), "adaptation"),
        (dict(a_max=10.0, a_max_cap=5.0), "a_max_cap"),
        (dict(alpha0=0.1, alpha_cap=0.05), "alpha_cap"),
        (dict(axes=4), "axes"),
        (dict(sigma_min=2.0, sigma_max=1.0), "sigma_max"),
    ],
)
def test_bad_options_name_the_field(kw, field):
    with pytest.raises(ValueError, match=f"^{field}:"):
        NonlinearCSFilter(ObserverBearings(_weave(5), 1e-3), **kw)


def test_position_indices_must_follow_the_axis_layout():
    with pytest.raises(ValueError, match="^measurement:"):
        NonlinearCSFilter(ObserverBearings(_weave(5), 1e-3, position_indices=(0, 2)))


def test_numba_backend_compiles_the_built_in_sensors_and_warns_for_others():
    """ObserverBearings compiles without a warning (tests/compiled/test_cs_compiled.py checks the numbers); others warn by name."""
    pytest.importorskip("numba")
    import warnings

    from pursuit.compute import CompiledBackendWarning

    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert NonlinearCSFilter(ObserverBearings(_weave(5), 1e-3), backend="numba").compiled

    class MyBearings(ObserverBearings):  # a subclass may change h: not trusted
        pass

    with pytest.warns(CompiledBackendWarning, match="MyBearings"):
        filt = NonlinearCSFilter(MyBearings(_weave(5), 1e-3), backend="numba")
    assert not filt.compiled
