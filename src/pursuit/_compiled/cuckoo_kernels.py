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
from .model_math import h_row
from .pf_kernels import exp_shifted_run, measure_run, moments_run, predictive_run
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
def _fitness(sensor, X, i, z, valid, measured, full, hbuf):
    """Fitness of particle ``X[i]``, with the NumPy filter's arithmetic (0 where nothing is measured).

    ``full=False``: −½ νᵀR⁻¹ν as Σ ν_j² (−½/R_jj) (the stock fast path);
    ``full=True``: the whole log-density −½ Σ (ν_j²/R_jj + log R_jj + log 2π)
    (missing components, angle models), as ``gaussian_loglik``.  The search
    amplifies rounding differences, so the two forms are kept apart.
    ``hbuf`` (1, m) is scratch.
    """
    if not measured:
        return 0.0
    R, angle = sensor.R, sensor.angle
    h_row(sensor, X, i, hbuf, 0)
    acc = 0.0
    for j in range(z.shape[0]):
        if valid[j]:
            r = z[j] - hbuf[0, j]
            if angle and j == 1:
                r = wrap(r)
            if full:
                acc += r * r / R[j, j] + (math.log(R[j, j]) + LOG_2PI)
            else:
                acc += r * r * (-0.5 / R[j, j])
    return -0.5 * acc if full else acc


@njit(cache=True, error_model="numpy")
def _greedy(X, F, C, sensor, z, valid, measured, add, lower, upper, hbuf):
    """Keep each candidate row of C whose fitness is strictly higher; returns the number accepted."""
    N, n = X.shape
    acc = 0
    for i in range(N):
        for j in range(n):
            c = C[i, j]
            if c < lower[j]:
                c = lower[j]
            if c > upper[j]:
                c = upper[j]
            C[i, j] = c
        fc = _fitness(sensor, C, i, z, valid, measured, add, hbuf)
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
    fitness carries the normalising constant (:func:`_fitness`).
    """
    n_iter, alphas, pas, amin, amax = search.n_iter, search.alphas, search.pas, search.alpha_min, search.alpha_max
    trend, kappa, beta, sigma_u, scaling = search.trend, search.kappa, search.beta, search.sigma_u, search.scaling
    yang, log_stop, use_stop, lower, upper = search.yang, search.log_stop, search.use_stop, search.lower, search.upper
    N, n = X.shape
    kk = 3 if scaling == SCALE_RELATIVE else 2
    C = np.empty((N, n))
    hbuf = np.empty((1, z.shape[0]))
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
        accepted += _greedy(X, F, C, sensor, z, valid, measured, add, lower, upper, hbuf)
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
        accepted += _greedy(X, F, C, sensor, z, valid, measured, add, lower, upper, hbuf)
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
        uniform = True
        if with_prior:
            for i in range(N):
                offset[i] = logw[r, i] + logN
                if offset[i] != 0.0:
                    uniform = False
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
        # fitness of the propagated particles, then the search
        add = include_const
        F = np.empty(N)
        if include_const:
            hb = np.empty((1, m))
            for i in range(N):
                F[i] = _fitness(sensor, Xp, i, z[r], valid[r], measured, True, hb)
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
