"""Cross-checks of the Gaussian filters against hand calculations and each other."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import pursuit as pu
from pursuit.engine.montecarlo import monte_carlo
from pursuit.models import ConstantAcceleration, ConstantVelocity, LinearGaussian
from pursuit.scenarios import LinearCV, WSNRange


@dataclass(frozen=True)
class RandomWalk:
    """A user-style 1-D random walk model: no subclassing, just the method names."""

    q: float

    def transition_matrix(self, k=None, dt=None):
        return np.array([[1.0]])

    def f(self, x, k=None, dt=None):
        return x

    def cov(self, k=None, dt=None):
        return np.array([[self.q]])


def test_kalman_filter_matches_a_hand_calculation():
    # prior N(0, 1), random walk q = 1, measurement noise r = 2, z = 3:
    # P- = 2, S = 4, K = 1/2, x = 1.5, P = 1, NIS = 9/4
    kf = pu.KalmanFilter(RandomWalk(1.0), LinearGaussian([[1.0]], [[2.0]]))
    state = kf.init(pu.Gaussian([0.0], [[1.0]]))
    state, info = kf.step(state, np.array([3.0]))
    assert state.mean == pytest.approx([1.5], abs=1e-15)
    assert state.cov[0, 0] == pytest.approx(1.0, abs=1e-15)
    assert info["innovation"] == pytest.approx([3.0])
    assert info["S"][0, 0] == pytest.approx(4.0)
    assert info["nis"] == pytest.approx(2.25)
    assert info["loglik"] == pytest.approx(-0.5 * (2.25 + np.log(4.0) + np.log(2 * np.pi)))
    # second step, z = 0: P- = 2, S = 4, K = 1/2, x = 0.75, P = 1
    state, info = kf.step(state, np.array([0.0]))
    assert state.mean == pytest.approx([0.75])
    assert state.cov[0, 0] == pytest.approx(1.0)


def test_kalman_filter_requires_linear_models():
    sc = pu.scenarios.WSNRange()
    with pytest.raises(TypeError, match="matrix"):
        pu.KalmanFilter(sc.motion, sc.measurement)


@pytest.mark.parametrize(
    "motion",
    [
        ConstantVelocity(ndim=1, dt=0.5, q=0.3),
        ConstantVelocity(ndim=2, dt=1.0, q=0.1, noise="continuous"),
        ConstantVelocity(ndim=3, dt=0.1, q=2.0, layout="derivative"),
        ConstantAcceleration(ndim=2, dt=1.0, q=0.05),
    ],
    ids=["cv1", "cv2-cont", "cv3-deriv", "ca2"],
)
@pytest.mark.parametrize("cls", [pu.ExtendedKalmanFilter, pu.UnscentedKalmanFilter, pu.CubatureKalmanFilter])
def test_nonlinear_filters_equal_the_kf_on_linear_models(motion, cls, rng):
    meas = LinearGaussian.position(motion.dim, motion.position_indices, 0.7)
    runs, K = 5, 40
    x = np.broadcast_to(np.ones(motion.dim), (runs, motion.dim))
    zs = []
    for k in range(K):
        x = motion.sample(x, k, rng)
        zs.append(meas.sample(x, k, rng))
    zs = np.array(zs)
    prior = pu.Gaussian(np.zeros(motion.dim), 4.0 * np.eye(motion.dim))
    kf = pu.run(pu.KalmanFilter(motion, meas), zs, prior)
    other = pu.run(cls(motion, meas), zs, prior)
    np.testing.assert_allclose(other.mean, kf.mean, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(other.cov, kf.cov, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(other.info["nis"], kf.info["nis"], rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("cls", [pu.UnscentedKalmanFilter, pu.CubatureKalmanFilter])
@pytest.mark.parametrize("batch", [(), (3,), (2, 3)])
def test_sigma_point_filters_predict_a_built_in_linear_model_without_points(cls, batch, monkeypatch):
    """F x, F P Fᵀ + Q, exactly symmetric, agreeing with the points' prediction of the same model given as a user's."""
    motion = ConstantVelocity(ndim=2, dt=0.7, q=0.3, noise="continuous")
    meas = LinearGaussian.position(4, motion.position_indices, 0.7)
    rng = np.random.default_rng(3)
    x = rng.standard_normal((*batch, 4))
    A = rng.standard_normal((*batch, 4, 4))
    P = A @ np.swapaxes(A, -1, -2) + 0.1 * np.eye(4)
    fast = cls(motion, meas)
    points = cls(Linear(motion.transition_matrix(), motion.cov()), meas)  # a user's model: the sigma points
    want = points._predict(x, P, 1, None)
    monkeypatch.setattr(cls, "_points", lambda *a: pytest.fail("sigma points drawn for a linear prediction"))
    got = fast._predict(x, P, 1, None)
    assert np.array_equal(got.mean, motion.f(x))
    assert np.array_equal(got.propagated, np.swapaxes(got.propagated, -1, -2))
    np.testing.assert_allclose(got.mean, want.mean, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(got.propagated, want.propagated, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(got.cross, want.cross, rtol=1e-12, atol=1e-12)
    assert got.repaired is None


@pytest.mark.parametrize("cls", [pu.UnscentedKalmanFilter, pu.CubatureKalmanFilter])
@pytest.mark.parametrize("how", ["nothing measured", "gated"])
def test_a_kept_prediction_of_a_covariance_that_needed_a_repair_is_the_repaired_one(cls, how):
    """A posterior that is not positive definite, a linear motion (predicted without points): the update's points
    repair P⁻, and a step that keeps the prediction keeps that repaired, positive-definite P⁻."""
    motion = ConstantVelocity(ndim=2, dt=1.0, q=0.1, noise="continuous")
    meas = LinearGaussian.position(4, motion.position_indices, 1.0)
    filt = cls(motion, meas, gate=0.99) if how == "gated" else cls(motion, meas)
    bad = np.diag([1.0, -2.0, 1.0, 1.0])  # F P Fᵀ + Q is not positive definite either
    state = pu.filters.GaussianState(mean=np.zeros((2, 4)), cov=np.broadcast_to(bad, (2, 4, 4)).copy(), k=0)
    z = np.full((2, 2), np.nan) if how == "nothing measured" else np.full((2, 2), 1e6)
    new, info = filt.step(state, z)
    assert info["repaired"].all()
    if how == "gated":
        assert info["gated"].all()
    assert np.all(np.linalg.eigvalsh(new.cov) > 0)
    np.testing.assert_allclose(new.cov, info["pred_cov"], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(new.mean, info["pred_mean"], rtol=0, atol=0)


@pytest.mark.parametrize("cls", [pu.filters.KalmanFilter, pu.filters.ExtendedKalmanFilter, pu.filters.UnscentedKalmanFilter])
def test_posterior_is_the_numpy_steps_mean_and_covariance_bit_for_bit(cls, rng):
    """posterior() skips the info only: mean, covariance and repair flags are numpy_step's, missing components,
    a covariance that needs a repair and a shared covariance included; None where the step does more."""
    motion = ConstantVelocity(ndim=2, dt=1.0, q=0.1, noise="continuous")
    meas = LinearGaussian.position(4, motion.position_indices, 0.5)
    filt = cls(motion, meas)
    cov = np.broadcast_to(np.eye(4), (3, 5, 4, 4)).copy()
    cov[0, 1] = np.diag([1.0, -2.0, 1.0, 1.0])  # repaired at the update's factorisation
    state = pu.filters.GaussianState(mean=rng.standard_normal((3, 5, 4)), cov=cov, k=0)
    z = rng.standard_normal((3, 5, 2))
    z[1, 2, 0] = np.nan  # one component missing
    z[2, 3] = np.nan  # nothing measured
    shared = pu.filters.GaussianState(mean=state.mean, cov=np.eye(4), k=0)
    flags = []
    for st_ in (state, shared):
        want, info = filt.numpy_step(st_, z, 1, None)
        mean, cov_out, repaired = filt.posterior(st_, z, 1)
        assert np.array_equal(mean, want.mean) and np.array_equal(cov_out, want.cov)
        assert np.array_equal(repaired, info["repaired"])
        flags.append(repaired)
    assert flags[0].shape == flags[1].shape == (3, 5) and not flags[1].any()
    if cls is pu.filters.UnscentedKalmanFilter:  # the sigma points factor P⁻, and repair it
        assert flags[0][0, 1] and flags[0].sum() == 1
    assert cls(motion, meas, gate=0.99).posterior(state, z, 1) is None
    assert cls(motion, meas, fading=pu.filters.StrongTracking()).posterior(state, z, 1) is None


def test_posterior_leaves_a_compiled_step_to_step():
    """With a compiled backend a batch of one axis runs compiled, so posterior() declines it; two axes stay NumPy."""
    pytest.importorskip("numba")
    motion = ConstantVelocity(ndim=2, dt=1.0, q=0.1, noise="continuous")
    meas = LinearGaussian.position(4, motion.position_indices, 0.5)
    filt = pu.filters.UnscentedKalmanFilter(motion, meas, backend="numba")
    z = np.random.default_rng(3).standard_normal((2, 3, 2))
    flat = pu.filters.GaussianState(mean=np.zeros((6, 4)), cov=np.broadcast_to(np.eye(4), (6, 4, 4)), k=0)
    assert filt.posterior(flat, z.reshape(6, 2), 1) is None
    grid = pu.filters.GaussianState(mean=np.zeros((2, 3, 4)), cov=np.broadcast_to(np.eye(4), (2, 3, 4, 4)), k=0)
    want, _ = filt.numpy_step(grid, z, 1, None)
    mean, cov, _ = filt.posterior(grid, z, 1)
    assert np.array_equal(mean, want.mean) and np.array_equal(cov, want.cov)


@st.composite
def stable_linear_models(draw):
    """Random linear-Gaussian models with a stable (spectral radius < 1.2) transition."""
    n = draw(st.integers(1, 4))
    m = draw(st.integers(1, 3))
    seed = draw(st.integers(0, 2**31 - 1))
    r = np.random.default_rng(seed)
    F = r.standard_normal((n, n))
    F *= draw(st.floats(0.1, 1.2)) / max(np.max(np.abs(np.linalg.eigvals(F))), 1e-9)
    A = r.standard_normal((n, n))
    Q = A @ A.T * draw(st.floats(1e-4, 10.0)) + 1e-6 * np.eye(n)
    H = r.standard_normal((m, n))
    B = r.standard_normal((m, m))
    R = B @ B.T * draw(st.floats(1e-3, 10.0)) + 1e-3 * np.eye(m)
    return F, Q, H, R, seed


@dataclass(frozen=True)
class Linear:
    F: np.ndarray
    Q: np.ndarray

    def transition_matrix(self, k=None, dt=None):
        return self.F

    def f(self, x, k=None, dt=None):
        return np.einsum("ij,...j->...i", self.F, x)

    def cov(self, k=None, dt=None):
        return self.Q


@settings(max_examples=40)
@given(stable_linear_models())
def test_covariances_stay_symmetric_positive_definite(model):
    F, Q, H, R, seed = model
    r = np.random.default_rng(seed)
    n = F.shape[0]
    zs = r.standard_normal((60, 3, H.shape[0])) * 5
    prior = pu.Gaussian(np.zeros(n), np.eye(n))
    for cls in (pu.KalmanFilter, pu.UnscentedKalmanFilter, pu.CubatureKalmanFilter):
        track = pu.run(cls(Linear(F, Q), LinearGaussian(H, R)), zs, prior)
        P = track.cov
        assert np.array_equal(P, np.swapaxes(P, -1, -2))
        assert np.all(np.linalg.eigvalsh(P) > 0), cls.__name__


@settings(max_examples=25)
@given(stable_linear_models())
def test_ukf_and_ckf_equal_kf_on_random_linear_models(model):
    F, Q, H, R, seed = model
    r = np.random.default_rng(seed)
    n = F.shape[0]
    zs = r.standard_normal((20, 2, H.shape[0]))
    prior = pu.Gaussian(r.standard_normal(n), np.eye(n))
    motion, meas = Linear(F, Q), LinearGaussian(H, R)
    kf = pu.run(pu.KalmanFilter(motion, meas), zs, prior)
    for cls in (pu.ExtendedKalmanFilter, pu.UnscentedKalmanFilter, pu.CubatureKalmanFilter):
        other = pu.run(cls(motion, meas), zs, prior)
        scale = max(1.0, float(np.max(np.abs(kf.cov))))
        np.testing.assert_allclose(other.mean, kf.mean, rtol=1e-9, atol=1e-9 * scale)
        np.testing.assert_allclose(other.cov, kf.cov, rtol=1e-9, atol=1e-9 * scale)


@pytest.mark.slow
def test_anees_inside_chi2_bounds_on_a_matched_model():
    scenario = LinearCV(ndim=2, steps=60, q=0.05, sigma=1.0)
    filters = [pu.KalmanFilter(scenario.motion, scenario.measurement), pu.UnscentedKalmanFilter(scenario.motion, scenario.measurement)]
    result = monte_carlo(scenario, filters, runs=500, seed=3)
    for name in result.filter_names:
        c = result.consistency(name)
        # runs are independent, so the per-step bounds are exact: about 95 % of steps inside
        assert c["anees_inside"] >= 0.85, (name, c)
        assert c["anis_inside"] >= 0.85, (name, c)
        assert c["anis_low"] <= c["anis"] <= c["anis_high"], (name, c)
        assert 0.95 * 4 <= c["anees"] <= 1.05 * 4, (name, c)


def test_a_mismatched_filter_fails_the_nees_test():
    # The same check must be able to fail: a filter that believes q is 100x smaller is overconfident.
    scenario = LinearCV(ndim=2, steps=60, q=0.5, sigma=1.0)
    wrong = ConstantVelocity(ndim=2, q=0.005)
    filt = pu.KalmanFilter(wrong, scenario.measurement, name="overconfident")
    result = monte_carlo(scenario, [filt], runs=200, seed=3)
    c = result.consistency("overconfident")
    assert c["anees"] > c["anees_high"]
    assert c["anees_inside"] < 0.5


def test_constant_fading_inflates_the_prediction():
    scenario = LinearCV(ndim=1, steps=5)
    sim = scenario.simulate(np.random.default_rng(0), 2)
    plain = pu.run(pu.KalmanFilter(scenario.motion, scenario.measurement), sim.measurements, sim.prior, store_predictions=True)
    faded = pu.run(
        pu.KalmanFilter(scenario.motion, scenario.measurement, fading=pu.Constant(1.5)),
        sim.measurements,
        sim.prior,
        store_predictions=True,
    )
    F, Q = scenario.motion.transition_matrix(), scenario.motion.cov()
    P0 = sim.prior.cov
    np.testing.assert_allclose(faded.info["pred_cov"][0, 0], 1.5 * F @ P0 @ F.T + Q, rtol=1e-12)
    np.testing.assert_allclose(plain.info["pred_cov"][0, 0], F @ P0 @ F.T + Q, rtol=1e-12)
    assert np.all(faded.info["fading"] == 1.5)
    with pytest.raises(ValueError, match="lam"):
        pu.Constant(0.9)


def test_infinite_measurement_is_refused():
    scenario = LinearCV(ndim=1, steps=3)
    kf = pu.KalmanFilter(scenario.motion, scenario.measurement)
    state = kf.init(pu.Gaussian([0.0, 0.0], np.eye(2)))
    with pytest.raises(ValueError, match="infinity"):
        kf.step(state, np.array([np.inf]))


def test_shared_covariance_path_equals_the_batched_path():
    # One covariance for all runs (broadcast) must give the same bits as an explicit stack.
    scenario = LinearCV(ndim=2, steps=30)
    sim = scenario.simulate(np.random.default_rng(1), 6)
    kf = pu.KalmanFilter(scenario.motion, scenario.measurement)
    shared = pu.run(kf, sim.measurements, sim.prior)
    stacked_prior = pu.Gaussian(sim.prior.mean, np.broadcast_to(sim.prior.cov, (6, 4, 4)).copy())
    stacked = pu.run(kf, sim.measurements, stacked_prior)
    np.testing.assert_array_equal(shared.mean, stacked.mean)
    np.testing.assert_array_equal(shared.cov, stacked.cov)


def test_ukf_rejects_impossible_parameters():
    sc = LinearCV(ndim=1)
    with pytest.raises(ValueError, match="alpha"):
        pu.UnscentedKalmanFilter(sc.motion, sc.measurement, alpha=0.0)
    # n + κ ≤ 0 leaves no sigma points: refused at construction, naming kappa
    with pytest.raises(ValueError, match="kappa: must exceed -n = -2"):
        pu.UnscentedKalmanFilter(sc.motion, sc.measurement, alpha=0.1, kappa=-2.5)
    pu.UnscentedKalmanFilter(sc.motion, sc.measurement, kappa=-1.5)  # n + κ = 0.5 is fine

    class NoDim:  # a user's motion model that does not state its dimension
        f = staticmethod(sc.motion.f)
        cov = staticmethod(sc.motion.cov)

    ukf = pu.UnscentedKalmanFilter(NoDim(), sc.measurement, alpha=0.1, kappa=-2.5)
    with pytest.raises(ValueError, match="n \\+ lambda"):  # then the first step says so
        pu.run(ukf, np.zeros((2, 1, 1)), pu.Gaussian([0.0, 0.0], np.eye(2)))


def test_filter_rejects_objects_that_are_not_models():
    with pytest.raises(TypeError, match="f\\(\\)"):
        pu.ExtendedKalmanFilter(object(), LinearGaussian([[1.0]], [[1.0]]))



_GAUSSIAN = [pu.KalmanFilter, pu.ExtendedKalmanFilter, pu.UnscentedKalmanFilter, pu.CubatureKalmanFilter]


def _scenario_for(cls, steps):
    if cls is pu.KalmanFilter:
        return LinearCV(ndim=2, steps=steps, sigma=1.0)
    return WSNRange(steps=steps)


@pytest.mark.parametrize("cls", _GAUSSIAN, ids=lambda c: c.__name__)
def test_a_prior_covariance_too_large_for_the_measurement_noise_is_refused_naming_prior_cov(cls):
    # A prior covariance of 1e20·I: R = 1 is lost in S = H P Hᵀ + R ≈ 1e20 (float64 keeps 52 bits), and
    # the filters used to give non-positive-definite covariances and negative NIS, unflagged, and
    # UKF/CKF estimates 1e7 m off.
    scenario = _scenario_for(cls, 5)
    sim = scenario.simulate(np.random.default_rng(3), 4)
    filt = cls(scenario.motion, scenario.measurement, backend="numpy")
    huge = pu.Gaussian(sim.prior.mean, 1e20 * np.eye(4))
    with pytest.raises(ValueError, match=r"^prior\.cov: too large for the measurement noise: measurement component \d would have a "
                       r"predicted variance H P Hᵀ = \S+, \S+ times its noise variance R = 1, beyond 2\^48 .* scale the prior covariance by at most"):
        pu.run(filt, sim.measurements, huge)


@pytest.mark.parametrize("cls", _GAUSSIAN, ids=lambda c: c.__name__)
def test_a_large_prior_within_the_limit_gives_positive_definite_covariances_and_nonnegative_nis(cls):
    # 1e13 m² (H P Hᵀ / R ≤ 1e13 < 2^48): the filters track as from the usual prior.
    scenario = _scenario_for(cls, 40)
    sim = scenario.simulate(np.random.default_rng(3), 6)
    filt = cls(scenario.motion, scenario.measurement, backend="numpy")
    wide = pu.run(filt, sim.measurements, pu.Gaussian(sim.prior.mean, 1e13 * np.eye(4)))
    usual = pu.run(filt, sim.measurements, sim.prior)
    np.linalg.cholesky(wide.cov)  # every covariance of every step and run is positive definite
    assert np.all(wide.info["nis"] >= 0) and not wide.info["repaired"].any()
    pos = [0, 2]
    err = (wide.mean[-1] - sim.truth[-1])[:, pos]
    sd = np.sqrt(np.diagonal(wide.cov[-1], axis1=-2, axis2=-1)[:, pos])
    assert np.all(np.abs(err) < 5 * sd)  # consistent with its covariance
    usual_err = np.abs(usual.mean[-1] - sim.truth[-1])[:, pos]
    assert np.abs(err).max() < 2 * usual_err.max()  # as close as from the usual prior (a different prior: not equal)


@pytest.mark.parametrize("backend", ["numpy", "numba"])
@pytest.mark.parametrize("cls", [*_GAUSSIAN, pu.BootstrapParticleFilter], ids=lambda c: c.__name__)
def test_a_time_step_too_long_for_the_motion_model_is_refused_naming_the_step(cls, backend):
    # dt = 1e300 raised OverflowError ("Numerical result out of range") from every filter and backend
    pytest.importorskip("numba") if backend == "numba" else None
    scenario = _scenario_for(cls, 3)
    kw = {"particles": 50} if cls is pu.BootstrapParticleFilter else {}
    filt = cls(scenario.motion, scenario.measurement, backend=backend, **kw)
    state = filt.init(pu.Gaussian(scenario.x0, scenario.P0), batch=(2,), rng=np.random.default_rng(0))
    z = scenario.simulate(np.random.default_rng(1), 2).measurements[0]
    for zk in (z, np.full_like(z, np.nan)):
        with pytest.raises(ValueError, match=r"^step 1: dt: 1e\+300 s is beyond 2\^200"):
            filt.step(state, zk, dt=1e300)


class _RunsFastestRange(pu.models.RangeSensors):
    """One range, returned with the runs as the fastest-varying axis (a layout a user's ``h`` may give)."""

    def h(self, x, k=None):
        return np.asfortranarray(super().h(x, k))


@pytest.mark.parametrize("kind", ["UKF", "CKF"])
def test_sigma_point_update_is_batch_invariant_whatever_the_layout_of_h(kind):
    """The small per-run GEMMs of the statistical linearisation see one layout whatever the batch: a run gives
    the same bits alone as among nine others, also when ``h`` returns a Fortran-ordered array."""
    motion = ConstantVelocity(ndim=2, dt=1.0, q=0.05, noise="continuous")
    meas = _RunsFastestRange([[0.0, 0.0]], 0.5)
    cls = pu.UnscentedKalmanFilter if kind == "UKF" else pu.CubatureKalmanFilter
    filt = cls(motion, meas, backend="numpy")
    rng = np.random.default_rng(4)
    prior = pu.Gaussian(np.array([30.0, 1.0, 40.0, -0.5]), np.diag([4.0, 0.5, 4.0, 0.5]))
    zs = 50.0 + rng.standard_normal((6, 10, 1))
    many, one = filt.init(prior, batch=(10,)), filt.init(prior, batch=(1,))
    for z in zs:
        many, _ = filt.step(many, z)
        one, _ = filt.step(one, z[7:8])
        assert np.array_equal(one.mean[0], many.mean[7]) and np.array_equal(one.cov[0], many.cov[7])
