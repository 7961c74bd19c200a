"""Scalar one-run EKF and UKF/CKF steps for the online lane (imports numba).

:func:`pursuit._compiled.gauss_kernels.ekf_one` / ``sigma_one`` run the
serial block kernel of the batched path on one lane: about forty small
arrays allocated per call and a view made in every inner loop, which costs
twenty times the arithmetic of a 4-state step.  The kernels here take the
same arguments and write the same ``out`` (the rows of
:func:`pursuit._compiled.kf_codegen.step_rows`), with plain loops over the
states and sigma points of one run and one scratch array per call, its
views made by slicing (a reshape calls into numba's runtime, about 40 ns).

Every sum, product and comparison is the block kernel's (``_ekf_step``,
``_sigma_step``, ``_sigma_correct``, ``_update_ws``, ``_chol``,
``_spd_inv``, ``_points``), written for one run in the same order, and
neither is compiled with fast-math, so the results are the same bits
(``tests/compiled/test_online_compiled_step.py`` compares them).  A change
to the block kernels' arithmetic must be made here too.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .common import LOG_2PI, wrap
from .model_math import h_row, h_sigma_row, jac_row, wraps

__all__ = ["ekf_one_scalar", "sigma_one_scalar"]

_NJ = dict(cache=True, error_model="numpy")
_MAX_Z = 2.0**500  # pursuit._validation.MAX_MEASUREMENT


@njit(**_NJ)
def _chol(P, L):
    """:func:`.gauss_kernels._chol` for one matrix; False where P is not positive definite."""
    n = P.shape[0]
    ok = True
    L[:] = 0.0
    for j in range(n):
        d = P[j, j]
        for p in range(j):
            d -= L[j, p] * L[j, p]
        good = d > 0.0 and d < np.inf
        ok &= good
        L[j, j] = math.sqrt(d) if good else 1.0
        for i in range(j + 1, n):
            v = P[i, j]
            for p in range(j):
                v -= L[i, p] * L[j, p]
            L[i, j] = v / L[j, j]
    return ok


@njit(**_NJ)
def _symmetrize(P):
    n = P.shape[0]
    for i in range(n):
        for j in range(i + 1, n):
            v = 0.5 * (P[i, j] + P[j, i])
            P[i, j] = v
            P[j, i] = v


@njit(**_NJ)
def _spd_inv(S, Si, ws):
    """:func:`.gauss_kernels._spd_inv` for one matrix: ``(ok, log det S)``; ``ws`` scratch of 2 m rows."""
    m = S.shape[0]
    if m == 1:
        a = S[0, 0]
        good = a > 0.0 and a < np.inf
        Si[0, 0] = 1.0 / a
        return good, (math.log(a) if good else 0.0)
    if m == 2:
        a = S[0, 0]
        b = S[0, 1]
        d = S[1, 1]
        det = a * d - b * b
        good = a > 0.0 and det > 0.0 and det < np.inf
        inv = 1.0 / det
        Si[0, 0] = d * inv
        Si[0, 1] = -b * inv
        Si[1, 0] = -b * inv
        Si[1, 1] = a * inv
        return good, (math.log(det) if good else 0.0)
    L = ws[:m, :m]
    Li = ws[m:2 * m, :m]
    ok = _chol(S, L)
    logdet = 0.0
    for j in range(m):
        logdet += 2.0 * math.log(L[j, j])
    Li[:] = 0.0
    for j in range(m):
        Li[j, j] = 1.0 / L[j, j]
        for i in range(j + 1, m):
            o = Li[i, j]
            for p in range(j, i):
                o -= L[i, p] * Li[p, j]
            Li[i, j] = o / L[i, i]
    for i in range(m):
        for j in range(m):
            o = 0.0
            for p in range(max(i, j), m):
                o += Li[p, i] * Li[p, j]
            Si[i, j] = o
    return ok, logdet


@njit(**_NJ)
def _mm(A, B, out):
    """out = A B, each entry summed from 0.0 in the block kernels' order."""
    for i in range(A.shape[0]):
        for j in range(B.shape[1]):
            o = 0.0
            for p in range(A.shape[1]):
                o += A[i, p] * B[p, j]
            out[i, j] = o


@njit(**_NJ)
def _mmT(A, B, out):
    """out = A Bᵀ."""
    for i in range(A.shape[0]):
        for j in range(B.shape[0]):
            o = 0.0
            for p in range(A.shape[1]):
                o += A[i, p] * B[j, p]
            out[i, j] = o


@njit(**_NJ)
def _outputs(out, n, m):
    """Views of ``out``: x, xp, P, Pp, cross, innov, S and the offset of nis (then loglik, dof, ok)."""
    nn = n * n
    o = 2 * n + 3 * nn
    return (out[0:n], out[n:2 * n], out[2 * n:2 * n + nn].reshape((n, n)), out[2 * n + nn:2 * n + 2 * nn].reshape((n, n)),
            out[2 * n + 2 * nn:o].reshape((n, n)), out[o:o + m], out[o + m:o + m + m * m].reshape((m, m)), o + m + m * m)


@njit(**_NJ)
def _measured(z, v):
    """v[a] = 1.0 where z[a] is measured, else 0.0; True if some z[a] is infinite or beyond ±2⁵⁰⁰."""
    bad = False
    for a in range(z.shape[0]):
        v[a] = 0.0 if np.isnan(z[a]) else 1.0
        bad = bad or abs(z[a]) > _MAX_Z
    return bad


@njit(**_NJ)
def _predict_moments(P_moments, Q, lam):
    """P⁻ = (P if λ = 1 else λ P) + Q in place."""
    n = Q.shape[0]
    for i in range(n):
        for j in range(n):
            P_moments[i, j] = (P_moments[i, j] if lam == 1.0 else lam * P_moments[i, j]) + Q[i, j]


@njit(**_NJ)
def _update(xp, Pp, zp, Pzz, Pxz, L, HL, D, z, v, sensor, x_o, P_o, innov, S, ws):
    """:func:`.gauss_kernels._update_ws` for one run: ``(ok, nis, dof, loglik)``; ``ws`` scratch (see :func:`_update_rows`)."""
    R, angle, kind = sensor.R, sensor.angle, sensor.kind
    n = xp.shape[0]
    m = zp.shape[0]
    # views of the 2-D scratch by slicing (a reshape calls into numba's runtime: ~40 ns each)
    nu = ws[0, :m]
    Reff = ws[1:1 + m, :m]
    Si = ws[1 + m:1 + 2 * m, :m]
    r = 1 + 2 * m
    Pxm = ws[r:r + n, :m]
    K = ws[r + n:r + 2 * n, :m]
    KN = ws[r + 2 * n:r + 3 * n, :m]
    AL = ws[r + 3 * n:r + 4 * n, :n]
    T2 = ws[r + 4 * n:r + 5 * n, :n]
    rest = ws[r + 5 * n:, :]
    for a in range(m):
        d = z[a] - zp[a]
        if wraps(kind, angle, a):
            d = wrap(d)
        meas = v[a] > 0.0
        innov[a] = d if meas else np.nan
        nu[a] = d if meas else 0.0
    for a in range(m):
        for b in range(m):
            eye = 1.0 if a == b else 0.0
            vv = v[a] * v[b]
            re = R[a, b] if vv > 0.0 else 0.0
            re += eye * (1.0 - v[b])
            Reff[a, b] = re
            S[a, b] = (Pzz[a, b] if vv > 0.0 else 0.0) + re
    _symmetrize(S)
    ok, ld = _spd_inv(S, Si, rest)
    for i in range(n):
        for b in range(m):
            Pxm[i, b] = Pxz[i, b] * v[b]
    _mm(Pxm, Si, K)
    for i in range(n):
        xi = xp[i]
        for b in range(m):
            xi += K[i, b] * nu[b]
        x_o[i] = xi
    _mm(K, HL, AL)
    for i in range(n):
        for j in range(n):
            AL[i, j] = L[i, j] - AL[i, j]
    _mmT(AL, AL, P_o)
    for a in range(m):
        for b in range(m):
            Reff[a, b] += D[a, b] * v[a] * v[b]
    _mm(K, Reff, KN)
    _mmT(KN, K, T2)
    for i in range(n):
        for j in range(n):
            P_o[i, j] += T2[i, j]
    dd = 0.0
    for a in range(m):
        dd += v[a]
    if dd == 0.0:  # nothing measured: the prediction itself, not its factor's L Lᵀ
        P_o[:] = Pp
    _symmetrize(P_o)
    q = 0.0
    for a in range(m):
        for b in range(m):
            q += nu[a] * Si[a, b] * nu[b]
    nis = q if dd > 0 else np.nan
    loglik = -0.5 * (q + ld + dd * LOG_2PI) if dd > 0 else 0.0
    return ok, nis, np.int64(dd), loglik


@njit(**_NJ)
def _update_rows(n, m):
    """Rows of :func:`_update`'s scratch (``max(n, m)`` columns, as every scratch here)."""
    return 1 + 4 * m + 5 * n


@njit(**_NJ)
def _finish(out, at, nis, loglik, dof, ok):
    out[at] = nis
    out[at + 1] = loglik
    out[at + 2] = dof
    out[at + 3] = 1.0 if ok else 0.0


@njit(**_NJ)
def ekf_one_scalar(x, P, z, prediction, sensor, out):
    """One KF/EKF step of one run (the arithmetic of :func:`.gauss_kernels.ekf_step_serial`) into ``out``; 1 if ``z`` is unusable, 2 if a covariance does not factor, else 0."""
    F, Q, lam = prediction
    n = x.shape[0]
    m = z.shape[0]
    w = max(n, m)
    ws = np.empty((2 + n + 3 * m + n + 2 * m + _update_rows(n, m), w))
    v = ws[0, :m]
    if _measured(z, v):
        return 1
    x_o, xp, P_o, Pp, cross, innov, S, at = _outputs(out, n, m)
    zp = ws[1, :m]
    L = ws[2:2 + n, :n]
    r = 2 + n
    Hb = np.zeros((1, m, n))  # jac_row writes H[0]; the entries a model leaves out stay zero
    H = Hb[0]
    HL = ws[r + m:r + 2 * m, :n]
    Pzz = ws[r + 2 * m:r + 3 * m, :m]
    PHt = ws[r + 3 * m:r + 3 * m + n, :m]
    r += 3 * m + n
    D = ws[r:r + m, :m]
    upd = ws[r + m:, :]
    # predict: xp = F x, cross = P Fᵀ, P⁻ = F cross (then λ, Q)
    for i in range(n):
        o = 0.0
        for j in range(n):
            o += F[i, j] * x[j]
        xp[i] = o
    for i in range(n):
        for j in range(n):
            o = 0.0
            for p in range(n):
                o += P[i, p] * F[j, p]
            cross[i, j] = o
    _mm(F, cross, Pp)
    _predict_moments(Pp, Q, lam)
    # linearise h at the prediction
    xp2 = out[n:2 * n].reshape((1, n))
    h_row(sensor, xp2, 0, ws[1:2, :m], 0)
    jac_row(sensor, xp2, 0, Hb, 0)
    _mmT(Pp, H, PHt)
    _mm(H, PHt, Pzz)
    ok = _chol(Pp, L)
    _mm(H, L, HL)
    D[:] = 0.0
    ok2, nis, dof, loglik = _update(xp, Pp, zp, Pzz, PHt, L, HL, D, z, v, sensor, x_o, P_o, innov, S, upd)
    good = ok and ok2
    _finish(out, at, nis, loglik, dof, good)
    return 0 if good else 2


@njit(**_NJ)
def sigma_one_scalar(x, P, z, prediction, sensor, sigma, out):
    """One UKF/CKF step of one run (the arithmetic of :func:`.gauss_kernels.sigma_step_serial`) into ``out``; 1 if ``z`` is unusable, 2 if a covariance does not factor, else 0."""
    F, Q, lam = prediction
    cscale, wm, wc, centre = sigma
    angle, kind = sensor.angle, sensor.kind
    n = x.shape[0]
    m = z.shape[0]
    npts = wm.shape[0]
    w = max(n, m)
    ws = np.empty((2 + n + npts + 3 * npts + 3 * m + n + _update_rows(n, m), w))
    v = ws[0, :m]
    if _measured(z, v):
        return 1
    x_o, xp, P_o, Pp, cross, innov, S, at = _outputs(out, n, m)
    zp = ws[1, :m]
    L = ws[2:2 + n, :n]
    r = 2 + n
    chi = ws[r:r + npts, :n]
    r += npts
    Z = ws[r:r + npts, :m]
    dZ = ws[r + npts:r + 2 * npts, :m]
    E = ws[r + 2 * npts:r + 3 * npts, :m]
    r += 3 * npts
    Pzz = ws[r:r + m, :m]
    D = ws[r + m:r + 2 * m, :m]
    GT = ws[r + 2 * m:r + 3 * m, :n]
    Pxz = ws[r + 3 * m:r + 3 * m + n, :m]
    upd = ws[r + 3 * m + n:, :]
    off = 1 if centre else 0
    # predict: xp = F x, cross = P Fᵀ, P⁻ = F cross, symmetrised (then λ, Q): the linear motion's
    # exact moments, as gauss_kernels._sigma_predict_ws, without points
    for i in range(n):
        o = 0.0
        for j in range(n):
            o += F[i, j] * x[j]
        xp[i] = o
    for i in range(n):
        for j in range(n):
            o = 0.0
            for p in range(n):
                o += P[i, p] * F[j, p]
            cross[i, j] = o
    _mm(F, cross, Pp)
    _symmetrize(Pp)
    _predict_moments(Pp, Q, lam)
    # measurement: points redrawn from the prediction
    ok = _chol(Pp, L)
    _points(xp, L, cscale, centre, chi)
    for s in range(npts):
        h_sigma_row(sensor, chi, s, Z, s)
    for a in range(m):
        o = 0.0
        for s in range(npts):
            d = Z[s, a] - Z[0, a]
            if wraps(kind, angle, a):
                d = wrap(d)
            o += wm[s] * d
        zp[a] = o + Z[0, a]
    for s in range(npts):
        for a in range(m):
            d = Z[s, a] - zp[a]
            if wraps(kind, angle, a):
                d = wrap(d)
            dZ[s, a] = d
    for a in range(m):
        for b in range(m):
            o = 0.0
            for s in range(npts):
                o += dZ[s, a] * wc[s] * dZ[s, b]
            Pzz[a, b] = o
        for i in range(n):
            o = 0.0
            for s in range(npts):
                o += (chi[s, i] - xp[i]) * wc[s] * dZ[s, a]
            Pxz[i, a] = o
    for j in range(n):
        wp = wc[off + j] * cscale
        wn = wc[off + n + j] * cscale
        for a in range(m):
            GT[a, j] = wp * dZ[off + j, a] - wn * dZ[off + n + j, a]
    for a in range(m):
        if centre:
            E[0, a] = dZ[0, a]
        for j in range(n):
            g = cscale * GT[a, j]
            E[off + j, a] = dZ[off + j, a] - g
            E[off + n + j, a] = dZ[off + n + j, a] + g
    for a in range(m):
        for b in range(m):
            o = 0.0
            for s in range(npts):
                o += E[s, a] * wc[s] * E[s, b]
            D[a, b] = o
    ok2, nis, dof, loglik = _update(xp, Pp, zp, Pzz, Pxz, L, GT, D, z, v, sensor, x_o, P_o, innov, S, upd)
    good = ok and ok2
    _finish(out, at, nis, loglik, dof, good)
    return 0 if good else 2


@njit(**_NJ)
def _points(x, L, cscale, centre, chi):
    """:func:`.gauss_kernels._points` for one run: chi (npts, n)."""
    n = x.shape[0]
    off = 1 if centre else 0
    for i in range(n):
        if centre:
            chi[0, i] = x[i]
        for j in range(n):
            col = cscale * L[i, j]
            chi[off + j, i] = x[i] + col
            chi[off + n + j, i] = x[i] - col
