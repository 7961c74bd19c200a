"""MH cuckoo moves: the resample-move step of CS-PF and ICS-PF with ``acceptance="mh"``.

A resample-move particle filter (Gilks & Berzuini 2001) whose move is a
Metropolis–Hastings kernel built from the cuckoo proposals, so the moves
keep the posterior instead of climbing the likelihood.  One step:

1. **Propagate in noise space.**  The motion model is additive Gaussian,
   x_k = f(x_{k−1}) + G ξ with ξ ~ N(0, I_r) and G = ``noise_factor(k, dt)``
   if the model has one, else a factor of ``cov(k, dt)``
   (:func:`pursuit._linalg.psd_factor`).  ξ is drawn with the call the
   models' ``sample`` makes (``standard_normal((*b, N, r))``) and
   X = f(X_prev) + G ξ with :func:`pursuit._linalg.apply_matrix`, so for the
   built-in kinematic models and UNGM X is bitwise what ``sample`` gives.
   m = f(X_prev) and ξ are kept per particle.  Moving ξ rather than x keeps
   a singular process noise (discrete white noise: rank 2 in 4-D) on its
   support.
2. **Weigh and resample** exactly as the bootstrap PF with
   ``ess_threshold=None`` (predictive statistics, NIS, loglik, ESS from the
   propagated particles), resampling the triples (X, m, ξ) in every run
   with a measurement.
3. **Move.**  Particle i targets π_i(ξ) ∝ N(ξ; 0, I) p(z_k | m_i + G ξ):
   log π_i = −½ |ξ|² + ℓ(m_i + G ξ), with ℓ the measurement log-likelihood
   as the filter's fitness computes it (missing components left out; the
   constant cancels).  The particles are split in halves A = [0, ⌊N/2⌋) and
   B = [⌊N/2⌋, N); each of the ``n_iter`` iterations runs, in this order,
   Lévy on A, Lévy on B, discovery on A (partners from B), discovery on B
   (partners from A), each followed by a Metropolis test per particle,
   accept when log u < log π_i(ξ') − log π_i(ξ):

   * Lévy: ξ' = ξ + α_h(t) L, L Mantegna's Lévy steps per entry (σ_u, β of
     the search).  Symmetric: the scale does not depend on ξ.
   * Discovery (DE-MC, ter Braak 2006): ξ' = ξ + γ_h (ξ_p1 − ξ_p2) ⊙ K with
     an ordered pair p1 ≠ p2 drawn uniformly from the *other* half (one
     uniform gives both), K_j = [s_j > Pa(t)] (``discovery="yang"``: a
     fraction 1 − Pa moves; ``"literal_pa"``: s_j < Pa) and γ_h one U(0, 1)
     per half and iteration.  Symmetric: (p1, p2) and (p2, p1) are equally
     likely and nothing depends on ξ_i.  A half whose other half has fewer
     than two particles (N < 4) makes no discovery proposals.
   * The test log u < Δ is evaluated as ``u − 1 < Δ or log u < Δ``: the
     same decision (log u ≤ u − 1, and u − 1 is exact for NumPy's uniforms,
     so a faithfully rounded log keeps the bound), and the compiled kernel
     then skips the logarithm for most accepted moves.
   * α(t) and Pa(t) are the search's schedules.  With ``trend`` on, the
     fitness-trend factor of paper eq. 10 is computed per half from the
     OTHER half's mean fitness f̄ = mean exp(ℓ) at the start of iterations t
     and t − 1: Δ = (f̄(t) − f̄(t−1)) / (f̄(t−1) + ε), α_h(t) = clip(α(t)
     exp(−κ Δ), α_min, α_max) (``"linear"``: α(t)(1 + κΔ)).  So the proposal
     of particle i never depends on ξ_i; it depends on the other half's past,
     which the moves of earlier iterations tied to ξ_i: a standard
     population-MCMC approximation (exact for ``trend="off"``, CS-PF).

   An accepted particle gets X_i = m_i + Σ_c G[:, c] ξ_ic, summed column by
   column (no BLAS product, so the compiled kernel has the same bits); a
   particle never accepted keeps its resampled X bitwise.  |ξ|² is summed
   over the columns in order, f̄ left to right (``np.cumsum``), for the same
   reason.
4. **Estimate.**  The weights after the moves are uniform.
   ``estimate="mean"`` (default) is the mean and covariance of the moved
   particles; ``estimate="weighted"`` the weighted mean and covariance of the
   propagated particles before resampling, so with ``n_iter=0`` the filter
   is the bootstrap PF (``ess_threshold=None``, same resampler) bit for bit.

Options of :class:`~pursuit.filters.cuckoo.CuckooSearch` that do not keep
the posterior raise a ValueError with ``acceptance="mh"``: ``step_scaling``
other than ``"absolute"`` (the Lévy step in ξ space; "relative" and "std"
scale by the particle's own position or the spread of a population that
includes it, which breaks the symmetry), ``f_stop`` (a stopping rule that
looks at the fitness), ``lower``/``upper`` (a box in x space) and the
filter's ``weight_mode`` (the weights are always uniform after the moves).
So does a set ``ess_threshold``: the filter resamples in every run with a
measurement, as resample-move requires.

Random numbers per run and step, in this order and always the same count:
ξ ``(N, r)``; the resampler's uniforms (runs with a measurement);
normals ``(n_iter, 2, N, r)`` (Lévy u, v); uniforms
``(n_iter, N (r + 3) + 2)``, per iteration laid out as the discovery s
``(N, r)``, the partner uniform ``(N,)``, the Lévy accept uniforms ``(N,)``,
the discovery accept uniforms ``(N,)``, then γ_A and γ_B.
"""

from __future__ import annotations

from functools import lru_cache
from typing import Any, Callable

import numpy as np

from .._linalg import apply_matrix, psd_factor
from .resample import gather

__all__ = ["noise_factor", "propagate_in_noise_space", "mh_layout", "mh_moves"]

_EPS = 1e-12


def noise_factor(motion: Any, k: int, dt: float | None) -> np.ndarray:
    """G ``(n, r)`` with G Gᵀ = Q of an additive Gaussian motion model (its ``noise_factor``, else a factor of ``cov``)."""
    if hasattr(motion, "noise_factor"):
        G = motion.noise_factor(k) if dt is None else motion.noise_factor(k, dt)
    else:
        G = psd_factor(motion.cov(k) if dt is None else motion.cov(k, dt))
    return np.ascontiguousarray(G, dtype=float)


def propagate_in_noise_space(
    motion: Any, X_prev: np.ndarray, k: int, dt: float | None, rng: Any
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``(X, m, ξ, G)``: X = m + G ξ with m = f(X_prev) and ξ ~ N(0, I_r) drawn as the models' ``sample`` draws it."""
    G = noise_factor(motion, k, dt)
    xi = rng.standard_normal((*X_prev.shape[:-1], G.shape[1]))
    m = np.asarray(motion.f(X_prev, k) if dt is None else motion.f(X_prev, k, dt), dtype=float)
    X = m + apply_matrix(G, xi)
    return X, m, xi, G


def mh_layout(N: int, r: int) -> tuple[int, int, int, int, int]:
    """Offsets of one iteration's uniforms: ``(pair, u_levy, u_disc, gamma, size)`` (the discovery s come first)."""
    pair = N * r
    return pair, pair + N, pair + 2 * N, pair + 3 * N, pair + 3 * N + 2


def _x_of(m: np.ndarray, xi: np.ndarray, G: np.ndarray) -> np.ndarray:
    """m + G ξ summed column by column (the compiled kernel's order).

    Component by component: X_j += G_jc ξ_c over whole ``(*b, M)`` planes is
    about three times faster than broadcasting the column ``G[:, c]`` (a
    NumPy inner loop n long per particle), with the same sums in the same order.
    """
    X = np.array(m, dtype=float, copy=True)
    term = np.empty(xi.shape[:-1])
    for j in range(G.shape[0]):
        Xj = X[..., j]
        for c in range(G.shape[1]):
            Xj += np.multiply(xi[..., c], G[j, c], out=term)
    return X


def _rows(a: np.ndarray) -> np.ndarray:
    """``a (..., n)`` viewed as ``(...)`` opaque n-number rows (the last axis must be contiguous)."""
    return a.view(_row_dtype(a.shape[-1] * a.itemsize))[..., 0]


@lru_cache(maxsize=None)
def _row_dtype(nbytes: int) -> np.dtype:
    """An opaque dtype of ``nbytes`` bytes (cached: building one costs more than the view)."""
    return np.dtype((np.void, nbytes))


def _select_rows(dst: np.ndarray, src: np.ndarray, ok: np.ndarray) -> None:
    """``dst[..., i, :] = src[..., i, :]`` where ``ok[..., i]``, the rows copied bitwise.

    A masked copy of whole rows: about five times faster than ``np.where`` on
    ``(*b, M, n)`` with the mask broadcast along the short last axis.
    """
    if dst.shape[-1] == 1 or not (_rows_viewable(dst) and _rows_viewable(src)) or src.dtype != dst.dtype:
        # one number per row (UNGM), where np.where is the cheaper one, or rows that are not contiguous
        # (a caller's Fortran-ordered or transposed particles, copied in their own layout)
        dst[...] = np.where(ok[..., None], src, dst)
        return
    np.copyto(_rows(dst), _rows(src), where=ok)


def _rows_viewable(a: np.ndarray) -> bool:
    """Whether ``a``'s last axis is contiguous, as :func:`_rows`' view needs."""
    return a.strides[-1] == a.itemsize


def _log_prior(xi: np.ndarray) -> np.ndarray:
    """−½ |ξ|², the squares summed over the columns in order."""
    q = xi[..., 0] * xi[..., 0]
    for c in range(1, xi.shape[-1]):
        q += xi[..., c] * xi[..., c]
    return q * -0.5


def _other_mean(e: np.ndarray) -> np.ndarray:
    """Mean over the last axis summed left to right (0 for an empty half)."""
    if e.shape[-1] == 0:
        return np.zeros(e.shape[:-1])
    return np.cumsum(e, axis=-1)[..., -1] / e.shape[-1]


def _mantegna(u: np.ndarray, v: np.ndarray, beta: float, sigma_u: float) -> np.ndarray:
    """Lévy steps (u σ_u) / |v|^(1/β), the compiled kernel's formula."""
    a = np.abs(v)
    if beta == 1.5:
        np.multiply(a, a, out=a)
        np.cbrt(a, out=a)
    elif beta == 2.0:
        np.sqrt(a, out=a)
    elif beta != 1.0:
        a = a ** (1.0 / beta)  # the operator: NumPy special-cases some exponents
    L = np.multiply(u, sigma_u)
    L /= a
    return L


def mh_moves(
    search: Any,
    sigma_u: float,
    X: np.ndarray,
    m: np.ndarray,
    xi: np.ndarray,
    G: np.ndarray,
    fitness: Callable[[np.ndarray], np.ndarray],
    rng: Any,
    F: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """Run the MH cuckoo moves on resampled particles (module docstring).

    Parameters
    ----------
    search
        The :class:`~pursuit.filters.cuckoo.CuckooSearch` (schedules, trend, β, discovery).
    sigma_u
        Mantegna's σ_u for ``search.beta``.
    X, m, xi
        ``(*b, N, n)`` particles, ``(*b, N, n)`` their f(x_{k−1}), ``(*b, N, r)`` their noise.
    G
        ``(n, r)`` noise factor.
    fitness
        ``fitness(C) -> (*b, M)`` measurement log-likelihood of ``C (*b, M, n)``.
    rng
        Streams (one per leading batch index with RunStreams).
    F
        ``(*b, N)`` fitness of ``X`` when the caller has it (None: computed
        here); it must be what ``fitness(X)`` returns, bit for bit.

    Returns
    -------
    X, xi, F, accepted, proposals
        Moved particles and noise, their fitness, accepted moves per run, and the proposals per run.
    """
    n_iter = search.n_iter
    *batch, N, r = xi.shape
    X = np.array(X, dtype=float, copy=True)
    xi = np.array(xi, dtype=float, copy=True)
    F = np.array(np.broadcast_to(fitness(X) if F is None else F, xi.shape[:-1]), dtype=float, copy=True)
    accepted = np.zeros(batch, dtype=np.int64)
    if n_iter == 0:
        return X, xi, F, accepted, 0
    normals = rng.standard_normal((*batch, n_iter, 2, N, r))
    pair, u_levy, u_disc, u_gamma, size = mh_layout(N, r)
    uniforms = rng.random((*batch, n_iter, size))
    LT = _log_prior(xi) + F
    h = N // 2
    halves = ((slice(0, h), 0, h), (slice(h, N), h, N - h))  # (slice, start, size)
    yang = search.discovery == "yang"
    trend = search.trend
    proposals = 0

    def metropolis(sl, prop, u):
        Xn = _x_of(m[..., sl, :], prop, G)
        Fn = np.asarray(fitness(Xn), dtype=float)
        LTn = _log_prior(prop) + Fn
        d = LTn - LT[..., sl]
        # log u < Δ, with the bound log u ≤ u − 1 tried first as the compiled kernel does (module docstring)
        ok = (u - 1.0 < d) | (np.log(u) < d)
        _select_rows(xi[..., sl, :], prop, ok)
        _select_rows(X[..., sl, :], Xn, ok)
        F[..., sl] = np.where(ok, Fn, F[..., sl])
        LT[..., sl] = np.where(ok, LTn, LT[..., sl])
        return ok.sum(axis=-1)

    fbar_prev = None
    for t in range(n_iter):
        a_t = search.alpha(t)
        pa = search.pa(t)
        U = uniforms[..., t, :]
        alphas: list[Any] = [a_t, a_t]
        if trend != "off":
            e = np.exp(F)
            # half A's step from B's mean fitness and vice versa
            fbar = [_other_mean(e[..., h:]), _other_mean(e[..., :h])]
            if fbar_prev is not None:
                for j in range(2):
                    delta = (fbar[j] - fbar_prev[j]) / (fbar_prev[j] + _EPS)
                    fac = np.exp(-search.kappa * delta) if trend == "exp" else 1.0 + search.kappa * delta
                    alphas[j] = np.clip(a_t * fac, search.alpha_min, search.alpha_max)[..., None, None]
            fbar_prev = fbar
        # Lévy flights, A then B
        for j, (sl, _, size_h) in enumerate(halves):
            if size_h == 0:
                continue
            L = _mantegna(normals[..., t, 0, sl, :], normals[..., t, 1, sl, :], search.beta, sigma_u)
            L *= alphas[j]
            prop = np.add(xi[..., sl, :], L, out=L)  # ξ + α L, in L's memory
            accepted += metropolis(sl, prop, U[..., u_levy : u_levy + N][..., sl])
            proposals += size_h
        # discovery, A with partners from B, then B with partners from A
        for j, (sl, _, size_h) in enumerate(halves):
            _, o0, mo = halves[1 - j]
            if size_h == 0 or mo < 2:
                continue
            npairs = mo * (mo - 1)
            idx = np.minimum(np.floor(U[..., pair : pair + N][..., sl] * npairs), npairs - 1).astype(np.int64)
            p1 = idx // (mo - 1)
            q = idx - p1 * (mo - 1)
            p2 = q + (q >= p1)
            x1 = gather(xi, o0 + p1)
            x2 = gather(xi, o0 + p2)
            s = U[..., : N * r].reshape(*batch, N, r)[..., sl, :]
            K = s > pa if yang else s < pa
            d = np.subtract(x1, x2, out=x1)  # (ξ_p1 − ξ_p2) ⊙ K γ, in x1's memory
            d *= K
            d *= U[..., u_gamma + j][..., None, None]
            prop = np.add(xi[..., sl, :], d, out=d)
            accepted += metropolis(sl, prop, U[..., u_disc : u_disc + N][..., sl])
            proposals += size_h
    return X, xi, F, accepted, proposals
