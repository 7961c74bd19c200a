"""Compiled cuckoo-search particle filters (CS-PF, ICS-PF): one step for a batch of runs, parallel over runs.

Follows :class:`pursuit.filters.cuckoo.CuckooParticleFilter` step by step
(see that module's docstring): propagate, the predictive statistics and
likelihood increment of the propagated particles, ``n_iter`` iterations of
Lévy flight and discovery with greedy selection, the weights and estimate
of the moved particles, and in sequential mode resampling on low ESS.

Random numbers per run, in the NumPy filter's order: the process noise, the
normals of all iterations, the uniforms of all iterations, then the
resampler's uniforms.  The caller propagates the particles with the motion
model's own NumPy ``sample`` (so the propagated particles are bitwise those
of the NumPy filter: the search amplifies any rounding difference in them);
with RunStreams of PCG64 generators (``per_run``) each run then draws its
search numbers from its own stream inside the kernel
(:mod:`pursuit._compiled.streams`) into the buffers ``normals`` and
``uniforms``; otherwise the caller fills them with NumPy.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .common import LOG_2PI, copy_by_counts, n_uniforms, resample_counts, serial_and_parallel, wrap
from .model_math import h_linear, h_point, h_range, h_range_bearing, h_ungm
from .pf_kernels import _weigh_run, exp_shifted_run, measure_run, moments_run, predictive_run
from .specs import M_LINEAR, M_RANGE, M_RANGE_BEARING, M_UNGM
from .streams import fill_normal, fill_random

_EPS = 1e-12

# option codes
SCALE_RELATIVE = 0
SCALE_ABSOLUTE = 1
SCALE_STD = 2
TREND_OFF = 0
TREND_EXP = 1
TREND_LINEAR = 2


@njit(cache=True, error_model="numpy")
def _h_rows(sensor, X, i0, i1, H):
    """``H[i] = h(X[i])`` for rows ``i0 ≤ i < i1``, the branch on the sensor taken once, outside the loop.

    A particle loop around :func:`~.model_math.h_row` (four sensor branches
    inlined in its body) cost about 250 ns a particle here against about
    10 ns for one sensor's formula alone: hence one loop per branch.  The
    same formulas, so the same bits; a sensor without its loop here goes
    through ``h_point``.
    """
    kind, A, idx, scale = sensor.kind, sensor.A, sensor.idx, sensor.scale
    if kind == M_RANGE:
        for i in range(i0, i1):
            h_range(A, idx, scale, X, i, H, i)
    elif kind == M_RANGE_BEARING:
        for i in range(i0, i1):
            h_range_bearing(A, idx, scale, X, i, H, i)
    elif kind == M_UNGM:
        for i in range(i0, i1):
            h_ungm(A, idx, scale, X, i, H, i)
    elif kind == M_LINEAR:
        for i in range(i0, i1):
            h_linear(A, idx, scale, X, i, H, i)
    else:
        for i in range(i0, i1):
            h_point(kind, A, idx, scale, X, i, H, i)


@njit(cache=True, error_model="numpy")
def _fit_consts(R, full):
    """Per component: −½/R_jj (the fast form's factor) or log R_jj + log 2π (the full form's constant) of :func:`_fitness_rows`."""
    m = R.shape[0]
    c = np.empty(m)
    for j in range(m):
        c[j] = (math.log(R[j, j]) + LOG_2PI) if full else -0.5 / R[j, j]
    return c


@njit(cache=True, error_model="numpy")
def _fitness_rows(sensor, X, i0, i1, z, valid, measured, full, cst, H, F):
    """Fitness ``F[i]`` of the particles ``X[i]``, ``i0 ≤ i < i1``, with the NumPy filter's arithmetic (0 where nothing is measured).

    ``full=False``: −½ νᵀR⁻¹ν as Σ ν_j² (−½/R_jj) (the stock fast path);
    ``full=True``: the whole log-density −½ Σ (ν_j²/R_jj + log R_jj + log 2π)
    (missing components, angle models), as ``gaussian_loglik``.  The search
    amplifies rounding differences, so the two forms are kept apart.
    ``cst`` is :func:`_fit_consts` of the same ``full`` (the same bits as
    forming the factors in the loop), ``H`` (N, m) scratch.
    """
    if not measured:
        for i in range(i0, i1):
            F[i] = 0.0
        return
    _h_rows(sensor, X, i0, i1, H)
    R, angle = sensor.R, sensor.angle
    m = z.shape[0]
    for i in range(i0, i1):
        acc = 0.0
        for j in range(m):
            if valid[j]:
                r = z[j] - H[i, j]
                if angle and j == 1:
                    r = wrap(r)
                if full:
                    acc += r * r / R[j, j] + cst[j]
                else:
                    acc += r * r * cst[j]
        F[i] = -0.5 * acc if full else acc


@njit(cache=True, error_model="numpy")
def _greedy(X, F, C, sensor, z, valid, measured, add, lower, upper, cst, H, Fc):
    """Keep each candidate row of C whose fitness is strictly higher; returns the number accepted.

    The candidates are complete before any replacement, so they are clipped and
    measured as one batch (:func:`_fitness_rows`; ``cst``, ``H``, ``Fc`` its scratch).
    """
    N, n = X.shape
    for i in range(N):
        for j in range(n):
            c = C[i, j]
            if c < lower[j]:
                c = lower[j]
            if c > upper[j]:
                c = upper[j]
            C[i, j] = c
    _fitness_rows(sensor, C, np.int64(0), N, z, valid, measured, add, cst, H, Fc)  # int64, not Literal[0]: one signature (docs/testing.md)
    acc = 0
    for i in range(N):
        fc = Fc[i]
        if fc > F[i]:
            F[i] = fc
            for j in range(n):
                X[i, j] = C[i, j]
            acc += 1
    return acc


@njit(cache=True, error_model="numpy")
def _argmax(F):
    best = 0
    for i in range(1, F.shape[0]):
        if F[i] > F[best]:
            best = i
    return best


@njit(cache=True, error_model="numpy")
def _mantegna(u, v, beta, sigma_u):
    a = abs(v)
    if beta == 1.5:
        a = np.cbrt(a * a)
    elif beta == 2.0:
        a = math.sqrt(a)
    elif beta != 1.0:
        a = a ** (1.0 / beta)
    return (u * sigma_u) / a


@njit(cache=True, error_model="numpy")
def search_run(X, F, normals, uniforms, search, sensor, z, valid, measured, add):
    """The cuckoo search of one run, in place on X (N, n) and F (N,); returns (iterations, accepted).

    ``search`` is a :class:`~.kernel_args.SearchArgs`, ``normals`` and
    ``uniforms`` the run's draws for all iterations, ``add`` whether the
    fitness carries the normalising constant (:func:`_fitness_rows`).
    """
    n_iter, alphas, pas, amin, amax = search.n_iter, search.alphas, search.pas, search.alpha_min, search.alpha_max
    trend, kappa, beta, sigma_u, scaling = search.trend, search.kappa, search.beta, search.sigma_u, search.scaling
    yang, log_stop, use_stop, lower, upper = search.yang, search.log_stop, search.use_stop, search.lower, search.upper
    N, n = X.shape
    kk = 3 if scaling == SCALE_RELATIVE else 2
    C = np.empty((N, n))
    cst = _fit_consts(sensor.R, add)
    H = np.empty((N, z.shape[0]))
    Fc = np.empty(N)
    f_prev = np.empty(N)
    f_start = np.empty(N)
    alpha = np.empty(N)
    sd = np.empty(n)
    iterations = 0
    accepted = 0
    for t in range(n_iter):
        if use_stop:
            fmax = -np.inf
            for i in range(N):
                if F[i] > fmax:
                    fmax = F[i]
            if not (fmax < log_stop):
                break
        iterations += 1
        a_t = alphas[t]
        for i in range(N):
            alpha[i] = a_t
        if trend != 0:
            for i in range(N):
                f_start[i] = math.exp(F[i])
            if t > 0:
                for i in range(N):
                    delta = (f_start[i] - f_prev[i]) / (f_prev[i] + _EPS)
                    fac = math.exp(-kappa * delta) if trend == TREND_EXP else 1.0 + kappa * delta
                    alpha[i] = min(max(a_t * fac, amin), amax)
            for i in range(N):
                f_prev[i] = f_start[i]
        base = t * kk * N * n
        # 1. Lévy flight
        if scaling == SCALE_RELATIVE:
            b = _argmax(F)
            for i in range(N):
                for j in range(n):
                    p = i * n + j
                    L = _mantegna(normals[base + p], normals[base + N * n + p], beta, sigma_u)
                    st = L * (X[i, j] - X[b, j]) * normals[base + 2 * N * n + p]
                    C[i, j] = X[i, j] + st * alpha[i]
        else:
            if scaling == SCALE_STD:
                for j in range(n):
                    mu = 0.0
                    for i in range(N):
                        mu += X[i, j]
                    mu /= N
                    v = 0.0
                    for i in range(N):
                        d = X[i, j] - mu
                        v += d * d
                    sd[j] = math.sqrt(v / N)
            for i in range(N):
                for j in range(n):
                    p = i * n + j
                    st = _mantegna(normals[base + p], normals[base + N * n + p], beta, sigma_u)
                    if scaling == SCALE_STD:
                        st *= sd[j]
                    C[i, j] = X[i, j] + st * alpha[i]
        accepted += _greedy(X, F, C, sensor, z, valid, measured, add, lower, upper, cst, H, Fc)
        # 2. discovery
        ub = t * (N * n + 1 + 2 * N)
        pa = pas[t]
        r = uniforms[ub + N * n]
        p1 = np.argsort(uniforms[ub + N * n + 1: ub + N * n + 1 + N])
        p2 = np.argsort(uniforms[ub + N * n + 1 + N: ub + N * n + 1 + 2 * N])
        for i in range(N):
            for j in range(n):
                s = uniforms[ub + i * n + j]
                K = (s > pa) if yang else (s < pa)
                d = (X[p1[i], j] - X[p2[i], j]) * (1.0 if K else 0.0)
                C[i, j] = X[i, j] + d * r
        # candidates read X before any greedy replacement (as the NumPy step): C is complete here
        accepted += _greedy(X, F, C, sensor, z, valid, measured, add, lower, upper, cst, H, Fc)
    return iterations, accepted


def _cuckoo_step(particles, draws, obs, sensor, search, opts, out):
    """One CS-PF / ICS-PF step for every run; outputs in place (module docstring).

    ``particles`` is ``(Xprop (B, N, n) propagated, logw (B, N))``, ``draws``
    ``(normals (B, ·), uniforms (B, ·), Draws)``, ``obs`` ``(z, valid)``,
    ``sensor`` the packed measurement model, ``search`` a
    :class:`~.kernel_args.SearchArgs`, ``opts`` a
    :class:`~.kernel_args.CuckooOptions` and ``out`` a
    :class:`~.kernel_args.CuckooOutputs`.
    """
    Xprop, logw = particles
    normals, uniforms, streams = draws
    addrs, per_run = streams
    z, valid = obs
    state_uniform, sequential, include_const, best_estimate, rkind, thr = opts
    n_iter = search.n_iter
    pf = out.pf
    Xout, logw_out, mean, cov, innov, S = pf.particles, pf.logw, pf.mean, pf.cov, pf.innov, pf.S
    nis, dof, loglik, reset, ess, need = pf.nis, pf.dof, pf.loglik, pf.reset, pf.ess, pf.need
    fbest, iters, acc = out.fitness_best, out.iterations, out.accepted
    M, N, n = Xprop.shape
    for rr in prange(M):
        r = np.int64(rr)
        logN = math.log(N)
        Xp = Xprop[r].copy()
        m = z.shape[1]
        Zp = np.empty((N, m))
        ll = np.empty(N)
        const, measured = measure_run(sensor, Xp, z[r], valid[r], Zp, ll)
        with_prior = sequential and not state_uniform
        offset = np.zeros(N)
        nonzero = 0  # counted, not a flag set to literal True/False: numba would compile the callee for Literal[bool] too
        if with_prior:
            for i in range(N):
                offset[i] = logw[r, i] + logN
                if offset[i] != 0.0:
                    nonzero += 1
        uniform = nonzero == 0
        L = np.empty((m, m))
        tmp = np.empty(m)
        nis[r], dof[r] = predictive_run(sensor, Zp, offset, uniform, z[r], valid[r], innov[r], S[r], L, tmp)
        a = np.empty(N)
        for i in range(N):
            a[i] = ll[i] + offset[i]
        e = np.empty(N)
        mx, s, s2, rst = exp_shifted_run(a, offset, with_prior, e)
        lk = mx + math.log(s) + ((const if measured else 0.0) - logN)
        loglik[r] = (-np.inf if rst else lk) if measured else 0.0
        # fitness of the propagated particles, then the search; a run with a missing component carries
        # the normalising constant in its fitness (the NumPy filter chooses so run by run)
        n_valid = 0
        for j in range(m):
            if valid[r, j]:
                n_valid += 1
        add = include_const or n_valid < m
        F = np.empty(N)
        if add:
            # add (True here) and np.int64(0), not literals: the signature the other callers use
            _fitness_rows(sensor, Xp, np.int64(0), N, z[r], valid[r], measured, add,
                          _fit_consts(sensor.R, add), np.empty((N, m)), F)
        else:
            for i in range(N):
                F[i] = ll[i] if measured else 0.0
        if per_run and n_iter > 0:
            fill_normal(addrs[r], normals[r])
            fill_random(addrs[r], uniforms[r])
        it, ac = search_run(Xp, F, normals[r], uniforms[r], search, sensor, z[r], valid[r], measured, add)
        iters[r] = it
        acc[r] = ac
        # weights of the moved particles
        lw = logw_out[r]
        for i in range(N):
            lw[i] = F[i] + logw[r, i] if with_prior else F[i]
        fb = np.empty(N)
        for i in range(N):
            fb[i] = logw[r, i]
        mx2, s2_, ss2, rst2 = exp_shifted_run(lw, fb, with_prior, e)
        reset[r] = rst2
        ess[r] = s2_ * s2_ / ss2
        if best_estimate:
            b = _argmax(F)
            for j in range(n):
                mean[r, j] = Xp[b, j]
            C = cov[r]
            for p in range(n):
                for q in range(n):
                    C[p, q] = 0.0
            d = np.empty(n)
            for i in range(N):
                w = e[i] / s2_
                for j in range(n):
                    d[j] = Xp[i, j] - mean[r, j]
                for p in range(n):
                    for q in range(n):
                        C[p, q] += w * d[p] * d[q]
            for p in range(n):
                for q in range(p + 1, n):
                    v = 0.5 * (C[p, q] + C[q, p])
                    C[p, q] = v
                    C[q, p] = v
        else:
            moments_run(Xp, e, s2_, mean[r], cov[r])
        ls = math.log(s2_)
        for i in range(N):
            lw[i] -= ls
        fmax = -np.inf
        for i in range(N):
            if F[i] > fmax:
                fmax = F[i]
        fbest[r] = fmax
        nd = sequential and measured and (thr < 0 or ess[r] < thr * N)
        need[r] = nd
        if nd and per_run:
            nu = n_uniforms(rkind, N)
            U = np.empty(nu)
            fill_random(addrs[r], U)
            c = np.empty(N)
            tmp2 = np.empty(N)
            counts = np.empty(N, dtype=np.int64)
            resample_counts(rkind, e, U, c, tmp2, counts)
            copy_by_counts(Xp, counts, Xout[r])
            for i in range(N):
                lw[i] = -logN
        else:
            Xout[r] = Xp


cuckoo_step_serial, cuckoo_step_parallel = serial_and_parallel(_cuckoo_step, cache=True, error_model="numpy")


# --------------------------------------------------------------------------
# acceptance="mh": resample-move with Metropolis-Hastings cuckoo moves
# --------------------------------------------------------------------------
@njit(cache=True, error_model="numpy")
def _mh_half(i0, i1, P, X, Mx, XI, F, LT, G, U, ub, sensor, z, valid, measured, add, cst, Xn, H, Fn):
    """Metropolis tests of the proposals ``P[i0:i1]`` (noise) of one half, in place; returns the number accepted.

    The arithmetic of :func:`pursuit.filters.cuckoo_mh.mh_moves`: x = m + Σ_c G[:, c] ξ_c
    column by column, log π = (Σ_c ξ_c²)(−½) + fitness, accept when log u < Δ.  The
    particles of a half are independent given the other half, so the proposals are
    measured as one batch (:func:`_fitness_rows`) before the tests.  The test is
    written ``u − 1 < Δ or log u < Δ`` as in the NumPy step: log u ≤ u − 1, so most
    accepted moves need no logarithm, and the decision is that of log u < Δ.
    """
    n, r = G.shape
    for i in range(i0, i1):
        for j in range(n):
            x = Mx[i, j]
            for c in range(r):
                x += G[j, c] * P[i, c]
            Xn[i, j] = x
    _fitness_rows(sensor, Xn, i0, i1, z, valid, measured, add, cst, H, Fn)
    acc = 0
    for i in range(i0, i1):
        q = P[i, 0] * P[i, 0]
        for c in range(1, r):
            q += P[i, c] * P[i, c]
        ltn = q * -0.5 + Fn[i]
        d = ltn - LT[i]
        u = U[ub + i]
        if u - 1.0 < d or math.log(u) < d:
            for c in range(r):
                XI[i, c] = P[i, c]
            for j in range(n):
                X[i, j] = Xn[i, j]
            F[i] = Fn[i]
            LT[i] = ltn
            acc += 1
    return acc


@njit(cache=True, error_model="numpy")
def _other_mean(F, i0, i1):
    """Mean of exp(F[i0:i1]) summed left to right (0 for an empty half)."""
    if i1 <= i0:
        return 0.0
    acc = 0.0
    for i in range(i0, i1):
        acc += math.exp(F[i])
    return acc / (i1 - i0)


@njit(cache=True, error_model="numpy")
def mh_search_run(X, Mx, XI, F, G, normals, uniforms, search, sensor, z, valid, measured, add):
    """The MH cuckoo moves of one run, in place on X (N, n), XI (N, r), F (N,); returns the accepted moves.

    ``normals`` (n_iter·2·N·r) and ``uniforms`` (n_iter·(N(r+3)+2)) are the
    run's draws in the layout of :func:`pursuit.filters.cuckoo_mh.mh_layout`.
    Each half's proposals are formed, then tested as a batch (:func:`_mh_half`):
    the order of the NumPy step, which the decisions do not depend on within a half.
    """
    n_iter, alphas, pas, amin, amax = search.n_iter, search.alphas, search.pas, search.alpha_min, search.alpha_max
    trend, kappa, beta, sigma_u, yang = search.trend, search.kappa, search.beta, search.sigma_u, search.yang
    N, n = X.shape
    r = G.shape[1]
    m = z.shape[0]
    h = N // 2
    size = N * r + 3 * N + 2
    LT = np.empty(N)
    for i in range(N):
        q = XI[i, 0] * XI[i, 0]
        for c in range(1, r):
            q += XI[i, c] * XI[i, c]
        LT[i] = q * -0.5 + F[i]
    P = np.empty((N, r))
    Xn = np.empty((N, n))
    H = np.empty((N, m))
    Fn = np.empty(N)
    cst = _fit_consts(sensor.R, add)
    starts = (0, h)
    ends = (h, N)
    alpha = np.empty(2)
    fprev = np.empty(2)
    fnow = np.empty(2)
    accepted = 0
    for t in range(n_iter):
        a_t = alphas[t]
        pa = pas[t]
        ub = t * size
        alpha[0] = a_t
        alpha[1] = a_t
        if trend != TREND_OFF:
            fnow[0] = _other_mean(F, h, N)
            fnow[1] = _other_mean(F, np.int64(0), h)  # int64, not Literal[0]: the signature of the call above
            if t > 0:
                for j in range(2):
                    delta = (fnow[j] - fprev[j]) / (fprev[j] + _EPS)
                    fac = math.exp(-kappa * delta) if trend == TREND_EXP else 1.0 + kappa * delta
                    alpha[j] = min(max(a_t * fac, amin), amax)
            fprev[0] = fnow[0]
            fprev[1] = fnow[1]
        # Lévy flights, A then B
        nu = (t * 2) * N * r
        nv = (t * 2 + 1) * N * r
        for j in range(2):
            aj = alpha[j]
            for i in range(starts[j], ends[j]):
                for c in range(r):
                    L = _mantegna(normals[nu + i * r + c], normals[nv + i * r + c], beta, sigma_u)
                    P[i, c] = XI[i, c] + L * aj
            accepted += _mh_half(starts[j], ends[j], P, X, Mx, XI, F, LT, G, uniforms, ub + N * r + N,
                                 sensor, z, valid, measured, add, cst, Xn, H, Fn)
        # discovery, partners from the other half
        for j in range(2):
            o0 = starts[1 - j]
            mo = ends[1 - j] - o0
            if mo < 2:
                continue
            npairs = mo * (mo - 1)
            gamma = uniforms[ub + N * r + 3 * N + j]
            for i in range(starts[j], ends[j]):
                idx = math.floor(uniforms[ub + N * r + i] * npairs)
                if idx > npairs - 1:
                    idx = npairs - 1
                k = np.int64(idx)
                p1 = k // (mo - 1)
                qq = k - p1 * (mo - 1)
                p2 = qq + (1 if qq >= p1 else 0)
                for c in range(r):
                    s = uniforms[ub + i * r + c]
                    K = (s > pa) if yang else (s < pa)
                    d = (XI[o0 + p1, c] - XI[o0 + p2, c]) * (1.0 if K else 0.0)
                    d *= gamma
                    P[i, c] = XI[i, c] + d
            accepted += _mh_half(starts[j], ends[j], P, X, Mx, XI, F, LT, G, uniforms, ub + N * r + 2 * N,
                                 sensor, z, valid, measured, add, cst, Xn, H, Fn)
    return accepted


@njit(cache=True, error_model="numpy")
def _mh_run(b, particles, buffers, streams, obs, G, sensor, search, opts, pf, stats):
    """The MH step of run b (:func:`_mh_step`)."""
    Xprop, Mprop, XIprop, logw = particles
    ures, normals, uniforms = buffers
    z, valid = obs
    fbest, iters, accepted = stats
    addrs, per_run = streams
    include_const, weighted, rkind = opts
    n_iter = search.n_iter
    N, n = Xprop.shape[1], Xprop.shape[2]
    r = G.shape[1]
    logN = math.log(N)
    e = np.empty(N)
    # the bootstrap PF's measurement step: info, weighted moments, ESS, need = measured
    _weigh_run(b, Xprop[b], logw, logN, z, valid, sensor, -1.0, pf, e)
    nd = pf.need[b]
    X = pf.particles[b]
    Mx = np.empty((N, n))
    XI = np.empty((N, r))
    if nd:
        U = ures[b]
        if per_run:
            fill_random(addrs[b], U)
        c = np.empty(N)
        tmp = np.empty(N)
        counts = np.empty(N, dtype=np.int64)
        resample_counts(rkind, e, U, c, tmp, counts)
        copy_by_counts(Xprop[b], counts, X)
        copy_by_counts(Mprop[b], counts, Mx)
        copy_by_counts(XIprop[b], counts, XI)
        lw = pf.logw[b]
        for i in range(N):
            lw[i] = -logN
    else:
        for i in range(N):
            for j in range(n):
                X[i, j] = Xprop[b, i, j]
                Mx[i, j] = Mprop[b, i, j]
            for c in range(r):
                XI[i, c] = XIprop[b, i, c]
    if per_run and n_iter > 0:
        fill_normal(addrs[b], normals[b])
        fill_random(addrs[b], uniforms[b])
    m = z.shape[1]
    n_valid = 0  # counted, not a flag set to literal True/False: numba would compile the callees for Literal[bool] too
    for j in range(m):
        if valid[b, j]:
            n_valid += 1
    measured = n_valid > 0
    add = include_const or n_valid < m  # a run with a missing component: the constant in its fitness
    F = np.empty(N)
    cst = _fit_consts(sensor.R, add)
    _fitness_rows(sensor, X, np.int64(0), N, z[b], valid[b], measured, add, cst, np.empty((N, m)), F)
    acc = 0
    if n_iter > 0:
        acc = mh_search_run(X, Mx, XI, F, G, normals[b], uniforms[b], search, sensor, z[b], valid[b], measured, add)
    if not weighted:
        # weights after the moves: uniform where the run resampled, else the (predictive) weights
        s = 0.0
        if nd:
            for i in range(N):
                e[i] = 1.0
            s = float(N)
        else:
            for i in range(N):
                s += e[i]
        moments_run(X, e, s, pf.mean[b], pf.cov[b])
    fmax = -np.inf
    for i in range(N):
        if F[i] > fmax:
            fmax = F[i]
    fbest[b] = fmax
    iters[b] = n_iter
    accepted[b] = acc


def _mh_step(particles, buffers, streams, obs, G, sensor, search, opts, pf, stats):
    """One CS-PF / ICS-PF step with MH moves for every run; outputs in place.

    ``particles`` is ``(X (B, N, n) propagated, M (B, N, n) = f(x_{k−1}), XI (B, N, r), logw (B, N))``,
    ``buffers`` ``(resampler uniforms (B, ·), normals (B, ·), uniforms (B, ·))``, filled here
    in that order when ``streams`` (a :class:`~.kernel_args.Draws`) is per run, ``obs``
    ``(z, valid)``, ``G`` (n, r) the noise factor, ``opts`` a :class:`~.kernel_args.MHOptions`,
    ``pf`` the :class:`~.kernel_args.PFOutputs` and ``stats`` ``(fitness_best, iterations, accepted)``.
    Every argument is a flat tuple, as numba's parallel loops need.
    """
    for rr in prange(particles[0].shape[0]):
        _mh_run(np.int64(rr), particles, buffers, streams, obs, G, sensor, search, opts, pf, stats)


mh_step_serial, mh_step_parallel = serial_and_parallel(_mh_step, cache=True, error_model="numpy")
