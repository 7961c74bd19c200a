"""Compiled bootstrap particle filter: one step, or the whole sequence, for a batch of runs, parallel over runs.

Each run is processed by one thread from start to end (propagate, weigh,
moments, resample) with its particles in cache, drawing from its own PCG64
stream (:mod:`.streams`, ``addrs``) in the same order as the NumPy filter
(process noise, then the resampler's uniforms), so run i's numbers do not
depend on the batch.  Where the kernels cannot draw themselves (one shared
Generator, or streams that are not distinct PCG64s) the caller draws the
noise with NumPy in the NumPy filter's order and passes it in
(``per_run=False``), and resampling is a second kernel after the caller has
drawn the uniforms of the runs that resample.  :func:`_pf_sequence` runs
all steps of each run in one call (the same step body, so the same bits).

The arithmetic follows :class:`pursuit.filters.particle.ParticleFilterBase`
step by step (see its module docstring for the meaning of every output);
only the summation order, ``exp`` (:func:`.common.exp_weight`, within 1 ulp
of libm's and vectorised) and its floor at −708 (denormal weights are set
to 0) differ, so estimates agree with NumPy's to rounding.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .common import (
    EXP_FLOOR,
    LOG_2PI,
    R_SYSTEMATIC,
    chol_quad,
    cholesky_inplace,
    copy_by_counts,
    exp_weight,
    n_uniforms,
    resample_counts,
    serial_and_parallel,
    wrap,
)
from .kernel_args import Motion, PFOutputs
from .model_math import h_point, h_row, propagate_point, propagate_row, ungm_h, ungm_mean
from .specs import LINEAR, M_LINEAR, M_RANGE, M_UNGM, UNGM
from .streams import fill_normal, fill_random, next_random


@njit(cache=True, error_model="numpy")
def propagate_run(motion, Xin, noise, Xout):
    """x_k = f(x_{k−1}) + noise for the N particles of one run (noise: N·q standard normals)."""
    for i in range(Xin.shape[0]):
        propagate_row(motion, Xin, i, noise, Xout, i)


@njit(cache=True, error_model="numpy")
def measure_run(sensor, X, z, valid, Zp, ll):
    """Predicted measurements Zp (N, m) and ll (N,) = −½ Σ_valid ν²/R_jj; returns the constant and measured flag."""
    R, angle = sensor.R, sensor.angle
    N = X.shape[0]
    m = z.shape[0]
    const = 0.0
    measured = False
    for j in range(m):
        if valid[j]:
            measured = True
            const += -0.5 * (math.log(R[j, j]) + LOG_2PI)
    for i in range(N):
        h_row(sensor, X, i, Zp, i)
        acc = 0.0
        for j in range(m):
            if valid[j]:
                r = z[j] - Zp[i, j]
                if angle and j == 1:
                    r = wrap(r)
                acc += r * r * (-0.5 / R[j, j])
        ll[i] = acc
    if not measured:
        for i in range(N):
            ll[i] = 0.0
    return const, measured


@njit(cache=True, error_model="numpy")
def predictive_run(sensor, Zp, offset, uniform, z, valid, innov, S, L, tmp):
    """Innovation, S and NIS of one run from predicted measurements and predictive weights exp(offset)/N."""
    R, angle = sensor.R, sensor.angle
    N, m = Zp.shape
    zhat = np.zeros(m)
    invN = 1.0 / N
    # weighted mean (about the first particle's value for an angle)
    for i in range(N):
        w = invN if uniform else math.exp(offset[i]) * invN
        for j in range(m):
            d = Zp[i, j]
            if angle and j == 1:
                d = wrap(d - Zp[0, j])
            zhat[j] += w * d
    if angle:
        zhat[1] += Zp[0, 1]
    P = np.zeros((m, m))
    D = np.empty(m)
    for i in range(N):
        w = invN if uniform else math.exp(offset[i]) * invN
        for j in range(m):
            d = Zp[i, j] - zhat[j]
            if angle and j == 1:
                d = wrap(d)
            D[j] = d
        for a in range(m):
            for b in range(a, m):
                P[a, b] += w * D[a] * D[b]
    dof = 0
    for a in range(m):
        nu = z[a] - zhat[a]
        if angle and a == 1:
            nu = wrap(nu)
        if valid[a]:
            dof += 1
            innov[a] = nu
            tmp[a] = nu
        else:
            innov[a] = np.nan
            tmp[a] = 0.0
        for b in range(m):
            if valid[a] and valid[b]:
                S[a, b] = (P[a, b] if a <= b else P[b, a]) + R[a, b]
            else:
                S[a, b] = 1.0 if a == b else 0.0
    nis = np.nan
    if dof > 0 and cholesky_inplace(S, L):
        nis = chol_quad(L, tmp.copy(), tmp)
    return nis, dof


@njit(cache=True, error_model="numpy")
def exp_shifted_run(a, fallback, has_fallback, e):
    """e = exp(a − max a) with NaN as −inf and the zero-likelihood recovery; returns (mx, s, s2, reset)."""
    N = a.shape[0]
    mx = -np.inf
    for i in range(N):
        v = a[i]
        if math.isnan(v):
            v = -np.inf
            a[i] = v
        if v > mx:
            mx = v
    reset = False
    if math.isinf(mx) and mx > 0:  # infinite densities share the weight
        for i in range(N):
            a[i] = 0.0 if (math.isinf(a[i]) and a[i] > 0) else -np.inf
        mx = 0.0
    elif not math.isfinite(mx):
        reset = True
        mx = -np.inf
        for i in range(N):
            a[i] = fallback[i] if has_fallback else 0.0
            if a[i] > mx:
                mx = a[i]
    s = 0.0
    s2 = 0.0
    for i in range(N):
        sh = a[i] - mx
        a[i] = sh
        v = math.exp(sh) if sh > EXP_FLOOR else 0.0
        e[i] = v
        s += v
        s2 += v * v
    return mx, s, s2, reset


@njit(cache=True, error_model="numpy")
def moments_run(X, e, s, mean, cov):
    """Weighted mean (n,) and covariance (n, n) of one run's particles (zero-weight particles skipped)."""
    N, n = X.shape
    inv = 1.0 / s
    for j in range(n):
        mean[j] = 0.0
    for i in range(N):
        w = e[i]
        if w > 0:
            for j in range(n):
                mean[j] += w * X[i, j]
    for j in range(n):
        mean[j] *= inv
    for a in range(n):
        for b in range(n):
            cov[a, b] = 0.0
    d = np.empty(n)
    for i in range(N):
        w = e[i]
        if w > 0:
            for j in range(n):
                d[j] = X[i, j] - mean[j]
            for a in range(n):
                for b in range(a, n):
                    cov[a, b] += w * d[a] * d[b]
    for a in range(n):
        for b in range(a, n):
            cov[a, b] *= inv
            cov[b, a] = cov[a, b]


@njit(cache=True, error_model="numpy")
def _weigh_run(r, Xp, logw, logN, z, valid, sensor, thr, out, e):
    """Measurement step of run r (module docstring); leaves exp(shifted) in e and shifted log-weights in out.logw[r]."""
    N, n = Xp.shape
    m = z.shape[1]
    Zp = np.empty((N, m))
    ll = np.empty(N)
    const, measured = measure_run(sensor, Xp, z[r], valid[r], Zp, ll)
    offset = np.empty(N)
    nonzero = 0  # counted, not a flag set to literal True/False: numba would compile predictive_run for Literal[bool] too
    for i in range(N):
        o = logw[r, i] + logN
        offset[i] = o
        if o != 0.0:
            nonzero += 1
    uniform = nonzero == 0
    L = np.empty((m, m))
    tmp = np.empty(m)
    out.nis[r], out.dof[r] = predictive_run(sensor, Zp, offset, uniform, z[r], valid[r], out.innov[r], out.S[r], L, tmp)
    a = out.logw[r]
    for i in range(N):
        a[i] = ll[i] + offset[i]
    mx, s, s2, rst = exp_shifted_run(a, offset, not uniform, e)
    ls = math.log(s)
    lk = mx + ls + ((const if measured else 0.0) - logN)
    if rst:
        lk = -np.inf
    out.loglik[r] = lk if measured else 0.0
    out.reset[r] = rst
    moments_run(Xp, e, s, out.mean[r], out.cov[r])
    es = s * s / s2
    out.ess[r] = es
    out.need[r] = measured and (thr < 0 or es < thr * N)
    for i in range(N):
        a[i] -= ls


@njit(cache=True, error_model="numpy")
def _fast_run(r, X, logw, logN, noise, draws, motion, sensor, opts, out):
    """The whole step of run r when every component is measured and no component is an angle.

    Fused passes over the particles: (1) propagate, measure, log-weights and
    the predictive mean; (2) exp, sums, weighted mean and the predictive
    spread; (3) covariance; (4) resampling.  Same arithmetic as the general
    path up to the order of summation.
    """
    addrs, per_run = draws
    rkind, thr = opts
    R = sensor.R
    N, n = X.shape[1], X.shape[2]
    m = R.shape[0]
    Xin = X[r]
    lw = logw[r]
    a = out.logw[r]
    Xp = np.empty((N, n))
    Zp = np.empty((N, m))
    nz = noise[r]
    if per_run:
        fill_normal(addrs[r], nz)
    uniform = _all_uniform(lw, logN)
    invN = 1.0 / N
    const = 0.0
    for j in range(m):
        const += -0.5 * (math.log(R[j, j]) + LOG_2PI)
    zr = np.empty(m)
    hR = np.empty(m)
    for j in range(m):
        hR[j] = -0.5 / R[j, j]
    zvec = out.innov[r]  # holds z on entry (set by the caller), innovation on exit
    for j in range(m):
        zr[j] = zvec[j]
    zhat = np.zeros(m)
    mx = -np.inf
    # pass 1 (the models' fields read once, outside the particle loop)
    mk, F, G, par = motion.kind, motion.F, motion.G, motion.par
    hk, A, idx, scale = sensor.kind, sensor.A, sensor.idx, sensor.scale
    for i in range(N):
        propagate_point(mk, F, G, par, Xin, i, nz, Xp, i)
        h_point(hk, A, idx, scale, Xp, i, Zp, i)
        ll = 0.0
        for j in range(m):
            d = zr[j] - Zp[i, j]
            ll += d * d * hR[j]
        if uniform:
            v = ll
            for j in range(m):
                zhat[j] += Zp[i, j]
        else:
            o = lw[i] + logN
            v = ll + o
            w = exp_weight(o) * invN
            for j in range(m):
                zhat[j] += w * Zp[i, j]
        if math.isnan(v):
            v = -np.inf
        a[i] = v
        if v > mx:
            mx = v
    if uniform:
        for j in range(m):
            zhat[j] *= invN
    rst = False
    if not math.isfinite(mx):
        # rare: infinite or all-zero likelihoods; the general recovery rule
        offset = np.empty(N)
        for i in range(N):
            offset[i] = lw[i] + logN
        e = np.empty(N)
        mx, s, s2, rst = exp_shifted_run(a, offset, not uniform, e)
    else:
        e = np.empty(N)
        for i in range(N):
            sh = a[i] - mx
            a[i] = sh
            e[i] = exp_weight(sh)
        s = 0.0
        for i in range(N):  # in order: systematic resampling divides the running sums by this total
            s += e[i]
        s2 = _sum_sq(e)
    # pass 2: weighted mean and predictive spread
    mu = out.mean[r]
    for j in range(n):
        mu[j] = 0.0
    P = np.zeros((m, m))
    D = np.empty(m)
    for i in range(N):
        w = e[i]
        if w > 0:
            for j in range(n):
                mu[j] += w * Xp[i, j]
        wp = invN if uniform else exp_weight(lw[i] + logN) * invN
        for j in range(m):
            D[j] = Zp[i, j] - zhat[j]
        for p in range(m):
            for q_ in range(p, m):
                P[p, q_] += wp * D[p] * D[q_]
    inv = 1.0 / s
    for j in range(n):
        mu[j] *= inv
    # pass 3: covariance
    C = out.cov[r]
    for p in range(n):
        for q_ in range(n):
            C[p, q_] = 0.0
    d = np.empty(n)
    for i in range(N):
        w = e[i]
        if w > 0:
            for j in range(n):
                d[j] = Xp[i, j] - mu[j]
            for p in range(n):
                for q_ in range(p, n):
                    C[p, q_] += w * d[p] * d[q_]
    for p in range(n):
        for q_ in range(p, n):
            C[p, q_] *= inv
            C[q_, p] = C[p, q_]
    # innovation statistics
    Sr = out.S[r]
    tmp = np.empty(m)
    for p in range(m):
        zvec[p] = zr[p] - zhat[p]
        tmp[p] = zvec[p]
        for q_ in range(m):
            Sr[p, q_] = (P[p, q_] if p <= q_ else P[q_, p]) + R[p, q_]
    L = np.empty((m, m))
    out.nis[r] = chol_quad(L, tmp.copy(), tmp) if cholesky_inplace(Sr, L) else np.nan
    out.dof[r] = m
    ls = math.log(s)
    out.loglik[r] = -np.inf if rst else mx + ls + (const - logN)
    out.reset[r] = rst
    es = s * s / s2
    out.ess[r] = es
    nd = thr < 0 or es < thr * N
    out.need[r] = nd
    if nd and per_run:
        if rkind == R_SYSTEMATIC:
            systematic_fill_rows(e, s, next_random(addrs[r]), Xp, out.particles[r])
            for i in range(N):
                a[i] = -logN
        else:
            nu = n_uniforms(rkind, N)
            U = np.empty(nu)
            fill_random(addrs[r], U)
            for i in range(N):
                a[i] -= ls
            _resample_run(r, rkind, Xp, e, U, out.particles, out.logw, logN)
    else:
        out.particles[r] = Xp
        for i in range(N):
            a[i] -= ls


@njit(cache=True, error_model="numpy")
def systematic_fill_cdf(c, u0, src, dst):
    """Systematic resampling of a 1-D particle set without branches, from the cumulative weights ``c``.

    With b_i = ceil(N c_i / c_N − u0) the positions (u0 + j)/N below the
    normalised cumulative weight of particle i, output j takes particle
    #{i: b_i <= j}.  The b_i never decrease (c is a running sum of weights
    >= 0), so that count is one more than the last i with b_i <= j: store
    i + 1 at b_i (a later i overwrites an earlier one; unlike a histogram's
    increments, the stores do not wait on each other), then a running
    maximum and a gather.  The last normalised weight is exactly 1, as in
    the NumPy resampler.
    """
    N = c.shape[0]
    s = c[N - 1]
    last = np.zeros(N + 1, dtype=np.int32)
    for i in range(N - 1):
        last[np.int32(math.ceil((c[i] / s) * N - u0))] = np.int32(i + 1)
    p = np.int32(0)
    for j in range(N):
        p = max(p, last[j])
        dst[j] = src[p]


@njit(cache=True, error_model="numpy")
def systematic_fill_rows(e, s, u0, src, dst):
    """:func:`systematic_fill_cdf` for particles with n components (rows of ``src``), from the weights ``e`` and their running total ``s``."""
    N, n = src.shape
    hist = np.zeros(N + 1, dtype=np.int64)
    acc = 0.0
    for i in range(N - 1):
        acc += e[i]
        hist[int(math.ceil((acc / s) * N - u0))] += 1
    hist[N] += 1
    p = 0
    for j in range(N):
        p += hist[j]
        for t in range(n):
            dst[j, t] = src[p, t]


@njit(cache=True, error_model="numpy", fastmath={"reassoc", "nsz"})
def _sum_sq(e):
    """Σ e_i² (reassociated, so the compiler vectorises it)."""
    s2 = 0.0
    for i in range(e.shape[0]):
        s2 += e[i] * e[i]
    return s2


@njit(cache=True, error_model="numpy", fastmath={"reassoc", "nsz"})
def _weighted_sum(w, x):
    """Σ w_i x_i over the particles of positive weight (a zero-weight particle may be non-finite)."""
    acc = 0.0
    for i in range(w.shape[0]):
        acc += w[i] * x[i] if w[i] > 0 else 0.0
    return acc


@njit(cache=True, error_model="numpy", fastmath={"reassoc", "nsz"})
def _weighted_sq_dev(w, x, c):
    """Σ w_i (x_i − c)² over the particles of positive weight."""
    acc = 0.0
    for i in range(w.shape[0]):
        d = x[i] - c
        acc += w[i] * (d * d) if w[i] > 0 else 0.0
    return acc


@njit(cache=True, error_model="numpy", fastmath={"reassoc", "nsz"})
def _sum_sq_scaled(x, scale):
    """Σ x_i² scale (UNGM's predicted measurements h_i = x_i² / s, summed)."""
    acc = 0.0
    for i in range(x.shape[0]):
        acc += ungm_h(x[i], scale)
    return acc


@njit(cache=True, error_model="numpy", fastmath={"reassoc", "nsz"})
def _weighted_sum_sq_scaled(w, x, scale):
    """Σ w_i x_i² scale over the particles of positive weight."""
    acc = 0.0
    for i in range(w.shape[0]):
        acc += w[i] * ungm_h(x[i], scale) if w[i] > 0 else 0.0
    return acc


@njit(cache=True, error_model="numpy", fastmath={"reassoc", "nsz"})
def _sq_scaled_dev(x, scale, c):
    """Σ (x_i² scale − c)²."""
    acc = 0.0
    for i in range(x.shape[0]):
        d = ungm_h(x[i], scale) - c
        acc += d * d
    return acc


@njit(cache=True, error_model="numpy", fastmath={"reassoc", "nsz"})
def _weighted_sq_scaled_dev(w, x, scale, c):
    """Σ w_i (x_i² scale − c)² over the particles of positive weight."""
    acc = 0.0
    for i in range(w.shape[0]):
        d = ungm_h(x[i], scale) - c
        acc += w[i] * (d * d) if w[i] > 0 else 0.0
    return acc


@njit(cache=True, error_model="numpy")
def _max(a):
    """The largest entry of ``a`` (no NaN in it); −inf for an empty or all −inf ``a``."""
    mx = -np.inf
    for i in range(a.shape[0]):
        mx = max(mx, a[i])
    return mx


@njit(cache=True, error_model="numpy")
def _all_uniform(lw, logN):
    """Whether every log-weight is exactly −log N (the run resampled, or the prior)."""
    for i in range(lw.shape[0]):
        if lw[i] + logN != 0.0:
            return False
    return True


@njit(cache=True, error_model="numpy")
def _ungm_run(r, X, logw, logN, noise, draws, motion, sensor, opts, out, uniform_known, ws):
    """The whole step of run r for UNGM motion and measurement (n = m = 1).

    Same arithmetic as :func:`_fast_run`, arranged in branch-free passes
    over the particles that the compiler vectorises (propagation and
    log-weights, ``exp``, the weighted sums), so a step costs little more
    than its normal draws.  ``ws`` (4, N) is scratch; ``uniform_known``
    says the log-weights are all −log N (the caller knows the run
    resampled), which saves checking them.
    """
    addrs, per_run = draws
    rkind, thr = opts
    par, scale, Rv = motion.par, sensor.scale, sensor.R[0, 0]
    N = X.shape[1]
    xin = X[r].reshape(N)  # n = 1; a contiguous view (X[r, :, 0] is strided to numba, which stops vectorisation)
    lw = logw[r]
    a = out.logw[r]
    xp, e, c, wp = ws[0], ws[1], ws[2], ws[3]
    if per_run:  # the noise goes where the particles will be, and is replaced by them
        fill_normal(addrs[r], xp)
    else:
        xp[:] = noise[r]
    uniform = uniform_known or _all_uniform(lw, logN)
    invN = 1.0 / N
    pa, pb, forcing, sq = par[0], par[1], par[2], par[3]
    iscale = 1.0 / scale
    hR = -0.5 / Rv
    zr = out.innov[r, 0]
    for i in range(N):  # propagate, predict the measurement, log-likelihood
        xn = xp[i] * sq + ungm_mean(xin[i], pa, pb, forcing)
        xp[i] = xn
        h = ungm_h(xn, iscale)  # recomputed from xp where needed: one array less in cache
        d = zr - h
        v = d * d * hR
        a[i] = v if v == v else -np.inf  # a NaN likelihood counts as zero
    if uniform:
        zhat = _sum_sq_scaled(xp, iscale) * invN
    else:  # predictive weights exp(offset)/N, offset = log w + log N
        for i in range(N):
            o = lw[i] + logN
            v = a[i] + o
            a[i] = v if v == v else -np.inf
            wp[i] = exp_weight(o) * invN
        zhat = _weighted_sum_sq_scaled(wp, xp, iscale)
    mx = _max(a)
    rst = False
    if not math.isfinite(mx):
        offset = np.empty(N)
        for i in range(N):
            offset[i] = lw[i] + logN
        mx, s, s2, rst = exp_shifted_run(a, offset, not uniform, e)
        acc = 0.0
        for i in range(N):
            acc += e[i]
            c[i] = acc
    else:
        for i in range(N):
            sh = a[i] - mx
            a[i] = sh
            e[i] = exp_weight(sh)
        acc = 0.0
        for i in range(N):  # the cumulative sums, in order: resampling needs them, and s is their last
            acc += e[i]
            c[i] = acc
        s = acc
        s2 = _sum_sq(e)
    inv = 1.0 / s
    mu = _weighted_sum(e, xp) * inv
    if uniform:
        pz = _sq_scaled_dev(xp, iscale, zhat) * invN
    else:
        pz = _weighted_sq_scaled_dev(wp, xp, iscale, zhat)
    c2 = _weighted_sq_dev(e, xp, mu)
    out.mean[r, 0] = mu
    out.cov[r, 0, 0] = c2 * inv
    nu = zr - zhat
    out.innov[r, 0] = nu
    Sv = pz + Rv
    out.S[r, 0, 0] = Sv
    out.nis[r] = nu * nu / Sv if (Sv > 0 and math.isfinite(Sv)) else np.nan
    out.dof[r] = 1
    ls = math.log(s)
    const = -0.5 * (math.log(Rv) + LOG_2PI)
    out.loglik[r] = -np.inf if rst else mx + ls + (const - logN)
    out.reset[r] = rst
    es = s * s / s2
    out.ess[r] = es
    nd = thr < 0 or es < thr * N
    out.need[r] = nd
    dst = out.particles[r].reshape(N)
    if nd and per_run and rkind == R_SYSTEMATIC:
        systematic_fill_cdf(c, next_random(addrs[r]), xp, dst)
        for i in range(N):
            a[i] = -logN
    elif nd and per_run:
        nu_ = n_uniforms(rkind, N)
        U = np.empty(nu_)
        fill_random(addrs[r], U)
        for i in range(N):
            a[i] -= ls
        _resample_run(r, rkind, xp.reshape(N, 1), e, U, out.particles, out.logw, logN)
    else:
        for i in range(N):
            dst[i] = xp[i]
            a[i] -= ls


# --------------------------------------------------------------------------
# linear motion, range or linear sensor: the particles' components as rows
# --------------------------------------------------------------------------
@njit(cache=True)
def lanes_rows(n: int, m: int) -> int:
    """Rows of scratch (each N long) :func:`_lanes_run` needs: X, X⁻ (n each), h (m), e, c, wp and the gather index."""
    return 2 * n + m + 4


@njit(cache=True, error_model="numpy", fastmath={"reassoc", "nsz"})
def _cross_dev(w, x, cx, y, cy):
    """Σ w_i (x_i − cx)(y_i − cy) over the particles of positive weight."""
    acc = 0.0
    for i in range(w.shape[0]):
        acc += w[i] * (x[i] - cx) * (y[i] - cy) if w[i] > 0 else 0.0
    return acc


@njit(cache=True, error_model="numpy", fastmath={"reassoc", "nsz"})
def _cross_dev_all(x, cx, y, cy):
    """Σ (x_i − cx)(y_i − cy)."""
    acc = 0.0
    for i in range(x.shape[0]):
        acc += (x[i] - cx) * (y[i] - cy)
    return acc


@njit(cache=True, error_model="numpy", fastmath={"reassoc", "nsz"})
def _sum(x):
    """Σ x_i (reassociated)."""
    acc = 0.0
    for i in range(x.shape[0]):
        acc += x[i]
    return acc


@njit(cache=True, error_model="numpy", fastmath={"reassoc", "nsz"})
def _dot(w, x):
    """Σ w_i x_i (reassociated; every weight counts)."""
    acc = 0.0
    for i in range(x.shape[0]):
        acc += w[i] * x[i]
    return acc


@njit(cache=True, error_model="numpy")
def _lanes_propagate(F, G, Xs, nz, Xp):
    """Xp[a] = Σ_j F[a, j] Xs[j] + Σ_j G[a, j] ξ_j, component by component over all particles (same sums as :func:`.model_math._linear_motion`)."""
    n, N = Xs.shape
    q = G.shape[1]
    for a_ in range(n):
        row = Xp[a_]
        for i in range(N):
            row[i] = 0.0
        for j in range(n):
            f = F[a_, j]
            xj = Xs[j]
            for i in range(N):
                row[i] += f * xj[i]
        for i in range(N):
            acc2 = 0.0
            for j in range(q):
                acc2 += G[a_, j] * nz[i * q + j]
            row[i] = row[i] + acc2


@njit(cache=True, error_model="numpy")
def _lanes_measure(hk, A, idx, scale, Xp, Zp):
    """Zp[a] = h_a of every particle: the ranges to the anchors (:func:`.model_math.h_range`) or a linear h, by rows."""
    m, N = Zp.shape
    if hk == M_RANGE:
        d = A.shape[1]
        for a_ in range(m):
            row = Zp[a_]
            for i in range(N):
                row[i] = 0.0
            for j in range(d):
                xj = Xp[idx[j]]
                c = A[a_, j]
                for i in range(N):
                    t = xj[i] - c
                    row[i] += t * t
            for i in range(N):
                row[i] = math.sqrt(row[i]) / scale
    else:  # M_LINEAR
        n = A.shape[1]
        for a_ in range(m):
            row = Zp[a_]
            for i in range(N):
                row[i] = 0.0
            for j in range(n):
                c = A[a_, j]
                xj = Xp[j]
                for i in range(N):
                    row[i] += c * xj[i]


@njit(cache=True, error_model="numpy")
def _lanes_run(r, X, logw, logN, noise, draws, motion, sensor, opts, out, uniform_known, ws):
    """The whole step of run r for linear motion and a range or linear sensor, every component measured.

    The arithmetic of :func:`_fast_run` element by element (propagation,
    predicted measurements, log-likelihoods, weights and the running sum
    that systematic resampling divides), computed a component at a time
    over all particles (the particles' components as rows of ``ws``), so
    the compiler vectorises every pass; the weighted sums of the moments
    are reassociated (last-bit differences only).  ``ws`` has
    :func:`lanes_rows` rows of N.
    """
    addrs, per_run = draws
    rkind, thr = opts
    R = sensor.R
    N, n = X.shape[1], X.shape[2]
    m = R.shape[0]
    Xin = X[r]
    lw = logw[r]
    a = out.logw[r]
    Xs = ws[0:n]
    Xp = ws[n:2 * n]
    Zp = ws[2 * n:2 * n + m]
    e, c, wp = ws[2 * n + m], ws[2 * n + m + 1], ws[2 * n + m + 2]
    gidx = ws[2 * n + m + 3].view(np.int64)
    nz = noise[r]
    if per_run:
        fill_normal(addrs[r], nz)
    uniform = uniform_known or _all_uniform(lw, logN)
    invN = 1.0 / N
    for i in range(N):
        for j in range(n):
            Xs[j, i] = Xin[i, j]
    _lanes_propagate(motion.F, motion.G, Xs, nz, Xp)
    _lanes_measure(sensor.kind, sensor.A, sensor.idx, sensor.scale, Xp, Zp)
    const = 0.0
    for j in range(m):
        const += -0.5 * (math.log(R[j, j]) + LOG_2PI)
    zvec = out.innov[r]  # holds z on entry (set by the caller), innovation on exit
    for i in range(N):
        a[i] = 0.0
    for j in range(m):
        zj = zvec[j]
        hR = -0.5 / R[j, j]
        row = Zp[j]
        for i in range(N):
            d = zj - row[i]
            a[i] += d * d * hR
    zhat = np.empty(m)
    if uniform:
        for i in range(N):
            v = a[i]
            a[i] = v if v == v else -np.inf  # a NaN likelihood counts as zero
        for j in range(m):
            zhat[j] = _sum(Zp[j]) * invN
    else:  # predictive weights exp(offset)/N, offset = log w + log N
        for i in range(N):
            o = lw[i] + logN
            v = a[i] + o
            a[i] = v if v == v else -np.inf
            wp[i] = exp_weight(o) * invN
        for j in range(m):
            zhat[j] = _dot(wp, Zp[j])
    mx = _max(a)
    rst = False
    if not math.isfinite(mx):
        # rare: infinite or all-zero likelihoods; the general recovery rule
        offset = np.empty(N)
        for i in range(N):
            offset[i] = lw[i] + logN
        mx, s, s2, rst = exp_shifted_run(a, offset, not uniform, e)
    else:
        for i in range(N):
            sh = a[i] - mx
            a[i] = sh
            e[i] = exp_weight(sh)
        s2 = _sum_sq(e)
    acc = 0.0
    for i in range(N):  # in order: systematic resampling divides the running sums by the total
        acc += e[i]
        c[i] = acc
    s = acc
    inv = 1.0 / s
    mu = out.mean[r]
    for j in range(n):
        mu[j] = _weighted_sum(e, Xp[j]) * inv
    C = out.cov[r]
    for p in range(n):
        for q_ in range(p, n):
            C[p, q_] = _cross_dev(e, Xp[p], mu[p], Xp[q_], mu[q_]) * inv
            C[q_, p] = C[p, q_]
    Sr = out.S[r]
    for p in range(m):
        for q_ in range(p, m):
            if uniform:
                v = _cross_dev_all(Zp[p], zhat[p], Zp[q_], zhat[q_]) * invN
            else:
                v = _cross_dev_all_w(wp, Zp[p], zhat[p], Zp[q_], zhat[q_])
            Sr[p, q_] = v + R[p, q_]
            Sr[q_, p] = v + R[q_, p]
    tmp = np.empty(m)
    for p in range(m):
        zvec[p] = zvec[p] - zhat[p]
        tmp[p] = zvec[p]
    L = np.empty((m, m))
    out.nis[r] = chol_quad(L, tmp.copy(), tmp) if cholesky_inplace(Sr, L) else np.nan
    out.dof[r] = m
    ls = math.log(s)
    out.loglik[r] = -np.inf if rst else mx + ls + (const - logN)
    out.reset[r] = rst
    es = s * s / s2
    out.ess[r] = es
    nd = thr < 0 or es < thr * N
    out.need[r] = nd
    dst = out.particles[r]
    if nd and per_run and rkind == R_SYSTEMATIC:
        _systematic_index(c, next_random(addrs[r]), gidx)
        for i in range(N):
            g = gidx[i]
            for j in range(n):
                dst[i, j] = Xp[j, g]
            a[i] = -logN
    elif nd and per_run:
        nu_ = n_uniforms(rkind, N)
        U = np.empty(nu_)
        fill_random(addrs[r], U)
        for i in range(N):
            a[i] -= ls
        _resample_run(r, rkind, np.ascontiguousarray(Xp.T), e, U, out.particles, out.logw, logN)
    else:
        for i in range(N):
            for j in range(n):
                dst[i, j] = Xp[j, i]
            a[i] -= ls


@njit(cache=True, error_model="numpy", fastmath={"reassoc", "nsz"})
def _cross_dev_all_w(w, x, cx, y, cy):
    """Σ w_i (x_i − cx)(y_i − cy) (every weight counts)."""
    acc = 0.0
    for i in range(x.shape[0]):
        acc += w[i] * (x[i] - cx) * (y[i] - cy)
    return acc


@njit(cache=True, error_model="numpy")
def _systematic_index(c, u0, idx):
    """The source particle of each output of systematic resampling, from the running sums ``c`` (:func:`systematic_fill_cdf`)."""
    N = c.shape[0]
    s = c[N - 1]
    for j in range(N):
        idx[j] = 0
    for i in range(N - 1):
        b = np.int64(math.ceil((c[i] / s) * N - u0))
        if b < N:  # b = N where the particles after i all weigh 0: no output takes i + 1
            idx[b] = i + 1
    p = np.int64(0)
    for j in range(N):
        p = max(p, idx[j])
        idx[j] = p


@njit(cache=True, error_model="numpy")
def _step_body(r, X, logw, noise, z, valid, draws, motion, sensor, opts, out, uniform_known, ws):
    """Step of run r (see :func:`_pf_step`); ``ws`` (at least 4 and :func:`lanes_rows` rows, N) is scratch, ``uniform_known`` as in :func:`_ungm_run`."""
    N, n = X.shape[1], X.shape[2]
    logN = math.log(N)
    m = z.shape[1]
    all_valid = True
    for j in range(m):
        if not valid[r, j]:
            all_valid = False
    if all_valid and motion.kind == UNGM and sensor.kind == M_UNGM:
        out.innov[r, 0] = z[r, 0]
        _ungm_run(r, X, logw, logN, noise, draws, motion, sensor, opts, out, uniform_known, ws)
        return
    if all_valid and motion.kind == LINEAR and (sensor.kind == M_RANGE or sensor.kind == M_LINEAR):
        zv = out.innov[r]
        for j in range(m):
            zv[j] = z[r, j]
        _lanes_run(r, X, logw, logN, noise, draws, motion, sensor, opts, out, uniform_known, ws)
        return
    if all_valid and not sensor.angle:
        zv = out.innov[r]
        for j in range(m):
            zv[j] = z[r, j]
        _fast_run(r, X, logw, logN, noise, draws, motion, sensor, opts, out)
        return
    addrs, per_run = draws
    rkind, thr = opts
    if per_run:
        fill_normal(addrs[r], noise[r])
    Xp = np.empty((N, n))
    propagate_run(motion, X[r], noise[r], Xp)
    e = np.empty(N)
    _weigh_run(r, Xp, logw, logN, z, valid, sensor, thr, out, e)
    if per_run and out.need[r]:
        nu = n_uniforms(rkind, N)
        U = np.empty(nu)
        fill_random(addrs[r], U)
        _resample_run(r, rkind, Xp, e, U, out.particles, out.logw, logN)
    else:
        out.particles[r] = Xp


@njit(cache=True, error_model="numpy")
def _resample_run(r, rkind, Xp, e, U, Xout, logw_out, logN):
    N = Xp.shape[0]
    c = np.empty(N)
    tmp = np.empty(N)
    counts = np.empty(N, dtype=np.int64)
    resample_counts(rkind, e, U, c, tmp, counts)
    copy_by_counts(Xp, counts, Xout[r])
    for i in range(N):
        logw_out[r, i] = -logN


def _pf_step(particles, noise, obs, draws, motion, sensor, opts, out):
    """One bootstrap-PF step for every run (outputs written in place); see the module docstring.

    ``particles`` is ``(X (B, N, n), logw (B, N))``, ``noise`` (B, N·q) the
    normals' buffer, ``obs`` ``(z (B, m), valid (B, m))``, ``draws`` a
    :class:`~.kernel_args.Draws`, ``motion`` / ``sensor`` the packed models
    (:mod:`.model_math`), ``opts`` a :class:`~.kernel_args.PFOptions` and
    ``out`` a :class:`~.kernel_args.PFOutputs`.
    """
    X, logw = particles
    z, valid = obs
    for rr in prange(X.shape[0]):
        r = np.int64(rr)  # prange counts in uint64
        ws = np.empty((max(4, lanes_rows(X.shape[2], z.shape[1])), X.shape[1]))
        known = r < 0  # False, typed bool: a literal False would compile _step_body & co. once more (Literal[bool])
        _step_body(r, X, logw, noise, z, valid, draws, motion, sensor, opts, out, known, ws)


def _pf_sequence(prior, noise, obs, draws, motion, sensor, opts, buffers, out, keep_cov):
    """All K steps of every run, time loop inside the run loop (outputs ``(K, B, ...)``, written in place).

    Run r draws from its own stream (``draws.addrs[r]``; the caller checked
    that every run has one), so its steps are :func:`_step_body`'s in the
    same order as K calls of :func:`_pf_step`: the same bits, without
    returning to Python between steps and with the run's particles still in
    cache.  ``prior`` is ``(X0, logw0)``; ``obs`` ``(zs (K, B, m), valids)``;
    ``motion`` holds every step's F, G and par stacked on a first axis.
    Step k reads the particles of step k − 1 from one of the two buffers
    ``buffers = (X2 (2, B, N, n), logw2 (2, B, N))`` and writes the other
    (``out.particles`` and ``out.logw`` are not used).  Covariances go to
    ``out.cov[k]``, or all to ``out.cov[0]`` where ``keep_cov`` is false.  A
    run that resampled has log-weights of exactly −log N (every resampler
    writes that), which the next step need not check.
    """
    X0, logw0 = prior
    zs, valids = obs
    X2, l2 = buffers
    K = zs.shape[0]
    for rr in prange(X0.shape[0]):
        r = np.int64(rr)
        ws = np.empty((max(4, lanes_rows(X0.shape[2], zs.shape[2])), X0.shape[1]))
        for k in range(K):
            c = k if keep_cov else 0
            known = k > 0 and out.need[k - 1, r]
            if k == 0:
                Xi, li = X0, logw0
            else:
                Xi, li = X2[(k + 1) % 2], l2[(k + 1) % 2]
            step_out = PFOutputs(X2[k % 2], l2[k % 2], out.mean[k], out.cov[c], out.innov[k], out.S[k], out.nis[k],
                                 out.dof[k], out.loglik[k], out.reset[k], out.ess[k], out.need[k])
            step_motion = Motion(motion.kind, motion.F[k], motion.G[k], motion.par[k])
            _step_body(r, Xi, li, noise, zs[k], valids[k], draws, step_motion, sensor, opts, step_out, known, ws)


def _pf_resample(logw_out, need, U, rkind, Xout):
    """Resample the runs in ``need`` of ``Xout`` in place from pre-drawn uniforms U (M, ·) (shared-Generator mode)."""
    M, N = logw_out.shape
    logN = math.log(N)
    for rr in prange(M):
        r = np.int64(rr)
        if need[r]:
            e = np.empty(N)
            for i in range(N):
                sh = logw_out[r, i]
                e[i] = math.exp(sh) if sh > EXP_FLOOR else 0.0
            _resample_run(r, rkind, Xout[r].copy(), e, U[r], Xout, logw_out, logN)


pf_step_serial, pf_step_parallel = serial_and_parallel(_pf_step, cache=True, error_model="numpy")
pf_sequence_serial, pf_sequence_parallel = serial_and_parallel(_pf_sequence, cache=True, error_model="numpy")
pf_resample_serial, pf_resample_parallel = serial_and_parallel(_pf_resample, cache=True, error_model="numpy")
