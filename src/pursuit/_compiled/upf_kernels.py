"""Compiled partial unscented particle filter: one step for a batch of runs, parallel over runs.

The step of :class:`pursuit.filters.upf.PartialUPF` (its module docstring
has the algorithm), run by run: one thread takes run r from start to end
with its own PCG64 stream (:mod:`.streams`), drawing in the NumPy filter's
order: the selection's tie-break uniforms (N, when ``0 < n_u < N`` and the
selection is not the fixed block), the UKF group's proposal normals
(n_u × n), the prior group's process noise, then the resampler's uniforms
if the run resamples.

Per run, the scratch arrays of the unscented transform are allocated once
(:func:`ukf_scratch`) and reused for every important particle; the
Cholesky factors are computed in place.  The unscented Kalman step follows
:class:`pursuit.filters.gaussian.UnscentedKalmanFilter` (points redrawn from
the prediction, statistical linearisation, the Joseph form as one Gram
matrix ``[A_L, K chol R, K Eᵀ]``), a covariance that does not factor is
repaired as :func:`pursuit._linalg.cholesky_psd` does (eigenvalues clipped),
and the weighing, moments and resampling reuse the bootstrap kernels'
per-run functions (:mod:`.pf_kernels`).  The arithmetic is the NumPy
filter's up to the order of summation and the small-matrix inverses
(LAPACK and closed forms there, a Cholesky solve here), so the two agree to
rounding, not bit for bit (docs/compiled-backend.md states the tolerance).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .common import LOG_2PI, cholesky_inplace, copy_by_counts, n_uniforms, resample_counts, serial_and_parallel, wrap
from .model_math import h_point, propagate_point
from .specs import LINEAR
from .pf_kernels import exp_shifted_run, measure_run, moments_run, predictive_run
from .streams import fill_normal, fill_random

__all__ = ["upf_step_serial", "upf_step_parallel", "SELECT_WEIGHT", "SELECT_RANDOM", "SELECT_BLOCK", "COV_CODES"]

# selection of the important particles (U1)
SELECT_WEIGHT = 0
SELECT_RANDOM = 1
SELECT_BLOCK = 2
# covariance of the prior group (U3)
COV_POPULATION = 0
COV_PROPAGATE = 1
COV_RESET = 2
COV_ZERO = 3
COV_CODES = {"population": COV_POPULATION, "propagate": COV_PROPAGATE, "reset": COV_RESET, "zero": COV_ZERO}

_NJ = dict(cache=True, error_model="numpy")
_JITTER = 1e-9  # the population covariance's and "zero" mode's 1e-9·I


@njit(cache=True, error_model="numpy", inline="always")
def cholesky_psd_inplace(P, L):
    """Lower Cholesky factor of ½(P + Pᵀ) into ``L``, as :func:`pursuit._linalg.cholesky_psd`; True if repaired.

    ``P`` is symmetrised in place.  A matrix that does not factor gets its
    eigenvalues clipped at 1e−12 times the largest magnitude (at least
    1e−12) and is factored again.
    """
    n = P.shape[0]
    for a in range(n):
        for b in range(a + 1, n):
            v = 0.5 * (P[a, b] + P[b, a])
            P[a, b] = v
            P[b, a] = v
    if _cholesky(P, L):
        return False
    return _repair(P, L)


@njit(cache=True, error_model="numpy", inline="always")
def _cholesky(S, L):
    """:func:`.common.cholesky_inplace`, inlined into the particle loop."""
    m = S.shape[0]
    for j in range(m):
        for i in range(j):
            L[i, j] = 0.0
    for j in range(m):
        acc = S[j, j]
        for p in range(j):
            acc -= L[j, p] * L[j, p]
        if not (acc > 0.0) or not math.isfinite(acc):
            return False
        d = math.sqrt(acc)
        L[j, j] = d
        for i in range(j + 1, m):
            acc = S[i, j]
            for p in range(j):
                acc -= L[i, p] * L[j, p]
            L[i, j] = acc / d
    return True


@njit(**_NJ)
def _repair(P, L):
    """Factor of P with its eigenvalues clipped (the rare path of :func:`cholesky_psd_inplace`); True."""
    n = P.shape[0]
    if not np.all(np.isfinite(P)):
        for a in range(n):
            for b in range(n):
                L[a, b] = math.nan
        return True
    w, V = np.linalg.eigh(P)
    floor = 1e-12 * max(np.max(np.abs(w)), 1.0)
    A = np.zeros((n, n))
    for a in range(n):
        for b in range(n):
            acc = 0.0
            for j in range(n):
                acc += V[a, j] * max(w[j], floor) * V[b, j]
            A[a, b] = acc
    for a in range(n):
        for b in range(a + 1, n):
            v = 0.5 * (A[a, b] + A[b, a])
            A[a, b] = v
            A[b, a] = v
    cholesky_inplace(A, L)
    return True


@njit(**_NJ)
def ukf_scratch(n, m, q):
    """The unscented step's scratch arrays for one run (reused for every particle); q normals per point for f."""
    p = 2 * n + 1
    return (
        np.empty((p, n)),  # 0 chi: sigma points
        np.empty((p, n)),  # 1 Y: propagated points
        np.empty((p, m)),  # 2 Z: predicted measurements of the points, then their residuals dZ
        np.empty((p, m)),  # 3 E: linearisation residuals
        np.empty((n, n)),  # 4 L: factor of the prior / predicted covariance
        np.empty((n, n)),  # 5 Pp: predicted covariance
        np.empty(n),  # 6 xp: predicted mean
        np.empty((n, m)),  # 7 Pxz, then the gain K
        np.empty((m, m)),  # 8 S, then its factor's scratch
        np.empty((m, m)),  # 9 chol S
        np.empty((n, m)),  # 10 G
        np.empty(m),  # 11 innovation
        np.empty(m),  # 12 zhat
        np.empty((n, n)),  # 13 A_L
        np.zeros(p * q),  # 14 zero noise: f(χ) through the motion's propagation
        np.empty((m, m)),  # 15 Pzz
        np.empty((m, n)),  # 16 K chol R, transposed
    )


@njit(cache=True, error_model="numpy", inline="always")
def _residual_comp(angle, j, a):
    return wrap(a) if (angle and j == 1) else a


@njit(cache=True, error_model="numpy", inline="always")
def ukf_one(x, P, z, valid, mk, F, G, par, hk, A, idx, hscale, angle, R, upf, ws, mean, cov):
    """One UKF step from (x, P) with measurement z into (mean, cov) (``P`` is overwritten)."""
    chi, Y, Z, E, L, Pp, xp, K, S, LS, Gm, nu, zp, AL, zero, Pzz, KC = ws
    n = x.shape[0]
    m = z.shape[0]
    p = 2 * n + 1
    c = upf.cscale
    wm, wc = upf.wm, upf.wc
    # -- predict
    if mk == LINEAR:
        # f = F x: the points' mean and spread are exactly F x and F P Fᵀ (Σ wm = 1, Σ wc ξ ξᵀ = I),
        # so skip the factor and the 2n + 1 propagations (the same numbers up to rounding)
        for a in range(n):
            acc = 0.0
            for j in range(n):
                acc += F[a, j] * x[j]
            xp[a] = acc
        for a in range(n):  # L = P Fᵀ (scratch), P symmetrised as the points' factor would see it
            for b in range(n):
                acc = 0.0
                for j in range(n):
                    acc += 0.5 * (P[a, j] + P[j, a]) * F[b, j]
                L[a, b] = acc
        for a in range(n):
            for b in range(a, n):
                acc = 0.0
                for j in range(n):
                    acc += F[a, j] * L[j, b]
                Pp[a, b] = acc
                Pp[b, a] = acc
    else:  # the points of (x, P) through f
        cholesky_psd_inplace(P, L)
        for a in range(n):
            chi[0, a] = x[a]
        for j in range(n):
            for a in range(n):
                d = c * L[a, j]
                chi[1 + j, a] = x[a] + d
                chi[1 + n + j, a] = x[a] - d
        for i in range(p):
            propagate_point(mk, F, G, par, chi, i, zero, Y, i)
        for a in range(n):
            acc = 0.0
            for i in range(p):
                acc += wm[i] * Y[i, a]
            xp[a] = acc
        for i in range(p):
            for a in range(n):
                Y[i, a] -= xp[a]
        for a in range(n):
            for b in range(a, n):
                acc = 0.0
                for i in range(p):
                    acc += Y[i, a] * wc[i] * Y[i, b]
                Pp[a, b] = acc
                Pp[b, a] = acc
    for a in range(n):
        for b in range(n):
            Pp[a, b] += upf.Q[a, b]
    # -- measure: points redrawn from (x⁻, P⁻)
    for a in range(n):
        for b in range(n):
            cov[a, b] = Pp[a, b]  # P⁻ kept (a step with nothing measured returns it)
    cholesky_psd_inplace(cov, L)
    for a in range(n):
        chi[0, a] = xp[a]
    for j in range(n):
        for a in range(n):
            d = c * L[a, j]
            chi[1 + j, a] = xp[a] + d
            chi[1 + n + j, a] = xp[a] - d
    for i in range(p):
        h_point(hk, A, idx, hscale, chi, i, Z, i)
    for j in range(m):  # residuals about the first point: angles averaged on the circle
        acc = 0.0
        for i in range(p):
            acc += wm[i] * _residual_comp(angle, j, Z[i, j] - Z[0, j])
        zp[j] = Z[0, j] + acc
    for i in range(p):
        for j in range(m):
            Z[i, j] = _residual_comp(angle, j, Z[i, j] - zp[j])
    for i in range(p):  # dX = χ − x⁻, into Y
        for a in range(n):
            Y[i, a] = chi[i, a] - xp[a]
    for a in range(m):
        for b in range(m):
            acc = 0.0
            for i in range(p):
                acc += Z[i, a] * wc[i] * Z[i, b]
            Pzz[a, b] = acc
    for a in range(n):
        for b in range(m):
            acc = 0.0
            for i in range(p):
                acc += Y[i, a] * wc[i] * Z[i, b]
            K[a, b] = acc
    # statistical linearisation: G = Σ wc ξ dZᵀ with ξ = 0, ±c e_j; E = dZ − ξ G
    for a in range(n):
        for b in range(m):
            Gm[a, b] = wc[1 + a] * c * Z[1 + a, b] + wc[1 + n + a] * (-c) * Z[1 + n + a, b]
    for b in range(m):
        E[0, b] = Z[0, b]
    for a in range(n):
        for b in range(m):
            E[1 + a, b] = Z[1 + a, b] - c * Gm[a, b]
            E[1 + n + a, b] = Z[1 + n + a, b] + c * Gm[a, b]
    # -- update with the measured components
    dof = 0
    for j in range(m):
        if valid[j]:
            dof += 1
            nu[j] = _residual_comp(angle, j, z[j] - zp[j])
        else:
            nu[j] = 0.0
    if dof == 0:
        for a in range(n):
            mean[a] = xp[a]
        return
    for a in range(m):
        for b in range(m):
            if valid[a] and valid[b]:
                S[a, b] = 0.5 * ((Pzz[a, b] + R[a, b]) + (Pzz[b, a] + R[b, a]))
            else:
                S[a, b] = 1.0 if a == b else 0.0
    for a in range(n):
        for b in range(m):
            if not valid[b]:
                K[a, b] = 0.0
    # K = Pxz S⁻¹ by a Cholesky solve per row
    if cholesky_inplace(S, LS):
        for a in range(n):
            for b in range(m):  # forward: LS y = Pxz[a]
                acc = K[a, b]
                for q in range(b):
                    acc -= LS[b, q] * K[a, q]
                K[a, b] = acc / LS[b, b]
            for b in range(m - 1, -1, -1):  # backward: LSᵀ k = y
                acc = K[a, b]
                for q in range(b + 1, m):
                    acc -= LS[q, b] * K[a, q]
                K[a, b] = acc / LS[b, b]
    else:
        Si = np.linalg.pinv(S)
        Kt = K.copy()
        for a in range(n):
            for b in range(m):
                acc = 0.0
                for q in range(m):
                    acc += Kt[a, q] * Si[q, b]
                K[a, b] = acc
    for a in range(n):
        acc = 0.0
        for j in range(m):
            acc += K[a, j] * nu[j]
        mean[a] = xp[a] + acc
    # Joseph form through the points' factor: A_L = L − K Gᵀ
    for a in range(n):
        for b in range(n):
            acc = 0.0
            for j in range(m):
                acc += K[a, j] * Gm[b, j]
            AL[a, b] = L[a, b] - acc
    if upf.gram:  # W Wᵀ with W = [A_L, K chol R, K Eᵀ diag √wc]; the last two blocks transposed in KC and W
        Rc = upf.R_chol
        W = chi  # (p, n) scratch: the points are no longer needed
        for i in range(p):  # KE[i, a] = √wc_i Σ_q K[a, q] E[i, q]
            sw = math.sqrt(wc[i])
            for a in range(n):
                acc = 0.0
                for q_ in range(m):
                    acc += K[a, q_] * E[i, q_]
                W[i, a] = sw * acc
        for j in range(m):  # KC[j, a] = Σ_q K[a, q] Rc[q, j]
            for a in range(n):
                acc = 0.0
                for q_ in range(m):
                    acc += K[a, q_] * Rc[q_, j]
                KC[j, a] = acc
        for a in range(n):
            for b in range(a, n):
                acc = 0.0
                for j in range(n):
                    acc += AL[a, j] * AL[b, j]
                for j in range(m):
                    acc += KC[j, a] * KC[j, b]
                for i in range(p):
                    acc += W[i, a] * W[i, b]
                cov[a, b] = acc
                cov[b, a] = acc
    else:  # A_L A_Lᵀ + K (R_eff + D) Kᵀ
        for a in range(m):
            for b in range(m):
                acc = 0.0
                if valid[a] and valid[b]:
                    for i in range(p):
                        acc += E[i, a] * wc[i] * E[i, b]
                    acc += R[a, b]
                elif a == b:
                    acc = 1.0
                Pzz[a, b] = acc
        for a in range(n):
            for b in range(a, n):
                acc = 0.0
                for j in range(n):
                    acc += AL[a, j] * AL[b, j]
                for q in range(m):
                    for j in range(m):
                        acc += K[a, q] * Pzz[q, j] * K[b, j]
                cov[a, b] = acc
                cov[b, a] = acc


@njit(**_NJ)
def _select(r, N, logw, draws, upf, order, u, key):
    """The particles in the order the NumPy step takes them: the n_u important ones first."""
    n_u = upf.n_u
    for i in range(N):
        order[i] = i
    if n_u == 0 or n_u == N or upf.select == SELECT_BLOCK:
        return
    fill_random(draws.addrs[r], u)
    o1 = np.argsort(u)  # the uniforms are distinct: any sort gives NumPy's order
    if upf.select == SELECT_WEIGHT and not upf.uniform:
        # lexsort((u, −logw)): largest weights first, ties in the order of u (a stable sort after sorting by u)
        for i in range(N):
            key[i] = -logw[r, o1[i]]
        o2 = np.argsort(key, kind="mergesort")
        for i in range(N):
            order[i] = o1[o2[i]]
    else:
        for i in range(N):
            order[i] = o1[i]


@njit(**_NJ)
def _upf_run(r, X, P, logw, z, valid, draws, motion, sensor, upf, opts, pf, Pout, repaired):
    """The whole step of run r (module docstring); ``pf`` a :class:`~.kernel_args.PFOutputs`, ``Pout`` and ``repaired`` the fields of a :class:`~.kernel_args.UPFOutputs`."""
    rkind, thr = opts
    P0 = upf.P0
    N, n = X.shape[1], X.shape[2]
    m = z.shape[1]
    n_u = upf.n_u
    n_r = N - n_u
    logN = math.log(N)
    mk, F, G, par = motion.kind, motion.F, motion.G, motion.par
    hk, A, idx, hscale, R, angle = sensor.kind, sensor.A, sensor.idx, sensor.scale, sensor.R, sensor.angle
    q = G.shape[1] if mk == LINEAR else 1
    addr = draws.addrs[r]
    order = np.empty(N, dtype=np.int64)
    u = np.empty(N)
    key = np.empty(N)
    _select(r, N, logw, draws, upf, order, u, key)
    # the normals: the UKF group's, then the prior group's process noise
    xi = np.empty(n_u * n)
    noise = np.empty(n_r * q)
    fill_normal(addr, xi)
    fill_normal(addr, noise)
    Xp = np.empty((N, n))
    Pn = np.empty((N, n * n))
    corr = np.zeros(N)
    ws = ukf_scratch(n, m, q)
    Pi = np.empty((n, n))
    Lq = np.empty((n, n))
    xb = np.empty(n)
    Pb = np.empty((n, n))
    fx = np.empty((1, n))
    zero1 = np.zeros(q)
    src1 = np.empty((1, n))
    rep = False
    Qi, Qld = upf.Q_inv_chol, upf.Q_logdiag
    for i in range(n_u):  # the UKF group: a proposal per particle, log p(x|x_prev) − log q(x)
        s = order[i]
        for a in range(n):
            for b in range(n):
                Pi[a, b] = P[r, s, a, b]
        ukf_one(X[r, s], Pi, z[r], valid[r], mk, F, G, par, hk, A, idx, hscale, angle, R, upf, ws, xb, Pb)
        for a in range(n):
            for b in range(n):
                Pn[i, a * n + b] = Pb[a, b]
        rep |= cholesky_psd_inplace(Pb, Lq)
        sq = 0.0
        ld = 0.0
        for a in range(n):
            acc = 0.0
            for j in range(a + 1):
                acc += Lq[a, j] * xi[i * n + j]
            Xp[i, a] = xb[a] + acc
            sq += xi[i * n + a] * xi[i * n + a]
            ld += math.log(Lq[a, a])
        log_q = -0.5 * sq - ld - 0.5 * n * LOG_2PI
        for a in range(n):
            src1[0, a] = X[r, s, a]
        propagate_point(mk, F, G, par, src1, 0, zero1, fx, 0)
        maha = 0.0
        for a in range(n):
            acc = 0.0
            for j in range(a + 1):
                acc += Qi[a, j] * (Xp[i, j] - fx[0, j])
            maha += acc * acc
        corr[i] = (-0.5 * maha - Qld - 0.5 * n * LOG_2PI) - log_q
    Xg = np.empty((n_r, n))  # the prior group: the transition prior
    for j in range(n_r):
        for a in range(n):
            Xg[j, a] = X[r, order[n_u + j], a]
    for j in range(n_r):
        propagate_point(mk, F, G, par, Xg, j, noise, Xp, n_u + j)
    # -- weigh: offset = log w_{k−1} + log N (in the new order), plus p/q for the UKF group
    offset = np.empty(N)
    nonzero = 0  # counted, not a flag set to literal True/False: numba would compile predictive_run for Literal[bool] too
    for i in range(N):
        o = 0.0 if upf.uniform else logw[r, order[i]] + logN
        offset[i] = o
        if o != 0.0:
            nonzero += 1
    Zp = np.empty((N, m))
    ll = np.empty(N)
    const, measured = measure_run(sensor, Xp, z[r], valid[r], Zp, ll)
    pred = np.empty(N)  # predictive weights as exp(pred)/N
    if n_u > 0:
        top = -np.inf
        for i in range(N):
            v = corr[i] + offset[i]
            if math.isnan(v):
                v = -np.inf
            offset[i] = v
            top = max(top, v)
        t0 = top if math.isfinite(top) else 0.0
        sew = 0.0
        for i in range(N):
            sew += math.exp(offset[i] - t0)
        shift = math.log(sew) - logN
        for i in range(N):
            pred[i] = (offset[i] - t0) - shift
    else:
        for i in range(N):
            pred[i] = offset[i]
    uniform = nonzero == 0 and n_u == 0  # the UKF group's p/q makes the weights non-uniform
    Ls = np.empty((m, m))
    tmp = np.empty(m)
    pf.nis[r], pf.dof[r] = predictive_run(sensor, Zp, pred, uniform, z[r], valid[r], pf.innov[r], pf.S[r], Ls, tmp)
    a_ = np.empty(N)
    for i in range(N):
        a_[i] = ll[i] + offset[i]
    e = np.empty(N)
    mx, s_, s2, rst = exp_shifted_run(a_, offset, not (n_u == 0 and upf.uniform), e)
    ls = math.log(s_)
    lk = mx + ls + ((const if measured else 0.0) - logN)
    if rst:
        lk = -np.inf
    pf.loglik[r] = lk if measured else 0.0
    pf.reset[r] = rst
    moments_run(Xp, e, s_, pf.mean[r], pf.cov[r])
    es = s_ * s_ / s2
    pf.ess[r] = es
    need = measured and (thr < 0 or es < thr * N)
    pf.need[r] = need
    repaired[r] = rep
    # -- per-particle covariances (U3), in the new order
    C = pf.cov[r]
    mode = upf.cov_mode
    if mode == COV_ZERO:
        for i in range(N):
            for a in range(n):
                for b in range(n):
                    Pn[i, a * n + b] = _JITTER if a == b else 0.0
    elif n_r > 0:
        for j in range(n_r):
            i = n_u + j
            if mode == COV_POPULATION:
                for a in range(n):
                    for b in range(n):
                        Pn[i, a * n + b] = C[a, b] + (_JITTER if a == b else 0.0)
            elif mode == COV_RESET:
                for a in range(n):
                    for b in range(n):
                        Pn[i, a * n + b] = P0[r, a, b]
            else:  # F P Fᵀ + Q (linear motion)
                s = order[i]
                for a in range(n):
                    for b in range(n):
                        acc = 0.0
                        for c1 in range(n):
                            t = 0.0
                            for c2 in range(n):
                                t += P[r, s, c1, c2] * F[b, c2]
                            acc += F[a, c1] * t
                        Pn[i, a * n + b] = acc + upf.Q[a, b]
    # -- resample particles and covariances together
    lw = pf.logw[r]
    if need:
        U = np.empty(n_uniforms(rkind, N))
        fill_random(addr, U)
        c = np.empty(N)
        tmp2 = np.empty(N)
        counts = np.empty(N, dtype=np.int64)
        resample_counts(rkind, e, U, c, tmp2, counts)
        copy_by_counts(Xp, counts, pf.particles[r])
        copy_by_counts(Pn, counts, Pout[r])
        for i in range(N):
            lw[i] = -logN
    else:
        pf.particles[r] = Xp
        Pout[r] = Pn
        for i in range(N):
            lw[i] = a_[i] - ls


def _upf_step(particles, obs, draws, motion, sensor, upf, opts, out, extra):
    """One partial-UPF step for every run (outputs written in place).

    ``particles`` is ``(X (B, N, n), P (B, N, n, n), logw (B, N))``, ``obs``
    ``(z (B, m), valid (B, m))``, ``draws`` a :class:`~.kernel_args.Draws`
    with every run's own stream, ``motion`` / ``sensor`` the packed models,
    ``upf`` a :class:`~.kernel_args.UPFArgs`, ``opts`` a
    :class:`~.kernel_args.PFOptions`, ``out`` a
    :class:`~.kernel_args.PFOutputs` and ``extra`` a
    :class:`~.kernel_args.UPFOutputs` (apart: a parallel loop takes no
    nested tuple).
    """
    X, P, logw = particles
    z, valid = obs
    Pout, repaired = extra
    for rr in prange(X.shape[0]):
        r = np.int64(rr)  # prange counts in uint64
        _upf_run(r, X, P, logw, z, valid, draws, motion, sensor, upf, opts, out, Pout, repaired)


upf_step_serial, upf_step_parallel = serial_and_parallel(_upf_step, cache=True, error_model="numpy")
