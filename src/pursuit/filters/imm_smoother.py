"""Fixed-interval IMM smoother for linear-Gaussian modes: a forward IMM filter and Kim's backward pass.

The modes j = 1..J have the linear dynamics ``x_k = F_j x_{k−1} + w``,
``w ~ N(0, Q_j)``, and switch as a Markov chain (``Π[i, j]`` =
P{mode j at k | mode i at k − 1}); one linear sensor ``z_k = H x_k + v``,
``v ~ N(0, R / W_k)`` (W_k a weight per step, 1 by default; PMHT's
synthetic measurements have ``R / W``).

**Forward** (the IMM filter, docs/spec/04-adaptive-cs-model.md §4.3), per step:
``c̄_j = Σ_i Π_ij μ_i``, mixing weights ``μ_{i|j} = Π_ij μ_i / c̄_j``, mixed
``x̂_0j = Σ_i μ_{i|j} x̂_i``, ``P_0j = Σ_i μ_{i|j} [P_i + (x̂_i − x̂_0j)(·)ᵀ]``;
each mode's Kalman step from its mixed state with its likelihood Λ_j;
``μ_j ∝ c̄_j Λ_j``.  It records the mode-conditional filtered ``x̂_k^j, P_k^j``
and ``μ_k``.

**Backward** (Kim 1994, "Dynamic linear models with Markov-switching",
J. Econometrics 60; the "IMM-RTS" smoother), from ``x^s_K^j = x̂_K^j``,
``μ^s_K = μ_K``, for k = K−1 … 1 with the step k → k+1's F_j, Q_j:

* mode probabilities: ``μ^s_k(i, j) = μ_k(i) Π_ij μ^s_{k+1}(j) / c̄_{k+1}(j)``
  (joint, with ``c̄_{k+1}(j) = Σ_i Π_ij μ_k(i)``), ``μ^s_k(i) = Σ_j μ^s_k(i, j)``,
  backward weights ``μ_{j|i} = μ^s_k(i, j) / μ^s_k(i)``;
* per pair (i, j), an RTS step from mode i's filtered estimate through mode
  j's dynamics: ``P⁻_ij = F_j P_k^i F_jᵀ + Q_j``, ``G_ij = P_k^i F_jᵀ (P⁻_ij)⁻¹``,
  ``x^s_ij = x̂_k^i + G_ij (x^s_{k+1}^j − F_j x̂_k^i)``,
  ``P^s_ij = P_k^i + G_ij (P^s_{k+1}^j − P⁻_ij) G_ijᵀ``;
* collapsed per mode: ``x^s_k^i = Σ_j μ_{j|i} x^s_ij``,
  ``P^s_k^i = Σ_j μ_{j|i} [P^s_ij + (x^s_ij − x^s_k^i)(·)ᵀ]``; the output
  ``x^s_k = Σ_i μ^s_k(i) x^s_k^i`` with its moment-matched covariance.

The approximations (besides the IMM's own mixing) are Kim's: p(mode_k |
mode_{k+1}, Z_{1..K}) ≈ p(mode_k | mode_{k+1}, Z_{1..k}), and each mode's
smoothed density a single Gaussian.  Exact cases: with one mode, or identical
modes, it is the Kalman filter and the RTS smoother; with Π = I (a fixed but
unknown mode) it is the exact posterior, the mixture of each mode's RTS
smoother weighted by that mode's posterior probability.

Steps where ``active`` is False hold everything (state, covariance, mode
probabilities), as before a track's first step in PMHT; steps where
``measured`` is False only predict.  Batched over any leading axes; the
Python loops run over the K steps and (backward) nothing else.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._linalg import symmetrize

__all__ = ["IMMSmoothed", "imm_smooth"]

_LOG_2PI = float(np.log(2.0 * np.pi))


@dataclass(frozen=True)
class IMMSmoothed:
    """The IMM smoother's output over K steps for a batch ``(*b)``.

    Attributes
    ----------
    mean, cov
        ``(*b, K, n)``, ``(*b, K, n, n)`` the smoothed mixture, moment-matched.
    mode_probs
        ``(*b, K, J)`` smoothed mode probabilities μ^s_k.
    filt_mean, filt_cov, filt_mode_probs
        The forward IMM filter's output (mixture, moment-matched) and μ_k.
    loglik
        ``(*b,)`` Σ_k log Σ_j c̄_j Λ_j, the IMM's (approximate) measurement log-likelihood.
    """

    mean: np.ndarray
    cov: np.ndarray
    mode_probs: np.ndarray
    filt_mean: np.ndarray
    filt_cov: np.ndarray
    filt_mode_probs: np.ndarray
    loglik: np.ndarray


def _per_step(A: np.ndarray, K: int, J: int, n: int, field: str) -> np.ndarray:
    """``(J, n, n)`` or ``(K, J, n, n)`` as ``(K, J, n, n)``."""
    A = np.asarray(A, dtype=float)
    if A.shape == (J, n, n):
        return np.broadcast_to(A, (K, J, n, n))
    if A.shape != (K, J, n, n):
        raise ValueError(f"{field}: expected shape {(J, n, n)} or {(K, J, n, n)}, got {A.shape}")
    return A


def _moments(w: np.ndarray, x: np.ndarray, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Moment-matched mean and covariance of the mixture Σ_j w_j N(x_j, P_j) over the axis before the state's."""
    mean = np.einsum("...j,...ja->...a", w, x)
    d = x - mean[..., None, :]
    cov = np.einsum("...j,...jab->...ab", w, P + d[..., :, None] * d[..., None, :])
    return mean, symmetrize(cov)


def _safe_ratio(num: np.ndarray, den: np.ndarray) -> np.ndarray:
    """num / den, 0 where den is 0 (a mode with no probability carries no weight)."""
    ok = den > 0.0
    return np.where(ok, num / np.where(ok, den, 1.0), 0.0)


def imm_smooth(
    prior_mean: np.ndarray,
    prior_cov: np.ndarray,
    mode_prior: np.ndarray,
    transition: np.ndarray,
    F: np.ndarray,
    Q: np.ndarray,
    z: np.ndarray,
    H: np.ndarray,
    R: np.ndarray,
    *,
    weight: np.ndarray | None = None,
    measured: np.ndarray | None = None,
    active: np.ndarray | None = None,
) -> IMMSmoothed:
    """Smooth K steps of linear-Gaussian modes with the IMM filter and Kim's backward pass.

    Parameters
    ----------
    prior_mean, prior_cov
        ``(*b, n)``, ``(*b, n, n)``: the state before the first step (every mode starts from it).
    mode_prior
        ``(*b, J)`` or ``(J,)``: the mode probabilities before the first step.
    transition
        Π, ``(J, J)``, rows summing to 1.
    F, Q
        ``(J, n, n)`` or ``(K, J, n, n)``: each mode's transition into each step and its process noise.
    z
        ``(*b, K, m)`` measurements (entries where ``measured`` is False are ignored).
    H, R
        ``(m, n)`` or ``(*b, K, m, n)``; ``(m, m)``.
    weight
        ``(*b, K)`` W_k > 0: the step's measurement noise is R / W_k (default 1).
    measured, active
        ``(*b, K)`` booleans (default all True): a step without a measurement
        only predicts; an inactive step holds everything as it was.

    Returns
    -------
    IMMSmoothed
    """
    z = np.asarray(z, dtype=float)
    x0 = np.asarray(prior_mean, dtype=float)
    n = x0.shape[-1]
    K = z.shape[-2]
    batch = z.shape[:-2]
    Pi = np.asarray(transition, dtype=float)
    J = Pi.shape[0]
    if Pi.shape != (J, J) or not np.allclose(Pi.sum(axis=1), 1.0) or (Pi < 0).any():
        raise ValueError(f"transition: expected a ({J}, {J}) Markov matrix (non-negative rows summing to 1), got {Pi!r}")
    F = _per_step(F, K, J, n, "F")
    Q = _per_step(Q, K, J, n, "Q")
    mu = np.asarray(mode_prior, dtype=float)
    if mu.shape[-1:] != (J,):
        raise ValueError(f"mode_prior: expected {J} probabilities (one per mode of transition), got shape {mu.shape}")
    mu = np.broadcast_to(mu, (*batch, J))
    H = np.asarray(H, dtype=float)
    R = np.asarray(R, dtype=float)
    W = np.ones((*batch, K)) if weight is None else np.broadcast_to(np.asarray(weight, dtype=float), (*batch, K))
    meas = np.ones((*batch, K), dtype=bool) if measured is None else np.broadcast_to(measured, (*batch, K))
    act = np.ones((*batch, K), dtype=bool) if active is None else np.broadcast_to(active, (*batch, K))
    meas = meas & act

    x = np.broadcast_to(x0[..., None, :], (*batch, J, n)).copy()  # mode-conditional estimates
    P = np.broadcast_to(np.asarray(prior_cov, dtype=float)[..., None, :, :], (*batch, J, n, n)).copy()
    mu = mu.copy()
    xf = np.empty((*batch, K, J, n))
    Pf = np.empty((*batch, K, J, n, n))
    muf = np.empty((*batch, K, J))
    loglik = np.zeros(batch)
    # contiguous transposes: a matmul whose right operand is a transposed view costs ~2.5x more (same bits)
    Ft = np.ascontiguousarray(np.swapaxes(F, -1, -2))
    Ht = np.ascontiguousarray(np.swapaxes(H, -1, -2))
    for k in range(K):
        step = act[..., k]
        cbar = mu @ Pi  # (*b, J)
        mix = _safe_ratio(Pi * mu[..., :, None], cbar[..., None, :])  # μ_{i|j}, (*b, i, j)
        # a mode with no predicted probability keeps its own estimate (finite, and it carries no weight)
        mix = np.where((cbar > 0.0)[..., None, :], mix, np.eye(J))
        x_mix = np.einsum("...ij,...ia->...ja", mix, x)
        d = x[..., None, :, :] - x_mix[..., :, None, :]  # (*b, j, i, n)
        P_mix = symmetrize(np.einsum("...ij,...jiab->...jab", mix, P[..., None, :, :, :] + d[..., :, None] * d[..., None, :]))
        Fk, Qk = F[k], Q[k]
        x_pred = np.einsum("jab,...jb->...ja", Fk, x_mix)
        PFt = P_mix @ Ft[k]
        P_pred = Fk @ PFt + Qk
        # the update with R / W, written without dividing by W (it may be tiny): S' = W H P⁻ H' + R = W S
        Hk, Htk = (H, Ht) if H.ndim == 2 else (H[..., k, None, :, :], Ht[..., k, None, :, :])
        upd = meas[..., k]
        Wk = np.where(upd, W[..., k], 0.0)[..., None, None, None]
        PHt = P_pred @ Htk
        Sw = Wk * (Hk @ PHt) + R
        nu = z[..., k, None, :] - np.einsum("...ab,...b->...a", Hk, x_pred)
        rhs = np.concatenate([np.swapaxes(PHt, -1, -2), np.broadcast_to(nu[..., None], (*PHt.shape[:-2], nu.shape[-1], 1))], axis=-1)
        both = np.linalg.solve(Sw, rhs)  # S'⁻¹ [H P⁻, ν] in one solve
        KtW, sol = both[..., :-1], both[..., -1]
        x_upd = x_pred + Wk[..., 0] * np.einsum("...ba,...b->...a", KtW, nu)
        P_upd = symmetrize(P_pred - Wk * (PHt @ KtW))
        # log N(ν; 0, S) with S = S' / W: W νᵀS'⁻¹ν and log det 2πS = log det 2πS' − m log W
        m = Sw.shape[-1]
        Wj = Wk[..., 0, 0]
        logdet = np.linalg.slogdet(Sw)[1] - m * np.log(np.where(upd, W[..., k], 1.0))[..., None]
        loglam = -0.5 * (Wj * np.einsum("...a,...a->...", nu, sol) + logdet + m * _LOG_2PI)
        logc = np.where(cbar > 0.0, np.log(np.where(cbar > 0.0, cbar, 1.0)), -np.inf) + np.where(upd[..., None], loglam, 0.0)
        top = logc.max(axis=-1, keepdims=True)
        e = np.exp(logc - top)
        tot = e.sum(axis=-1)
        mu_new = e / tot[..., None]
        loglik += np.where(upd, np.log(tot) + top[..., 0], 0.0)
        x_new = np.where(upd[..., None, None], x_upd, x_pred)
        P_new = np.where(upd[..., None, None, None], P_upd, P_pred)
        x = np.where(step[..., None, None], x_new, x)
        P = np.where(step[..., None, None, None], P_new, P)
        mu = np.where(step[..., None], mu_new, mu)
        xf[..., k, :, :], Pf[..., k, :, :, :], muf[..., k, :] = x, P, mu

    # Kim's backward pass
    xs_j, Ps_j, mus = xf[..., K - 1, :, :].copy(), Pf[..., K - 1, :, :, :].copy(), muf[..., K - 1, :].copy()
    out_x = np.empty((*batch, K, n))
    out_P = np.empty((*batch, K, n, n))
    out_mu = np.empty((*batch, K, J))
    out_x[..., K - 1, :], out_P[..., K - 1, :, :] = _moments(mus, xs_j, Ps_j)
    out_mu[..., K - 1, :] = mus
    for k in range(K - 2, -1, -1):
        step = act[..., k + 1]  # the transition k → k+1 happened (else everything was held)
        xk, Pk, muk = xf[..., k, :, :], Pf[..., k, :, :, :], muf[..., k, :]
        Fn, Qn = F[k + 1], Q[k + 1]
        cbar = muk @ Pi
        joint = muk[..., :, None] * Pi * _safe_ratio(mus, cbar)[..., None, :]  # μ^s(i, j)
        mus_new = joint.sum(axis=-1)
        back = _safe_ratio(joint, mus_new[..., :, None])  # μ_{j|i}
        back = np.where((mus_new > 0.0)[..., None], back, np.eye(J))
        # per pair (i, j): mode i's filtered estimate smoothed through mode j's dynamics
        PFt = Pk[..., :, None, :, :] @ Ft[k + 1]  # (*b, i, j, n, n)
        P_pred = Fn @ PFt + Qn
        x_pred = np.einsum("jab,...ib->...ija", Fn, xk)
        G = np.swapaxes(np.linalg.solve(P_pred, np.swapaxes(PFt, -1, -2)), -1, -2)
        x_ij = xk[..., :, None, :] + np.einsum("...ab,...b->...a", G, xs_j[..., None, :, :] - x_pred)
        P_ij = Pk[..., :, None, :, :] + G @ (Ps_j[..., None, :, :, :] - P_pred) @ np.swapaxes(G, -1, -2)
        x_i, P_i = _moments(back, x_ij, P_ij)
        xs_j = np.where(step[..., None, None], x_i, xs_j)
        Ps_j = np.where(step[..., None, None, None], P_i, Ps_j)
        mus = np.where(step[..., None], mus_new, mus)
        out_x[..., k, :], out_P[..., k, :, :] = _moments(mus, xs_j, Ps_j)
        out_mu[..., k, :] = mus
    fm, fc = _moments(muf, xf, Pf)
    return IMMSmoothed(out_x, out_P, out_mu, fm, fc, muf, loglik)
