"""Cross-checks of the bootstrap particle filter."""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np
import pytest
from scipy.special import logsumexp

import pursuit as pu
from pursuit.engine.montecarlo import monte_carlo
from pursuit.engine.snapshots import particle_snapshots
from pursuit.filters.particle import BootstrapParticleFilter, weighted_moments
from pursuit.models import LinearGaussian, gaussian_loglik
from pursuit.rng import run_streams
from pursuit.scenarios import WSNRange
from pursuit.scenarios.ungm import UNGM


@dataclass(frozen=True)
class RandomWalk:
    """1-D random walk, a user-style model (no subclassing)."""

    q: float = 1.0
    dim = 1

    def transition_matrix(self, k=None, dt=None):
        return np.array([[1.0]])

    def f(self, x, k=None, dt=None):
        return np.asarray(x, dtype=float)

    def cov(self, k=None, dt=None):
        return np.array([[self.q]])

    def sample(self, x, k, rng, dt=None):
        return np.asarray(x, dtype=float) + np.sqrt(self.q) * rng.standard_normal(np.shape(x))


def _random_walk_data(runs=50, K=30, seed=3):
    motion, meas = RandomWalk(1.0), LinearGaussian([[1.0]], [[1.0]])
    g = np.random.default_rng(seed)
    x = np.zeros((runs, 1))
    zs = []
    for k in range(K):
        x = motion.sample(x, k, g)
        zs.append(meas.sample(x, k, g))
    return motion, meas, np.array(zs), pu.Gaussian([0.0], [[1.0]])


def test_sir_converges_to_the_kalman_filter_as_one_over_sqrt_n():
    motion, meas, zs, prior = _random_walk_data()
    kf = pu.run(pu.KalmanFilter(motion, meas), zs, prior)
    sigma = float(np.sqrt(kf.cov[..., 0, 0]).mean())
    errors = []
    for N in (250, 1000, 4000):
        pf = pu.run(BootstrapParticleFilter(motion, meas, particles=N), zs, prior, rng=run_streams(4, range(zs.shape[1]), 1))
        errors.append(float(np.abs(pf.mean - kf.mean).mean()))
    # Monte Carlo error ~ 1/sqrt(N): each fourfold N should halve it.  The mean over
    # 50 runs x 30 steps makes the ratios precise to a few per cent.
    ratios = np.array(errors[:-1]) / np.array(errors[1:])
    assert np.all((ratios > 1.6) & (ratios < 2.5)), (errors, ratios)
    # spec 01 §9: N = 5000-ish within 0.05 sigma of the KF mean
    assert errors[-1] < 0.05 * sigma


def test_pf_loglik_estimates_the_kalman_loglik():
    motion, meas, zs, prior = _random_walk_data()
    kf = pu.run(pu.KalmanFilter(motion, meas), zs, prior)
    pf = pu.run(BootstrapParticleFilter(motion, meas, particles=20000), zs, prior, rng=run_streams(4, range(zs.shape[1]), 1))
    total_kf = kf.info["loglik"].sum(axis=0)
    total_pf = pf.info["loglik"].sum(axis=0)
    # the PF's estimate of log p(z_1:K) is within a few hundredths of the exact value
    assert np.abs(total_pf - total_kf).mean() < 0.05
    # S is a particle spread plus R: about 1 % Monte Carlo error on average at N = 20 000
    rel = np.abs(pf.info["S"] / kf.info["S"] - 1.0)
    assert rel.mean() < 0.01 and rel.max() < 0.1


def test_one_step_matches_a_hand_computation():
    motion, meas = RandomWalk(0.5), LinearGaussian([[1.0]], [[2.0]])
    filt = BootstrapParticleFilter(motion, meas, particles=50, ess_threshold=0.0)
    g = np.random.default_rng(5)
    state = filt.init(pu.Gaussian([1.0], [[3.0]]), batch=(2,), rng=g)
    X0 = state.particles.copy()
    g_copy = copy.deepcopy(g)
    z = np.array([[1.7], [0.2]])
    state, info = filt.step(state, z)
    X1 = motion.sample(X0, 1, g_copy)
    ll = meas.loglik(z[:, None, :], X1)
    w = np.exp(ll - logsumexp(ll, axis=-1, keepdims=True))
    np.testing.assert_allclose(info["loglik"], logsumexp(ll, axis=-1) - np.log(50), rtol=1e-12)
    np.testing.assert_allclose(state.mean, np.einsum("mp,mpi->mi", w, X1), rtol=1e-12)
    zhat = X1[..., 0].mean(axis=-1)
    S = X1[..., 0].var(axis=-1) + 2.0
    np.testing.assert_allclose(info["innovation"][:, 0], z[:, 0] - zhat, rtol=1e-12)
    np.testing.assert_allclose(info["S"][:, 0, 0], S, rtol=1e-12)
    np.testing.assert_allclose(info["ess"], 1.0 / (w**2).sum(axis=-1), rtol=1e-12)
    np.testing.assert_allclose(state.logw, np.log(w), rtol=1e-12)  # never resampled
    assert not info["resampled"].any()


class Gate:
    """A bounded likelihood: zero unless |z − x| < 1; returns NaN for z > 100."""

    dim = 1

    def h(self, x, k=None):
        return np.asarray(x, dtype=float)

    def cov(self, k=None):
        return np.eye(1)

    def loglik(self, z, x, k=None):
        d = np.abs(z - x)[..., 0]
        out = np.where(d < 1.0, 0.0, -np.inf)
        return np.where(z[..., 0] > 100, np.nan, out)


def test_all_zero_likelihoods_keep_the_predictive_weights_and_flag_it():
    filt = BootstrapParticleFilter(RandomWalk(0.01), Gate(), particles=200, ess_threshold=0.5)
    state = filt.init(pu.Gaussian([0.0], [[1.0]]), batch=(3,), rng=np.random.default_rng(2))
    state, info = filt.step(state, np.array([[0.3], [0.1], [-0.2]]))  # ordinary step: weights vary
    prior_logw = state.logw.copy()
    g_copy = copy.deepcopy(state.rng)
    X_prop = RandomWalk(0.01).sample(state.particles, 2, g_copy)
    z = np.array([[50.0], [0.0], [500.0]])  # run 0: no particle within the gate; run 2: NaN likelihoods
    state, info = filt.step(state, z)
    np.testing.assert_array_equal(info["weights_reset"], [True, False, True])
    assert np.all(np.isfinite(state.mean))
    assert info["loglik"][0] == -np.inf and info["loglik"][2] == -np.inf and np.isfinite(info["loglik"][1])
    for i in (0, 2):  # the estimate is the predictive mean under the previous weights
        w = np.exp(prior_logw[i])
        np.testing.assert_allclose(state.mean[i], w @ X_prop[i], rtol=1e-10)
    state, info = filt.step(state, np.array([[0.0], [0.0], [0.0]]))  # and the filter goes on
    assert np.all(np.isfinite(state.mean))


def test_a_nan_likelihood_of_one_particle_counts_as_zero():
    class HalfNaN(Gate):
        def loglik(self, z, x, k=None):
            out = -0.5 * ((z - x)[..., 0]) ** 2
            out[..., ::2] = np.nan
            return out

    filt = BootstrapParticleFilter(RandomWalk(1.0), HalfNaN(), particles=10, ess_threshold=0.0)
    state = filt.init(pu.Gaussian([0.0], [[1.0]]), batch=(1,), rng=np.random.default_rng(0))
    state, info = filt.step(state, np.array([[0.5]]))
    w = state.weights[0]
    assert np.all(w[::2] == 0) and np.all(w[1::2] > 0) and w.sum() == pytest.approx(1.0)
    assert not info["weights_reset"].any()


def test_missing_measurement_keeps_the_weights_and_does_not_resample():
    sc = UNGM(steps=4)
    filt = BootstrapParticleFilter(sc.motion, sc.measurement, particles=100, ess_threshold=0.5)
    sim = sc.simulate(run_streams(1, range(3), 0), 3)
    state = filt.init(sim.prior, rng=run_streams(1, range(3), 1))
    state, _ = filt.step(state, sim.measurements[0])
    before = state.logw.copy()
    g_copy = copy.deepcopy(state.rng)
    X_prop = sc.motion.sample(state.particles, 2, g_copy)
    state, info = filt.step(state, np.full((3, 1), np.nan))
    np.testing.assert_array_equal(state.logw, before)
    np.testing.assert_array_equal(state.particles, X_prop)
    assert not info["resampled"].any()
    np.testing.assert_allclose(state.mean, np.einsum("mp,mpi->mi", np.exp(before), X_prop), rtol=1e-12)


@pytest.mark.parametrize("resampler", ["systematic", "multinomial"])
def test_results_do_not_depend_on_the_chunking_bit_for_bit(resampler):
    sc = UNGM(steps=15)
    filt = BootstrapParticleFilter(sc.motion, sc.measurement, particles=300, resampler=resampler, ess_threshold=0.5)
    _assert_chunking_changes_no_bit(sc, filt, 7, (2,), seed=5)


@pytest.mark.parametrize("kind", ["pf", "cs-pf"])
def test_components_no_run_measured_change_no_bit_whatever_the_chunk(kind):
    """A 16-node WSN whose nodes range within 60 m: the likelihoods leave out the nodes no run of the chunk
    measured, with the bits of the full width, so a run's results do not depend on which runs share its chunk."""
    from pursuit.config.build import build_filter

    grid = [[x, y] for y in (5.0, 55.0, 105.0, 155.0) for x in (-40.0, 10.0, 60.0, 110.0)]
    sc = WSNRange(steps=12, anchors=grid, sensing_radius=60.0, p_detect=0.9)
    filt = build_filter({"type": kind, "particles": 100}, sc, "filters[0]")
    whole = monte_carlo(sc, [filt], runs=6, seed=11)
    unmeasured = np.isnan(whole.measurements)  # (steps, runs, nodes)
    assert unmeasured.all(axis=1).any(axis=-1).all()  # every step, nodes that no run measured: left out
    assert (unmeasured[:, :1].all(axis=1) != unmeasured.all(axis=1)).any()  # a chunk of one run leaves out more
    # the narrow likelihoods are the full-width ones, bit for bit
    X = np.random.default_rng(2).normal([30.0, 1.0, 80.0, 0.5], 20.0, (6, 100, 4))
    z = whole.measurements[3]
    valid = ~np.isnan(z)
    Zp, ll, const = filt._likelihoods(X, z, 3, valid, valid.any(axis=-1))
    full = gaussian_loglik(z[:, None, :] - sc.measurement.h(X, 3), sc.measurement.cov(3))
    assert const == 0.0 and np.array_equal(ll, full) and Zp.shape == (6, 100, 16)
    # the cuckoo searches' fitness asks for no predicted measurements: only the ranges some run measured
    Zp_none, ll_fit, _ = filt._likelihoods(X, z, 3, valid, valid.any(axis=-1), predicted=False)
    assert Zp_none is None and np.array_equal(ll_fit, ll)
    _assert_chunking_changes_no_bit(sc, filt, 6, (1, 4))


def _assert_chunking_changes_no_bit(sc, filt, runs, chunks, seed=11):
    """The filter's results on ``runs`` runs in one chunk equal those in chunks of each size in ``chunks``, bit for bit."""
    whole = monte_carlo(sc, [filt], runs=runs, seed=seed, chunk_size=runs)
    for chunk in chunks:
        parts = monte_carlo(sc, [filt], runs=runs, seed=seed, chunk_size=chunk)
        a, b = whole.filters[filt.name], parts.filters[filt.name]
        np.testing.assert_array_equal(a.estimates, b.estimates)
        np.testing.assert_array_equal(a.covariances, b.covariances)
        for key in a.info:
            np.testing.assert_array_equal(a.info[key], b.info[key], err_msg=key)


@pytest.mark.parametrize("kind", ["pf", "cs-pf"])
def test_a_run_that_measured_everything_keeps_its_bits_beside_runs_that_did_not(kind):
    """One node heard with probability 0.9 (p1-wsn's first variant): in a chunk, some runs measured and some
    did not; each run's log-likelihood arithmetic is chosen by what it measured, not by its chunk-mates."""
    from pursuit.config.build import build_filter

    sc = WSNRange(steps=20, anchors=[[0.0, 0.0]], sensing_radius=60.0, p_detect=0.9)
    filt = build_filter({"type": kind, "particles": 60}, sc, "filters[0]")
    z = monte_carlo(sc, [filt], runs=8, seed=11).measurements
    mixed = np.isnan(z[..., 0]).any(axis=1) & ~np.isnan(z[..., 0]).all(axis=1)
    assert mixed.sum() >= 3  # steps where some runs measured and some did not
    _assert_chunking_changes_no_bit(sc, filt, 8, (1, 3))


def test_a_full_measurement_covariance_refuses_missing_components_whatever_the_chunk():
    """Only a diagonal R lets the filters leave components out; with a full R a missing component is refused
    (gaussian_loglik's ValueError) whether or not the other runs measured it."""
    R = np.array([[1.0, 0.3, 0.0], [0.3, 1.0, 0.0], [0.0, 0.0, 1.0]])
    meas = LinearGaussian(np.eye(3), R)
    filt = BootstrapParticleFilter(RandomWalk3(), meas, particles=20)
    for runs in (1, 2, 3):
        state = filt.init(pu.Gaussian(np.zeros(3), np.eye(3)), batch=(runs,), rng=np.random.default_rng(0))
        z = np.zeros((runs, 3))
        z[:, 2] = np.nan  # missing in every run: could be left out, but R is not diagonal
        if runs == 3:
            z[2, 2] = 0.5
        with pytest.raises(ValueError, match="diagonal"):
            filt.step(state, z)


@dataclass(frozen=True)
class RandomWalk3:
    """3-D random walk (user-style)."""

    dim = 3

    def f(self, x, k=None, dt=None):
        return np.asarray(x, dtype=float)

    def cov(self, k=None, dt=None):
        return np.eye(3)

    def sample(self, x, k, rng, dt=None):
        return np.asarray(x, dtype=float) + rng.standard_normal(np.shape(x))


def test_ess_threshold_controls_resampling():
    sc = UNGM(steps=20)
    sim = sc.simulate(run_streams(2, range(5), 0), 5)
    never = pu.run(BootstrapParticleFilter(sc.motion, sc.measurement, particles=200, ess_threshold=0.0), sim.measurements, sim.prior, rng=1)
    always = pu.run(BootstrapParticleFilter(sc.motion, sc.measurement, particles=200), sim.measurements, sim.prior, rng=1)
    half = pu.run(BootstrapParticleFilter(sc.motion, sc.measurement, particles=200, ess_threshold=0.5), sim.measurements, sim.prior, rng=1)
    assert not never.info["resampled"].any()
    assert always.info["resampled"].all()
    np.testing.assert_array_equal(half.info["resampled"], half.info["ess"] < 100)
    assert np.all(always.info["ess"] <= 200 + 1e-9) and np.all(always.info["ess"] >= 1 - 1e-9)


def test_weighted_moments_ignore_nonfinite_particles_of_zero_weight():
    X = np.array([[[1.0, 2.0], [np.nan, np.inf], [3.0, 4.0]]])
    e = np.array([[1.0, 0.0, 1.0]])
    mean, cov = weighted_moments(X, e)
    np.testing.assert_allclose(mean, [[2.0, 3.0]])
    np.testing.assert_allclose(cov, [[[1.0, 1.0], [1.0, 1.0]]])


def test_snapshots_reproduce_a_monte_carlo_run():
    sc = UNGM(steps=12)
    filt = BootstrapParticleFilter(sc.motion, sc.measurement, particles=50)
    result = monte_carlo(sc, [filt], runs=4, seed=8)
    sim = sc.simulate(run_streams(8, [2], 0), 1)
    snaps = particle_snapshots(filt, sim.measurements, sim.prior, run_streams(8, [2], 1), [3, 12, 40])
    assert sorted(snaps) == [3, 12]
    np.testing.assert_array_equal(snaps[12]["mean"][0], result.filters["PF"].estimates[11, 2])
    assert snaps[3]["particles"].shape == (1, 50, 1)


def test_bad_parameters_are_refused():
    sc = UNGM()
    with pytest.raises(ValueError, match="particles"):
        BootstrapParticleFilter(sc.motion, sc.measurement, particles=0)
    with pytest.raises(ValueError, match="ess_threshold"):
        BootstrapParticleFilter(sc.motion, sc.measurement, ess_threshold=1.5)
    with pytest.raises(ValueError, match="resampler"):
        BootstrapParticleFilter(sc.motion, sc.measurement, resampler="magic")
    with pytest.raises(TypeError, match="sample"):
        BootstrapParticleFilter(object(), sc.measurement)
    filt = BootstrapParticleFilter(sc.motion, sc.measurement, particles=10)
    state = filt.init(pu.Gaussian([0.0], [[1.0]]), batch=(2,), rng=0)
    with pytest.raises(ValueError, match="infinity"):
        filt.step(state, np.array([[np.inf], [0.0]]))


@pytest.mark.slow
def test_pf_improves_with_more_particles_on_ungm():
    # Paper P1 §6 expects the PF to improve as N grows; shown here with a paired
    # run-by-run comparison over the p1-ungm set-up (100 runs, 50 steps).
    from pursuit.experiments.sweep import paired_difference, run_metric

    sc = UNGM(steps=50)
    errs = {}
    for N in (30, 100):
        res = monte_carlo(sc, [BootstrapParticleFilter(sc.motion, sc.measurement, particles=N)], runs=100, seed=20220701)
        errs[N] = run_metric(res, "PF", "state", "per-run")[0]
    mean, half, verdict = paired_difference(errs[100], errs[30])
    assert verdict == "A < B", (mean, half)


def test_nis_of_a_non_finite_or_singular_spread_is_nan_not_an_error():
    from pursuit.filters.particle import _safe_inverse

    S = np.stack([np.diag([2.0, 1.0, 4.0, 1.0]), np.full((4, 4), 1.0), np.diag([np.inf, 1.0, 1.0, 1.0])])
    inv = _safe_inverse(S)
    np.testing.assert_allclose(inv[0], np.linalg.inv(S[0]))
    assert np.all(np.isnan(inv[1])) and np.all(np.isnan(inv[2]))


@pytest.mark.xfail(strict=False, reason=(  # not strict: other CPUs may happen to agree
    "known, not fixed (2026-12-05): NumPy's einsum '...i,...i->...' over more than 8192 particles gives a "
    "batch of one run other bits than the same row in a larger batch (its buffered reduction), so a chunk "
    "of one run of a PF with N > 8192 differs at round-off from that run in a larger chunk"
))
def test_a_lone_run_with_many_particles_has_the_bits_it_has_in_a_batch():
    sc = UNGM(steps=3)
    filt = BootstrapParticleFilter(sc.motion, sc.measurement, particles=20000)
    a = monte_carlo(sc, [filt], runs=3, seed=5, chunk_size=3).filters["PF"]
    b = monte_carlo(sc, [filt], runs=3, seed=5, chunk_size=1).filters["PF"]
    np.testing.assert_array_equal(a.estimates, b.estimates)
