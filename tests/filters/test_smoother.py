"""RTS smoother against the exact batch solution and across filters."""

import numpy as np
import pytest

import pursuit as pu
from pursuit.scenarios import LinearCV, WSNRange


def _batch_posterior(F, Q, H, R, m0, P0, zs):
    """Posterior mean and covariance of x_1..x_K given z_1..z_K by solving the joint Gaussian."""
    K, n = zs.shape[0], F.shape[0]
    # x = A w with w = [x0, w_1..w_K]: x_k = F x_{k-1} + w_k
    A = np.zeros((K * n, (K + 1) * n))
    for k in range(K):
        for j in range(k + 2):
            A[k * n : (k + 1) * n, j * n : (j + 1) * n] = np.linalg.matrix_power(F, k + 1 - j) if j else np.linalg.matrix_power(F, k + 1)
    Pw = np.zeros(((K + 1) * n, (K + 1) * n))
    Pw[:n, :n] = P0
    for k in range(1, K + 1):
        Pw[k * n : (k + 1) * n, k * n : (k + 1) * n] = Q
    mw = np.zeros((K + 1) * n)
    mw[:n] = m0
    mx, Px = A @ mw, A @ Pw @ A.T
    Hb = np.kron(np.eye(K), H)
    Rb = np.kron(np.eye(K), R)
    S = Hb @ Px @ Hb.T + Rb
    G = Px @ Hb.T @ np.linalg.inv(S)
    mean = mx + G @ (zs.reshape(-1) - Hb @ mx)
    cov = Px - G @ Hb @ Px
    return mean.reshape(K, n), np.array([cov[k * n : (k + 1) * n, k * n : (k + 1) * n] for k in range(K)])


def test_kf_smoother_equals_the_batch_posterior():
    sc = LinearCV(ndim=1, steps=8, q=0.3, sigma=0.8, P0=np.diag([2.0, 0.5]))
    sim = sc.simulate(np.random.default_rng(4), 1)
    track = pu.run(pu.KalmanFilter(sc.motion, sc.measurement), sim.measurements, sim.prior, store_predictions=True)
    sm = pu.rts_smooth(track)
    F, Q = sc.motion.transition_matrix(), sc.motion.cov()
    H, R = sc.measurement.matrix(), sc.measurement.cov()
    mean, cov = _batch_posterior(F, Q + 1e-12 * np.eye(2), H, R, sim.prior.mean[0], sim.prior.cov, sim.measurements[:, 0])
    np.testing.assert_allclose(sm.mean[:, 0], mean, rtol=1e-6, atol=1e-8)
    np.testing.assert_allclose(sm.cov[:, 0], cov, rtol=1e-6, atol=1e-8)
    # the last smoothed estimate is the filtered one
    np.testing.assert_array_equal(sm.mean[-1], track.mean[-1])


@pytest.mark.parametrize("cls", [pu.ExtendedKalmanFilter, pu.UnscentedKalmanFilter, pu.CubatureKalmanFilter])
def test_other_smoothers_equal_the_kf_smoother_on_linear_models(cls):
    sc = LinearCV(ndim=2, steps=20)
    sim = sc.simulate(np.random.default_rng(2), 3)
    ref = pu.rts_smooth(pu.run(pu.KalmanFilter(sc.motion, sc.measurement), sim.measurements, sim.prior, store_predictions=True))
    other = pu.rts_smooth(pu.run(cls(sc.motion, sc.measurement), sim.measurements, sim.prior, store_predictions=True))
    np.testing.assert_allclose(other.mean, ref.mean, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(other.cov, ref.cov, rtol=1e-9, atol=1e-9)


def test_smoothing_reduces_the_error_on_a_nonlinear_scenario():
    sc = WSNRange(steps=40)
    sim = sc.simulate(np.random.default_rng(8), 200)
    track = pu.run(pu.UnscentedKalmanFilter(sc.motion, sc.measurement), sim.measurements, sim.prior, store_predictions=True)
    sm = pu.rts_smooth(track)
    err_f = np.mean((track.mean - sim.truth) ** 2)
    err_s = np.mean((sm.mean - sim.truth) ** 2)
    assert err_s < 0.8 * err_f


def test_smoother_needs_predictions():
    sc = LinearCV(ndim=1, steps=3)
    sim = sc.simulate(np.random.default_rng(0), 1)
    track = pu.run(pu.KalmanFilter(sc.motion, sc.measurement), sim.measurements, sim.prior)
    with pytest.raises(ValueError, match="store_predictions"):
        pu.rts_smooth(track)


@pytest.mark.parametrize("kind", ["pf", "imm"])
def test_smoother_refuses_filters_it_has_no_smoother_for(kind):
    sc = LinearCV(ndim=1, steps=4)
    sim = sc.simulate(np.random.default_rng(0), 2)
    if kind == "pf":
        filt = pu.BootstrapParticleFilter(sc.motion, sc.measurement, particles=20)
    else:
        kf = pu.KalmanFilter(sc.motion, sc.measurement)
        filt = pu.filters.InteractingMultipleModel([kf, kf], np.array([[0.9, 0.1], [0.1, 0.9]]))
    track = pu.run(filt, sim.measurements, sim.prior, rng=1, store_predictions=True)
    what = "a particle filter" if kind == "pf" else "an interacting multiple model"
    with pytest.raises(ValueError, match=f"comes from {what}.*no smoother for yet"):
        pu.rts_smooth(track)
