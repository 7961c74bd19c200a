"""The IMM smoother (forward IMM, Kim's backward pass) against exact references where they exist."""

from __future__ import annotations

import numpy as np
import pytest

from pursuit.filters.imm_smoother import imm_smooth
from pursuit.models import ConstantTurn, ConstantVelocity

K, N = 7, 4
H = np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0]])
R = np.diag([1.0, 0.5])
P0 = np.diag([4.0, 1.0, 4.0, 1.0])


def _batch_posterior(F, Q, m0, P0, z, W, measured):
    """Exact p(x_1..x_K | z) of one linear-Gaussian model by solving the joint Gaussian: means, covariances, log p(z)."""
    n = m0.size
    A = np.zeros((K * n, (K + 1) * n))  # x = A [x0, w_1..w_K]
    blocks = [np.eye(n)]
    for k in range(K):
        blocks = [F[k] @ b for b in blocks] + [np.eye(n)]
        for j, b in enumerate(blocks):
            A[k * n : (k + 1) * n, j * n : (j + 1) * n] = b
    Pw = np.zeros(((K + 1) * n, (K + 1) * n))
    Pw[:n, :n] = P0
    for k in range(K):
        Pw[(k + 1) * n : (k + 2) * n, (k + 1) * n : (k + 2) * n] = Q[k]
    mw = np.zeros((K + 1) * n)
    mw[:n] = m0
    mx, Px = A @ mw, A @ Pw @ A.T
    rows = [k for k in range(K) if measured[k]]
    Hb = np.zeros((2 * len(rows), K * n))
    Rb = np.zeros((2 * len(rows), 2 * len(rows)))
    for i, k in enumerate(rows):
        Hb[2 * i : 2 * i + 2, k * n : (k + 1) * n] = H
        Rb[2 * i : 2 * i + 2, 2 * i : 2 * i + 2] = R / W[k]
    zz = np.concatenate([z[k] for k in rows])
    S = Hb @ Px @ Hb.T + Rb
    G = Px @ Hb.T @ np.linalg.inv(S)
    r = zz - Hb @ mx
    mean = mx + G @ r
    cov = Px - G @ Hb @ Px
    loglik = -0.5 * (r @ np.linalg.solve(S, r) + np.linalg.slogdet(2 * np.pi * S)[1])
    return mean.reshape(K, n), np.array([cov[k * n : (k + 1) * n, k * n : (k + 1) * n] for k in range(K)]), loglik


def _modes(rates, q=0.05, dt=1.0):
    """Per-mode F, Q ``(K, J, n, n)`` for coordinated turns at ``rates`` (0: constant velocity)."""
    F = np.stack([ConstantTurn(omega=w, q=q, dt=dt).transition_matrix() for w in rates])
    Q = np.stack([ConstantTurn(omega=w, q=q, dt=dt).cov() for w in rates])
    return np.broadcast_to(F, (K, *F.shape)), np.broadcast_to(Q, (K, *Q.shape))


def _data(seed, runs=3):
    rng = np.random.default_rng(seed)
    m0 = rng.normal(0, 3, (runs, N))
    z = rng.normal(0, 5, (runs, K, 2))
    W = rng.uniform(0.2, 1.5, (runs, K))
    measured = rng.random((runs, K)) > 0.25
    measured[:, 0] = True
    return m0, z, W, measured


def test_one_mode_is_the_rts_smoother_and_kalman_filter():
    """J = 1: the exact batch posterior (1e-9), with weights R / W and missed steps, batched over runs."""
    F, Q = _modes([0.0])
    m0, z, W, measured = _data(1)
    out = imm_smooth(m0, np.broadcast_to(P0, (3, N, N)), np.ones(1), np.eye(1), F, Q, z, H, R, weight=W, measured=measured)
    for r in range(3):
        mean, cov, ll = _batch_posterior(F[:, 0], Q[:, 0], m0[r], P0, z[r], W[r], measured[r])
        np.testing.assert_allclose(out.mean[r], mean, rtol=0, atol=1e-9)
        np.testing.assert_allclose(out.cov[r], cov, rtol=0, atol=1e-9)
        assert out.loglik[r] == pytest.approx(ll, rel=1e-10)
        # the filtered estimate at the last step is the smoothed one
        np.testing.assert_allclose(out.filt_mean[r, -1], mean[-1], rtol=0, atol=1e-9)
    np.testing.assert_array_equal(out.mode_probs, 1.0)


def test_identical_modes_reduce_to_the_rts_smoother():
    """Three copies of one model under an asymmetric Π: the mode probabilities stay Π's, the states are RTS's (1e-9)."""
    F, Q = _modes([0.1, 0.1, 0.1])
    Pi = np.array([[0.8, 0.15, 0.05], [0.3, 0.6, 0.1], [0.05, 0.25, 0.7]])
    m0, z, W, measured = _data(2)
    out = imm_smooth(m0, P0, np.array([0.2, 0.5, 0.3]), Pi, F, Q, z, H, R, weight=W, measured=measured)
    for r in range(3):
        mean, cov, ll = _batch_posterior(F[:, 0], Q[:, 0], m0[r], P0, z[r], W[r], measured[r])
        np.testing.assert_allclose(out.mean[r], mean, rtol=0, atol=1e-9)
        np.testing.assert_allclose(out.cov[r], cov, rtol=0, atol=1e-9)
        assert out.loglik[r] == pytest.approx(ll, rel=1e-10)


def test_pinned_mode_is_that_modes_rts_smoother():
    """Π = I and a known prior mode: the smoother of that mode's F (1e-9), whatever the other modes are."""
    F, Q = _modes([0.0, 0.2, -0.2])
    m0, z, W, measured = _data(3)
    for j in range(3):
        prior = np.eye(3)[j]
        out = imm_smooth(m0, P0, prior, np.eye(3), F, Q, z, H, R, weight=W, measured=measured)
        for r in range(3):
            mean, cov, _ = _batch_posterior(F[:, j], Q[:, j], m0[r], P0, z[r], W[r], measured[r])
            np.testing.assert_allclose(out.mean[r], mean, rtol=0, atol=1e-9)
            np.testing.assert_allclose(out.cov[r], cov, rtol=0, atol=1e-9)
            np.testing.assert_allclose(out.mode_probs[r], np.broadcast_to(prior, (K, 3)), rtol=0, atol=0)


def test_fixed_unknown_mode_is_the_exact_bayesian_mixture():
    """Π = I and a spread prior: the exact posterior is Σ_j p(j | z) RTS_j, p(j | z) ∝ p_j p(z | j) (1e-9)."""
    F, Q = _modes([0.0, 0.15, -0.1])
    m0, z, W, measured = _data(4)
    prior = np.array([0.5, 0.3, 0.2])
    out = imm_smooth(m0, P0, prior, np.eye(3), F, Q, z, H, R, weight=W, measured=measured)
    for r in range(3):
        fits = [_batch_posterior(F[:, j], Q[:, j], m0[r], P0, z[r], W[r], measured[r]) for j in range(3)]
        logw = np.log(prior) + np.array([f[2] for f in fits])
        post = np.exp(logw - logw.max())
        post /= post.sum()
        mean = np.einsum("j,jka->ka", post, np.stack([f[0] for f in fits]))
        d = np.stack([f[0] for f in fits]) - mean
        cov = np.einsum("j,jkab->kab", post, np.stack([f[1] for f in fits]) + d[..., :, None] * d[..., None, :])
        np.testing.assert_allclose(out.mode_probs[r], np.broadcast_to(post, (K, 3)), rtol=0, atol=1e-9)
        np.testing.assert_allclose(out.mean[r], mean, rtol=0, atol=1e-9)
        np.testing.assert_allclose(out.cov[r], cov, rtol=0, atol=1e-8)
        top = logw.max()
        assert out.loglik[r] == pytest.approx(top + np.log(np.exp(logw - top).sum()), rel=1e-10)


def test_batch_equals_one_run_at_a_time_and_inactive_steps_hold():
    """A (2, 3) batch = each element alone (1e-12); leading inactive steps = smoothing the rest from the prior."""
    F, Q = _modes([0.0, 0.1, -0.1])
    Pi = np.full((3, 3), 0.05) + np.eye(3) * 0.85
    rng = np.random.default_rng(5)
    m0 = rng.normal(0, 3, (2, 3, N))
    z = rng.normal(0, 5, (2, 3, K, 2))
    W = rng.uniform(0.2, 1.5, (2, 3, K))
    first = rng.integers(0, 4, (2, 3))
    active = np.arange(K) >= first[..., None]
    out = imm_smooth(m0, P0, np.full(3, 1 / 3), Pi, F, Q, z, H, R, weight=W, active=active)
    for a in range(2):
        for b in range(3):
            one = imm_smooth(m0[a, b], P0, np.full(3, 1 / 3), Pi, F, Q, z[a, b], H, R, weight=W[a, b], active=active[a, b])
            np.testing.assert_allclose(out.mean[a, b], one.mean, rtol=0, atol=1e-12)
            np.testing.assert_allclose(out.mode_probs[a, b], one.mode_probs, rtol=0, atol=1e-12)
            f = first[a, b]
            late = imm_smooth(
                m0[a, b], P0, np.full(3, 1 / 3), Pi, F[f:], Q[f:], z[a, b, f:], H, R, weight=W[a, b, f:]
            ) if f else None  # fmt: skip
            if late is not None:
                # K is fixed in the module; shorter sequences pass their own F, Q
                np.testing.assert_allclose(one.mean[f:], late.mean, rtol=0, atol=1e-9)
                np.testing.assert_allclose(one.filt_mean[:f], np.broadcast_to(m0[a, b], (f, N)), rtol=0, atol=1e-12)


def test_bad_input_names_the_field():
    F, Q = _modes([0.0, 0.1])
    m0, z, _, _ = _data(6)
    with pytest.raises(ValueError, match="transition"):
        imm_smooth(m0, P0, np.full(2, 0.5), np.array([[0.9, 0.2], [0.1, 0.9]]), F, Q, z, H, R)
    with pytest.raises(ValueError, match="F"):
        imm_smooth(m0, P0, np.full(2, 0.5), np.eye(2), F[:2], Q, z, H, R)
    with pytest.raises(ValueError, match="mode_prior"):
        imm_smooth(m0, P0, np.full(3, 1 / 3), np.eye(2), F, Q, z, H, R)


def test_turn_modes_find_a_turn():
    """A noise-free quarter turn at 0.1 rad/s: the smoothed probability of the right turn mode ends above 0.9."""
    cv, ct = ConstantVelocity(ndim=2, q=0.01), ConstantTurn(omega=0.1, q=0.01)
    x = np.array([0.0, 10.0, 0.0, 0.0])
    states = []
    for k in range(K):
        x = (cv if k < 2 else ct).f(x)
        states.append(x)
    z = np.array(states)[:, [0, 2]]
    F, Q = _modes([0.0, 0.1, -0.1], q=0.01)
    out = imm_smooth(np.array([0.0, 10.0, 0.0, 0.0]), P0, np.full(3, 1 / 3), np.full((3, 3), 0.05) + 0.85 * np.eye(3), F, Q, z, H, R * 0.01)
    assert out.mode_probs[-1, 1] > 0.9
    assert (out.mode_probs[-3:, 2] < 0.05).all()
