"""Cross-checks of the partial-UKF unscented particle filter."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.special import logsumexp

import pursuit as pu
from pursuit.filters.particle import BootstrapParticleFilter
from pursuit.filters.upf import JitteredMotion, PartialUPF, full_rank_motion
from pursuit.models import ConstantVelocity, LinearGaussian
from pursuit.rng import run_streams
from pursuit.scenarios import LinearCV, WSNRange
from pursuit.scenarios.ungm import UNGM


@pytest.mark.parametrize("scenario", [UNGM(steps=25), WSNRange(steps=25, noise="continuous")], ids=["ungm", "wsn-cwna"])
def test_l_zero_is_the_bootstrap_pf_with_ess_resampling_bit_for_bit(scenario):
    runs = 4
    sim = scenario.simulate(run_streams(3, range(runs), 0), runs)
    upf = PartialUPF(scenario.motion, scenario.measurement, particles=150, fraction=0.0)
    sir = BootstrapParticleFilter(scenario.motion, scenario.measurement, particles=150, ess_threshold=0.5)
    a = pu.run(upf, sim.measurements, sim.prior, rng=run_streams(3, range(runs), 1))
    b = pu.run(sir, sim.measurements, sim.prior, rng=run_streams(3, range(runs), 1))
    np.testing.assert_array_equal(a.mean, b.mean)
    np.testing.assert_array_equal(a.cov, b.cov)
    for key in ("nis", "loglik", "ess", "resampled"):
        np.testing.assert_array_equal(a.info[key], b.info[key], err_msg=key)


def test_with_point_particles_the_ukf_proposal_is_the_optimal_one():
    # Linear-Gaussian model, l = 1, particle covariances ~ 0: the UKF proposal is
    # p(x_k | x_{k-1}, z_k), so loglik + logtrans − logq = log N(z; H F x_{k-1}, H Q Hᵀ + R)
    # for every particle, whatever was sampled (spec 02 §9).
    motion = ConstantVelocity(ndim=1, dt=1.0, q=0.5, noise="continuous")
    meas = LinearGaussian.position(2, (0,), 0.7)
    filt = PartialUPF(motion, meas, particles=40, fraction=1.0, ess_threshold=0.0)
    state = filt.init(pu.Gaussian([0.0, 1.0], np.diag([4.0, 1.0])), batch=(3,), rng=np.random.default_rng(1))
    n = 2
    state = type(state)(**{**state.__dict__, "particle_cov": np.broadcast_to(1e-12 * np.eye(n), (3, 40, n, n))})
    X_prev = state.particles
    z = np.array([[0.4], [2.0], [-1.0]])
    state, info = filt.step(state, z)
    F, Q, H, R = motion.transition_matrix(), motion.cov(), meas.matrix(), meas.cov()
    mu = np.einsum("ij,...j->...i", H @ F, X_prev)
    S = H @ Q @ H.T + R
    expected = -0.5 * ((z[:, None, :] - mu) ** 2 / S[0, 0]).sum(axis=-1) - 0.5 * np.log(2 * np.pi * S[0, 0])
    expected_logw = expected - logsumexp(expected, axis=-1, keepdims=True)
    np.testing.assert_allclose(state.logw, expected_logw, atol=1e-6)
    # and the likelihood increment is the exact predictive likelihood averaged over particles
    np.testing.assert_allclose(info["loglik"], logsumexp(expected, axis=-1) - np.log(40), atol=1e-6)


def test_more_ukf_particles_help_on_a_well_observed_linear_model():
    # On a linear-Gaussian model with a precise sensor the UKF proposal is close to the
    # optimal one, so the effective sample size grows with l.
    sc = LinearCV(ndim=1, steps=30, q=1.0, sigma=0.1)
    motion = ConstantVelocity(ndim=1, q=1.0, noise="continuous")
    runs = 20
    sim = sc.simulate(run_streams(4, range(runs), 0), runs)
    ess = []
    for l in (0.0, 1.0):
        filt = PartialUPF(motion, sc.measurement, particles=100, fraction=l, ess_threshold=0.0)
        tr = pu.run(filt, sim.measurements, sim.prior, rng=run_streams(4, range(runs), 1))
        ess.append(tr.info["ess"][1:].mean())
    assert ess[1] > 2 * ess[0], ess


def test_singular_process_noise_is_replaced_by_a_full_rank_one():
    cv = ConstantVelocity(ndim=2, q=0.01)  # discrete: rank 2 of 4
    cwna = full_rank_motion(cv, "cwna")
    assert cwna.noise == "continuous" and cwna.q == cv.q
    jit = full_rank_motion(cv, "jitter", jitter=1e-4)
    assert isinstance(jit, JitteredMotion)
    np.testing.assert_allclose(jit.cov(), cv.cov() + 1e-4 * np.eye(4))
    assert np.all(np.linalg.eigvalsh(jit.cov()) > 0)
    full = ConstantVelocity(ndim=2, q=0.01, noise="continuous")
    assert full_rank_motion(full) is full
    filt = PartialUPF(cv, WSNRange().measurement, particles=10)
    assert filt.model.noise == "continuous"


def test_selection_rounding_and_bad_parameters():
    sc = UNGM()
    assert PartialUPF(sc.motion, sc.measurement, particles=10, fraction=0.25).n_ukf == 3  # 2.5 rounds up
    assert PartialUPF(sc.motion, sc.measurement, particles=10, fraction=0.25, rounding="floor").n_ukf == 2
    assert PartialUPF(sc.motion, sc.measurement, particles=10, fraction=0.21, rounding="ceil").n_ukf == 3
    for kw, field in (({"fraction": 1.5}, "fraction"), ({"select": "best"}, "select"), ({"cov_mode": "x"}, "cov_mode")):
        with pytest.raises(ValueError, match=field):
            PartialUPF(sc.motion, sc.measurement, **kw)


@pytest.mark.parametrize("select", ["weight", "random", "block"])
@pytest.mark.parametrize("cov_mode", ["population", "propagate", "reset"])
def test_every_selection_and_covariance_mode_runs_and_is_batch_invariant(select, cov_mode):
    sc = WSNRange(steps=8)
    runs = 3
    sim = sc.simulate(run_streams(5, range(runs), 0), runs)
    filt = PartialUPF(sc.motion, sc.measurement, particles=30, fraction=0.4, select=select, cov_mode=cov_mode)
    batch = pu.run(filt, sim.measurements, sim.prior, rng=run_streams(5, range(runs), 1))
    assert np.all(np.isfinite(batch.mean))
    assert np.all(batch.info["n_ukf"] == 12)
    one = pu.run(filt, sim.measurements[:, 1:2], pu.Gaussian(sim.prior.mean[1:2], sim.prior.cov), rng=run_streams(5, [1], 1))
    np.testing.assert_array_equal(one.mean[:, 0], batch.mean[:, 1])
