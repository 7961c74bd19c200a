"""Compiled Kalman-family steps (KF/EKF with the Joseph form, UKF/CKF) with runs across SIMD lanes.

The state is stored as ``x (n, M)`` and ``P (n, n, M)``: every loop over a
matrix entry has the runs innermost, so the compiler vectorises across runs
(explicit loops, no BLAS: a 4 × 4 product through BLAS costs more than the
arithmetic).  Blocks of runs are processed in parallel.

The arithmetic follows :mod:`pursuit.filters.gaussian` (predict
``P⁻ = λ F P Fᵀ + Q``, masked missing components, Joseph form for KF/EKF,
``P⁻ − K S Kᵀ`` for the sigma-point filters).  A run whose covariance or
innovation covariance does not factor (the NumPy filters would repair it)
is flagged in ``fail`` and recomputed by the caller with NumPy.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .common import LOG_2PI, M_LINEAR, M_RANGE, M_RANGE_BEARING, M_UNGM, wrap

BLOCK = 128


@njit(cache=True, inline="always")
def _h_lane(hk, A, idx, scale, X, r, out, col):
    """out[:, col] = h(X[:, r]) for lane-major X (n, ·)."""
    if hk == M_UNGM:
        out[0, col] = X[0, r] * X[0, r] * (1.0 / scale)
    elif hk == M_LINEAR:
        m, n = A.shape
        for a in range(m):
            acc = 0.0
            for j in range(n):
                acc += A[a, j] * X[j, r]
            out[a, col] = acc
    elif hk == M_RANGE:
        s, d = A.shape
        for a in range(s):
            acc = 0.0
            for j in range(d):
                t = X[idx[j], r] - A[a, j]
                acc += t * t
            out[a, col] = math.sqrt(acc) / scale
    else:
        dx = X[idx[0], r] - A[0, 0]
        dy = X[idx[1], r] - A[0, 1]
        out[0, col] = math.hypot(dx, dy)
        out[1, col] = math.atan2(dy, dx)


@njit(cache=True, inline="always")
def _jac_lane(hk, A, idx, scale, X, r, H, col):
    """H[:, :, col] = ∂h/∂x at X[:, r]."""
    m = H.shape[0]
    n = H.shape[1]
    for a in range(m):
        for j in range(n):
            H[a, j, col] = 0.0
    if hk == M_UNGM:
        H[0, 0, col] = (2.0 / scale) * X[0, r]
    elif hk == M_LINEAR:
        for a in range(m):
            for j in range(n):
                H[a, j, col] = A[a, j]
    elif hk == M_RANGE:
        s, d = A.shape
        for a in range(s):
            acc = 0.0
            for j in range(d):
                t = X[idx[j], r] - A[a, j]
                acc += t * t
            rr = math.sqrt(acc)
            if rr > 0:
                for j in range(d):
                    H[a, idx[j], col] = (X[idx[j], r] - A[a, j]) / rr / scale
    else:
        dx = X[idx[0], r] - A[0, 0]
        dy = X[idx[1], r] - A[0, 1]
        r2 = dx * dx + dy * dy
        rr = math.sqrt(r2)
        if rr > 0:
            H[0, idx[0], col] = dx / rr
            H[0, idx[1], col] = dy / rr
        if r2 > 0:
            H[1, idx[0], col] = -dy / r2
            H[1, idx[1], col] = dx / r2


@njit(cache=True, inline="always")
def _chol_lanes(P, L, B, ok):
    """Lower Cholesky factors of P (n, n, B) into L; ok[c] False where a lane fails."""
    n = P.shape[0]
    for i in range(n):
        for j in range(n):
            for c in range(B):
                L[i, j, c] = 0.0
    for j in range(n):
        for c in range(B):
            acc = P[j, j, c]
            for p in range(j):
                acc -= L[j, p, c] * L[j, p, c]
            good = acc > 0.0 and math.isfinite(acc)
            if not good:
                ok[c] = False
                acc = 1.0
            L[j, j, c] = math.sqrt(acc)
        for i in range(j + 1, n):
            for c in range(B):
                acc = P[i, j, c]
                for p in range(j):
                    acc -= L[i, p, c] * L[j, p, c]
                L[i, j, c] = acc / L[j, j, c]


@njit(cache=True, inline="always")
def _spd_inv_lanes(S, Si, L, B, ok, logdet):
    """Si = S⁻¹ and logdet for S (m, m, B) via Cholesky; ok[c] False where a lane fails."""
    m = S.shape[0]
    _chol_lanes(S, L, B, ok)
    for c in range(B):
        ld = 0.0
        for j in range(m):
            ld += math.log(L[j, j, c])
        logdet[c] = 2.0 * ld
    # Li = L⁻¹ (lower) stored in Si's lower part temporarily via a scratch
    Li = np.zeros((m, m, B))
    for j in range(m):
        for c in range(B):
            Li[j, j, c] = 1.0 / L[j, j, c]
        for i in range(j + 1, m):
            for c in range(B):
                acc = 0.0
                for p in range(j, i):
                    acc -= L[i, p, c] * Li[p, j, c]
                Li[i, j, c] = acc / L[i, i, c]
    for i in range(m):
        for j in range(m):
            for c in range(B):
                acc = 0.0
                for p in range(max(i, j), m):
                    acc += Li[p, i, c] * Li[p, j, c]
                Si[i, j, c] = acc


@njit(cache=True)
def _update_block(xp, Pp, zp, Pzz, Pxz, H, z, valid, R, angle, joseph, B,
                  x_out, P_out, innov, S_out, nis, dof, loglik, ok):
    """Masked Kalman update of one block (see module docstring); H used only with the Joseph form."""
    n = xp.shape[0]
    m = zp.shape[0]
    nu = np.empty((m, B))
    for a in range(m):
        for c in range(B):
            d = z[a, c] - zp[a, c]
            if angle and a == 1:
                d = wrap(d)
            innov[a, c] = d if valid[a, c] else np.nan
            nu[a, c] = d if valid[a, c] else 0.0
    S = np.empty((m, m, B))
    Reff = np.empty((m, m, B))
    for a in range(m):
        for b in range(m):
            for c in range(B):
                vv = valid[a, c] and valid[b, c]
                Reff[a, b, c] = R[a, b] if vv else (1.0 if a == b else 0.0)
                pz = Pzz[a, b, c] if vv else 0.0
                S[a, b, c] = pz + Reff[a, b, c]
    for a in range(m):
        for b in range(a + 1, m):
            for c in range(B):
                v = 0.5 * (S[a, b, c] + S[b, a, c])
                S[a, b, c] = v
                S[b, a, c] = v
    Si = np.empty((m, m, B))
    L = np.empty((m, m, B))
    ld = np.empty(B)
    _spd_inv_lanes(S, Si, L, B, ok, ld)
    # gain K = Pxz_masked S⁻¹ (n, m)
    K = np.zeros((n, m, B))
    for i in range(n):
        for b in range(m):
            for p in range(m):
                for c in range(B):
                    pxz = Pxz[i, p, c] if valid[p, c] else 0.0
                    K[i, b, c] += pxz * Si[p, b, c]
    for i in range(n):
        for c in range(B):
            acc = 0.0
            for b in range(m):
                acc += K[i, b, c] * nu[b, c]
            x_out[i, c] = xp[i, c] + acc
    if joseph:
        # A = I − K H (H rows masked), P = A P⁻ Aᵀ + K R Kᵀ
        Am = np.empty((n, n, B))
        for i in range(n):
            for j in range(n):
                for c in range(B):
                    acc = 1.0 if i == j else 0.0
                    for b in range(m):
                        hb = H[b, j, c] if valid[b, c] else 0.0
                        acc -= K[i, b, c] * hb
                    Am[i, j, c] = acc
        T = np.zeros((n, n, B))
        for i in range(n):
            for j in range(n):
                for p in range(n):
                    for c in range(B):
                        T[i, j, c] += Am[i, p, c] * Pp[p, j, c]
        KR = np.zeros((n, m, B))
        for i in range(n):
            for b in range(m):
                for p in range(m):
                    for c in range(B):
                        KR[i, b, c] += K[i, p, c] * Reff[p, b, c]
        for i in range(n):
            for j in range(n):
                for c in range(B):
                    acc = 0.0
                    for p in range(n):
                        acc += T[i, p, c] * Am[j, p, c]
                    acc2 = 0.0
                    for b in range(m):
                        acc2 += KR[i, b, c] * K[j, b, c]
                    P_out[i, j, c] = acc + acc2
    else:
        KS = np.zeros((n, m, B))
        for i in range(n):
            for b in range(m):
                for p in range(m):
                    for c in range(B):
                        KS[i, b, c] += K[i, p, c] * S[p, b, c]
        for i in range(n):
            for j in range(n):
                for c in range(B):
                    acc = 0.0
                    for b in range(m):
                        acc += KS[i, b, c] * K[j, b, c]
                    P_out[i, j, c] = Pp[i, j, c] - acc
    for i in range(n):
        for j in range(i + 1, n):
            for c in range(B):
                v = 0.5 * (P_out[i, j, c] + P_out[j, i, c])
                P_out[i, j, c] = v
                P_out[j, i, c] = v
    for c in range(B):
        q = 0.0
        d = 0
        for a in range(m):
            if valid[a, c]:
                d += 1
            for b in range(m):
                q += nu[a, c] * Si[a, b, c] * nu[b, c]
        dof[c] = d
        nis[c] = q if d > 0 else np.nan
        loglik[c] = -0.5 * (q + ld[c] + d * LOG_2PI) if d > 0 else 0.0
    for a in range(m):
        for b in range(m):
            for c in range(B):
                S_out[a, b, c] = S[a, b, c]


def _ekf_step(x, P, z, valid, F, Q, lam, hk, A, idx, scale, R, angle,
              x_out, P_out, xp_out, Pp_out, cross_out, innov, S_out, nis, dof, loglik, ok):
    """KF / EKF step (Joseph form) for lane-major arrays; linear motion F, Q."""
    n, M = x.shape
    m = R.shape[0]
    nblocks = (M + BLOCK - 1) // BLOCK
    for bb in prange(nblocks):
        r0 = np.int64(bb) * BLOCK
        r1 = min(r0 + BLOCK, M)
        B = r1 - r0
        # predict: xp = F x, cross = P Fᵀ, P⁻ = λ F cross + Q
        for i in range(n):
            for c in range(B):
                acc = 0.0
                for j in range(n):
                    acc += F[i, j] * x[j, r0 + c]
                xp_out[i, r0 + c] = acc
        for i in range(n):
            for j in range(n):
                for c in range(B):
                    acc = 0.0
                    for p in range(n):
                        acc += P[i, p, r0 + c] * F[j, p]
                    cross_out[i, j, r0 + c] = acc
        for i in range(n):
            for j in range(n):
                for c in range(B):
                    acc = 0.0
                    for p in range(n):
                        acc += F[i, p] * cross_out[p, j, r0 + c]
                    Pp_out[i, j, r0 + c] = (acc if lam == 1.0 else lam * acc) + Q[i, j]
        xp = xp_out[:, r0:r1]
        Pp = Pp_out[:, :, r0:r1]
        zp = np.empty((m, B))
        H = np.empty((m, n, B))
        for c in range(B):
            _h_lane(hk, A, idx, scale, xp, c, zp, c)
            _jac_lane(hk, A, idx, scale, xp, c, H, c)
        PHt = np.zeros((n, m, B))
        for i in range(n):
            for a in range(m):
                for p in range(n):
                    for c in range(B):
                        PHt[i, a, c] += Pp[i, p, c] * H[a, p, c]
        Pzz = np.zeros((m, m, B))
        for a in range(m):
            for b in range(m):
                for p in range(n):
                    for c in range(B):
                        Pzz[a, b, c] += H[a, p, c] * PHt[p, b, c]
        _update_block(xp, Pp, zp, Pzz, PHt, H, z[:, r0:r1], valid[:, r0:r1], R, angle, True, B,
                      x_out[:, r0:r1], P_out[:, :, r0:r1], innov[:, r0:r1], S_out[:, :, r0:r1],
                      nis[r0:r1], dof[r0:r1], loglik[r0:r1], ok[r0:r1])


def _sigma_step(x, P, z, valid, F, Q, lam, hk, A, idx, scale, R, angle, cscale, wm, wc, centre,
                x_out, P_out, xp_out, Pp_out, cross_out, innov, S_out, nis, dof, loglik, ok):
    """UKF / CKF step for lane-major arrays: points x (± cscale · columns of chol P), centre first if ``centre``."""
    n, M = x.shape
    m = R.shape[0]
    npts = wm.shape[0]
    nblocks = (M + BLOCK - 1) // BLOCK
    for bb in prange(nblocks):
        r0 = np.int64(bb) * BLOCK
        r1 = min(r0 + BLOCK, M)
        B = r1 - r0
        okb = ok[r0:r1]
        L = np.empty((n, n, B))
        _chol_lanes(P[:, :, r0:r1], L, B, okb)
        chi = np.empty((npts, n, B))
        _points(x[:, r0:r1], L, cscale, centre, chi, B)
        # propagate the points through F
        Y = np.empty((npts, n, B))
        for s in range(npts):
            for i in range(n):
                for c in range(B):
                    acc = 0.0
                    for j in range(n):
                        acc += F[i, j] * chi[s, j, c]
                    Y[s, i, c] = acc
        xp = xp_out[:, r0:r1]
        for i in range(n):
            for c in range(B):
                acc = 0.0
                for s in range(npts):
                    acc += wm[s] * Y[s, i, c]
                xp[i, c] = acc
        Pp = Pp_out[:, :, r0:r1]
        cr = cross_out[:, :, r0:r1]
        for i in range(n):
            for j in range(n):
                for c in range(B):
                    acc = 0.0
                    acc2 = 0.0
                    for s in range(npts):
                        dyj = Y[s, j, c] - xp[j, c]
                        acc += (Y[s, i, c] - xp[i, c]) * wc[s] * dyj
                        acc2 += (chi[s, i, c] - x[i, r0 + c]) * wc[s] * dyj
                    Pp[i, j, c] = acc
                    cr[i, j, c] = acc2
        for i in range(n):
            for j in range(n):
                for c in range(B):
                    v = 0.5 * (Pp[i, j, c] + Pp[j, i, c]) if i != j else Pp[i, j, c]
                    if j > i:
                        Pp[i, j, c] = v
                        Pp[j, i, c] = v
        for i in range(n):
            for j in range(n):
                for c in range(B):
                    Pp[i, j, c] = (Pp[i, j, c] if lam == 1.0 else lam * Pp[i, j, c]) + Q[i, j]
        # measurement: new points from the prediction
        _chol_lanes(Pp, L, B, okb)
        _points(xp, L, cscale, centre, chi, B)
        Z = np.empty((m, npts * B))
        for s in range(npts):
            for c in range(B):
                _h_lane(hk, A, idx, scale, chi[s], c, Z, s * B + c)
        zp = np.empty((m, B))
        for a in range(m):
            for c in range(B):
                z0 = Z[a, c]
                acc = 0.0
                for s in range(npts):
                    d = Z[a, s * B + c] - z0
                    if angle and a == 1:
                        d = wrap(d)
                    acc += wm[s] * d
                zp[a, c] = z0 + acc
        dZ = np.empty((npts, m, B))
        for s in range(npts):
            for a in range(m):
                for c in range(B):
                    d = Z[a, s * B + c] - zp[a, c]
                    if angle and a == 1:
                        d = wrap(d)
                    dZ[s, a, c] = d
        Pzz = np.zeros((m, m, B))
        Pxz = np.zeros((n, m, B))
        for s in range(npts):
            w = wc[s]
            for a in range(m):
                for b in range(m):
                    for c in range(B):
                        Pzz[a, b, c] += dZ[s, a, c] * w * dZ[s, b, c]
                for i in range(n):
                    for c in range(B):
                        Pxz[i, a, c] += (chi[s, i, c] - xp[i, c]) * w * dZ[s, a, c]
        _update_block(xp, Pp, zp, Pzz, Pxz, Pzz, z[:, r0:r1], valid[:, r0:r1], R, angle, False, B,
                      x_out[:, r0:r1], P_out[:, :, r0:r1], innov[:, r0:r1], S_out[:, :, r0:r1],
                      nis[r0:r1], dof[r0:r1], loglik[r0:r1], okb)


@njit(cache=True)
def _points(x, L, cscale, centre, chi, B):
    """Sigma points (npts, n, B): [x,] x + c·L[:, j], then x − c·L[:, j]."""
    n = x.shape[0]
    off = 1 if centre else 0
    for i in range(n):
        for c in range(B):
            if centre:
                chi[0, i, c] = x[i, c]
            for j in range(n):
                col = cscale * L[i, j, c]
                chi[off + j, i, c] = x[i, c] + col
                chi[off + n + j, i, c] = x[i, c] - col


ekf_step_parallel = njit(cache=True, parallel=True)(_ekf_step)
ekf_step_serial = njit(cache=True)(_ekf_step)
sigma_step_parallel = njit(cache=True, parallel=True)(_sigma_step)
sigma_step_serial = njit(cache=True)(_sigma_step)
