"""Compiled Kalman-family steps (KF/EKF with the Joseph form, UKF/CKF) with runs across SIMD lanes.

The state is stored as ``x (n, M)`` and ``P (n, n, M)``.  Each block of
``BLOCK`` runs is copied into block arrays whose last axis is the run, and
every loop has the runs innermost with a plain body, so the compiler
vectorises across runs (explicit loops, no BLAS: a 4 × 4 product through
BLAS costs more than its arithmetic).  Blocks run in parallel.

The arithmetic follows :mod:`pursuit.filters.gaussian` (predict
``P⁻ = λ F P Fᵀ + Q``, missing components masked, and for every filter the
Joseph form through a Cholesky factor L of P⁻: ``A_L A_Lᵀ + K (R + D) Kᵀ``
with ``A_L = L − K (H L)``, where H L is the Jacobian times L for the
KF/EKF (D = 0) and ``Gᵀ = (L⁻¹ Pxz)ᵀ`` summed from the sigma points, with D
their linearisation-error covariance, for the UKF/CKF (the NumPy UKF/CKF
form the sum as one Gram matrix; here it is still the product); a run that measures
nothing keeps P⁻ itself).  A run whose
covariance or innovation covariance does not factor (the NumPy filters
would repair it) is flagged in ``ok`` and recomputed by the caller with
NumPy.

The measurement half of each step (:func:`_ekf_correct`, :func:`_sigma_correct`)
is also a kernel of its own, :func:`correct_serial` / :func:`correct_parallel`,
for a filter that forms its prediction itself (the CS-model filter).

The whole-sequence kernels (:func:`_ekf_sequence`, :func:`_sigma_sequence`)
run every step of a block of runs in one call, the block's state and
scratch arrays allocated once.  The UKF/CKF step and sequence kernels share
their block functions (:func:`_sigma_predict_ws`, :func:`_sigma_correct_ws`),
so the two give the same bits whatever their block sizes: no loop reduces
across runs.

The UKF/CKF's sigma points are measured without libm calls in the loop over
the runs (:func:`_h_sigma_block`: RangeBearing's range and bearing by
``common.hypot_lanes`` / ``common.atan2_lanes``, within 1 ulp of libm's),
and an angle's differences are wrapped without the remainder where they are
already in [−π, π) (``common.wrap_inside``), so those loops vectorise; a
point the fast forms do not take gets the libm / ``wrap`` value in a second
loop, taken only when there is such a point (the same bits as those forms
wherever the fast ones apply).  The one-run kernels
(:mod:`.one_run_kernels`) measure their points through the same
``model_math.h_sigma_row``, so every compiled UKF/CKF path gives the same
bits.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .common import LOG_2PI, serial_and_parallel, wrap, wrap_inside
from .kernel_args import GaussOutputs
from .model_math import h_row, jac_row, range_bearing_lanes, wraps
from .specs import M_RANGE_BEARING

BLOCK = 512
SEQUENCE_BLOCK = 256
"""Runs per block of the UKF/CKF whole-sequence kernel: its state and scratch (about 450 kB for n = 4,
m = 2, 9 points) stay in the core's L2 cache from one step to the next, and each loop over the runs
is long enough to pay for its set-up (measured: 256 runs 1.4x faster than 16)."""
_NJ = dict(cache=True, error_model="numpy")


# --------------------------------------------------------------------------
# block linear algebra, runs innermost
# --------------------------------------------------------------------------
@njit(**_NJ)
def _cmv(F, x, out):
    """out[i] = Σ_j F[i, j] x[j] (F shared)."""
    for i in range(F.shape[0]):
        o = out[i]
        o[:] = 0.0
        for j in range(F.shape[1]):
            f = F[i, j]
            xj = x[j]
            for c in range(o.shape[0]):
                o[c] += f * xj[c]


@njit(**_NJ)
def _cmm(F, A, out):
    """out[i, j] = Σ_p F[i, p] A[p, j] (F shared)."""
    for i in range(F.shape[0]):
        for j in range(A.shape[1]):
            o = out[i, j]
            o[:] = 0.0
            for p in range(F.shape[1]):
                f = F[i, p]
                a = A[p, j]
                for c in range(o.shape[0]):
                    o[c] += f * a[c]


@njit(**_NJ)
def _mmT_c(A, F, out):
    """out[i, j] = Σ_p A[i, p] F[j, p] (F shared)."""
    for i in range(A.shape[0]):
        for j in range(F.shape[0]):
            o = out[i, j]
            o[:] = 0.0
            for p in range(A.shape[1]):
                f = F[j, p]
                a = A[i, p]
                for c in range(o.shape[0]):
                    o[c] += a[c] * f


@njit(**_NJ)
def _bmm(A, B, out):
    """out[i, j] = Σ_p A[i, p] B[p, j] (per run)."""
    for i in range(A.shape[0]):
        for j in range(B.shape[1]):
            o = out[i, j]
            o[:] = 0.0
            for p in range(A.shape[1]):
                a = A[i, p]
                b = B[p, j]
                for c in range(o.shape[0]):
                    o[c] += a[c] * b[c]


@njit(**_NJ)
def _bmmT(A, B, out):
    """out[i, j] = Σ_p A[i, p] B[j, p] (per run)."""
    for i in range(A.shape[0]):
        for j in range(B.shape[0]):
            o = out[i, j]
            o[:] = 0.0
            for p in range(A.shape[1]):
                a = A[i, p]
                b = B[j, p]
                for c in range(o.shape[0]):
                    o[c] += a[c] * b[c]


@njit(**_NJ)
def _add_process_noise(Pp, Q, lam):
    """P⁻ = (F P Fᵀ if λ = 1 else λ F P Fᵀ) + Q in place on a block (``one_run_kernels._predict_moments`` for one run)."""
    n = Q.shape[0]
    for i in range(n):
        for j in range(n):
            q = Q[i, j]
            p = Pp[i, j]
            for c in range(p.shape[0]):
                p[c] = (p[c] if lam == 1.0 else lam * p[c]) + q


@njit(**_NJ)
def _symmetrize(P):
    n = P.shape[0]
    for i in range(n):
        for j in range(i + 1, n):
            a = P[i, j]
            b = P[j, i]
            for c in range(a.shape[0]):
                v = 0.5 * (a[c] + b[c])
                a[c] = v
                b[c] = v


@njit(**_NJ)
def _chol(P, L, ok):
    """Lower Cholesky factors of P (n, n, B) into L; ok[c] = False where a run's P is not positive definite."""
    _chol_ws(P, L, ok, np.empty(P.shape[2]))


@njit(**_NJ)
def _chol_ws(P, L, ok, d):
    """:func:`_chol` with its scratch row ``d (B,)`` given (the whole-sequence kernel allocates it once)."""
    n = P.shape[0]
    B = P.shape[2]
    L[:] = 0.0
    for j in range(n):
        for c in range(B):
            d[c] = P[j, j, c]
        for p in range(j):
            lj = L[j, p]
            for c in range(B):
                d[c] -= lj[c] * lj[c]
        Ljj = L[j, j]
        for c in range(B):
            good = d[c] > 0.0 and d[c] < np.inf
            ok[c] &= good
            Ljj[c] = math.sqrt(d[c]) if good else 1.0
        for i in range(j + 1, n):
            Lij = L[i, j]
            for c in range(B):
                Lij[c] = P[i, j, c]
            for p in range(j):
                a = L[i, p]
                b = L[j, p]
                for c in range(B):
                    Lij[c] -= a[c] * b[c]
            for c in range(B):
                Lij[c] /= Ljj[c]


@njit(**_NJ)
def _spd_inv(S, Si, ok, logdet):
    """Si = S⁻¹ and log det S for S (m, m, B) through Cholesky."""
    m = S.shape[0]
    B = S.shape[2]
    if m == 1:
        for c in range(B):
            a = S[0, 0, c]
            good = a > 0.0 and a < np.inf
            ok[c] &= good
            Si[0, 0, c] = 1.0 / a
            logdet[c] = math.log(a) if good else 0.0
        return
    if m == 2:  # closed form, as pursuit._linalg.inv_spd; positive definite iff a > 0 and det > 0
        for c in range(B):
            a = S[0, 0, c]
            b = S[0, 1, c]
            d = S[1, 1, c]
            det = a * d - b * b
            good = a > 0.0 and det > 0.0 and det < np.inf
            ok[c] &= good
            inv = 1.0 / det
            Si[0, 0, c] = d * inv
            Si[0, 1, c] = -b * inv
            Si[1, 0, c] = -b * inv
            Si[1, 1, c] = a * inv
            logdet[c] = math.log(det) if good else 0.0
        return
    L = np.empty((m, m, B))
    _chol(S, L, ok)
    logdet[:] = 0.0
    for j in range(m):
        Ljj = L[j, j]
        for c in range(B):
            logdet[c] += 2.0 * math.log(Ljj[c])
    Li = np.zeros((m, m, B))
    for j in range(m):
        for c in range(B):
            Li[j, j, c] = 1.0 / L[j, j, c]
        for i in range(j + 1, m):
            o = Li[i, j]
            for p in range(j, i):
                a = L[i, p]
                b = Li[p, j]
                for c in range(B):
                    o[c] -= a[c] * b[c]
            for c in range(B):
                o[c] /= L[i, i, c]
    for i in range(m):
        for j in range(m):
            o = Si[i, j]
            o[:] = 0.0
            for p in range(max(i, j), m):
                a = Li[p, i]
                b = Li[p, j]
                for c in range(B):
                    o[c] += a[c] * b[c]


@njit(**_NJ)
def _h_block(sensor, X, out):
    """out (m, B) = h of the states X (n, B), run by run (:func:`.model_math.h_row` on the transposes)."""
    XT, oT = X.T, out.T
    for c in range(X.shape[1]):
        h_row(sensor, XT, c, oT, c)


@njit(**_NJ)
def _h_sigma_block(sensor, X, out):
    """out (m, B) = h of the sigma points X (n, B): :func:`.model_math.h_sigma_row` run by run, the same bits.

    RangeBearing in one loop over the runs without libm calls (it
    vectorises), then, only if there are any, libm's values for the runs
    :func:`.model_math.range_bearing_lanes` does not take (an offset with
    dx = 0 exactly, one beyond its range, NaN: one libm call per such run).
    """
    if sensor.kind != M_RANGE_BEARING:
        _h_block(sensor, X, out)
        return
    px, py = X[sensor.idx[0]], X[sensor.idx[1]]
    sx, sy = sensor.A[0, 0], sensor.A[0, 1]
    ranges, bearings = out[0], out[1]
    inexact = 0
    for c in range(X.shape[1]):
        r, b, exact = range_bearing_lanes(px[c] - sx, py[c] - sy)
        ranges[c] = r
        bearings[c] = b
        inexact += 0 if exact else 1
    if inexact:
        XT, oT = X.T, out.T
        for c in range(X.shape[1]):
            if not range_bearing_lanes(px[c] - sx, py[c] - sy)[2]:
                h_row(sensor, XT, c, oT, c)  # libm's values for this run (what h_sigma_row gives it)


@njit(**_NJ)
def _jac_block(sensor, X, H):
    """H (m, n, B) = ∂h/∂x at the states X (n, B), run by run (:func:`.model_math.jac_row`)."""
    XT, HT = X.T, H.transpose((2, 0, 1))
    for c in range(X.shape[1]):
        jac_row(sensor, XT, c, HT, c)


# --------------------------------------------------------------------------
# the masked update of one block
# --------------------------------------------------------------------------
@njit(**_NJ)
def _update_workspace(n, m, B):
    """Scratch arrays for :func:`_update_ws` (allocated once per block by the sequence kernel)."""
    return (np.empty((m, B)), np.empty((m, m, B)), np.empty((m, m, B)), np.empty((m, m, B)), np.empty(B),
            np.empty((n, m, B)), np.empty((n, m, B)), np.empty((n, n, B)), np.empty((n, m, B)), np.empty((n, n, B)),
            np.empty(B), np.empty(B))


@njit(**_NJ)
def _update(pred, obs, sensor, blk):
    """Kalman update of one block.

    ``pred = (xp, Pp, zp, Pzz, Pxz, L, HL, D)``: the predicted state and
    measurement moments, ``L (n, n, B)`` the Cholesky factor of ``Pp``,
    ``HL (m, n, B)`` the linearisation times L and ``D (m, m, B)`` the
    linearisation-error covariance added to R (zeros for the KF/EKF).
    ``obs = (z, v)`` with v (m, B) 1.0 where measured, 0.0 where missing.
    ``blk = (x, P, innov, S, nis, dof, loglik, ok)``: the block's outputs.
    """
    xp, zp = pred[0], pred[2]
    _update_ws(pred, obs, sensor, blk, _update_workspace(xp.shape[0], zp.shape[0], xp.shape[1]))


@njit(**_NJ)
def _update_ws(pred, obs, sensor, blk, ws):
    """:func:`_update` with its scratch arrays ``ws`` from :func:`_update_workspace`."""
    xp, Pp, zp, Pzz, Pxz, L, HL, D = pred
    z, v = obs
    R, angle, kind = sensor.R, sensor.angle, sensor.kind
    x_o, P_o, innov, S_o, nis, dof, loglik, ok = blk
    nu, S, Reff, Si, ld, Pxm, K, AL, KN, T2, q, dd = ws
    n = xp.shape[0]
    m = zp.shape[0]
    B = xp.shape[1]
    for a in range(m):
        for c in range(B):
            d = z[a, c] - zp[a, c]
            if wraps(kind, angle, a):
                d = wrap(d)
            meas = v[a, c] > 0.0
            innov[a, c] = d if meas else np.nan
            nu[a, c] = d if meas else 0.0
    for a in range(m):
        for b in range(m):
            eye = 1.0 if a == b else 0.0
            rab = R[a, b]
            for c in range(B):
                vv = v[a, c] * v[b, c]
                re = rab if vv > 0.0 else 0.0
                re += eye * (1.0 - v[b, c])
                Reff[a, b, c] = re
                S[a, b, c] = (Pzz[a, b, c] if vv > 0.0 else 0.0) + re
    _symmetrize(S)
    _spd_inv(S, Si, ok, ld)
    for i in range(n):
        for b in range(m):
            for c in range(B):
                Pxm[i, b, c] = Pxz[i, b, c] * v[b, c]
    _bmm(Pxm, Si, K)
    for i in range(n):
        for c in range(B):
            x_o[i, c] = xp[i, c]
        for b in range(m):
            for c in range(B):
                x_o[i, c] += K[i, b, c] * nu[b, c]
    # Joseph form through the factor: A_L = (I − K H) L = L − K (H L); K's columns of missing
    # components are zero, so HL needs no mask
    _bmm(K, HL, AL)
    for i in range(n):
        for j in range(n):
            for c in range(B):
                AL[i, j, c] = L[i, j, c] - AL[i, j, c]
    _bmmT(AL, AL, P_o)
    for a in range(m):  # the noise R_eff + D, D masked like R
        for b in range(m):
            for c in range(B):
                Reff[a, b, c] += D[a, b, c] * v[a, c] * v[b, c]
    _bmm(K, Reff, KN)
    _bmmT(KN, K, T2)
    for i in range(n):
        for j in range(n):
            for c in range(B):
                P_o[i, j, c] += T2[i, j, c]
    q[:] = 0.0
    dd[:] = 0.0
    for a in range(m):
        for c in range(B):
            dd[c] += v[a, c]
    for i in range(n):  # nothing measured: the prediction itself, not its factor's L Lᵀ
        for j in range(n):
            for c in range(B):
                if dd[c] == 0.0:
                    P_o[i, j, c] = Pp[i, j, c]
    _symmetrize(P_o)
    for a in range(m):
        for b in range(m):
            for c in range(B):
                q[c] += nu[a, c] * Si[a, b, c] * nu[b, c]
    for c in range(B):
        d = dd[c]
        dof[c] = np.int64(d)
        nis[c] = q[c] if d > 0 else np.nan
        loglik[c] = -0.5 * (q[c] + ld[c] + d * LOG_2PI) if d > 0 else 0.0
    S_o[:] = S


@njit(**_NJ)
def _load(x, P, z, valid, r0, B):
    n = x.shape[0]
    m = z.shape[0]
    xb = np.empty((n, B))
    Pb = np.empty((n, n, B))
    zb = np.empty((m, B))
    vb = np.empty((m, B))
    for i in range(n):
        for c in range(B):
            xb[i, c] = x[i, r0 + c]
        for j in range(n):
            for c in range(B):
                Pb[i, j, c] = P[i, j, r0 + c]
    for a in range(m):
        for c in range(B):
            zb[a, c] = z[a, r0 + c]
            vb[a, c] = 1.0 if valid[a, r0 + c] else 0.0
    return xb, Pb, zb, vb


@njit(**_NJ)
def _store(blk, full, r0):
    """full[..., r0:r0+B] = blk for 1-, 2- and 3-axis arrays flattened to (rows, B)."""
    B = blk.shape[-1]
    b2 = blk.reshape(-1, B)
    f2 = full.reshape(-1, full.shape[-1])
    for i in range(b2.shape[0]):
        for c in range(B):
            f2[i, r0 + c] = b2[i, c]


@njit(**_NJ)
def _ekf_correct(xp, Pp, zb, vb, sensor, blk):
    """The EKF's measurement update of one block: linearise h at the prediction ``(xp, Pp)``, then :func:`_update` into ``blk``."""
    n, B = xp.shape
    m = zb.shape[0]
    zp = np.empty((m, B))
    _h_block(sensor, xp, zp)
    H = np.empty((m, n, B))
    _jac_block(sensor, xp, H)
    PHt = np.empty((n, m, B))
    _bmmT(Pp, H, PHt)
    Pzz = np.empty((m, m, B))
    _bmm(H, PHt, Pzz)
    L = np.empty((n, n, B))
    _chol(Pp, L, blk[7])
    HL = np.empty((m, n, B))
    _bmm(H, L, HL)
    _update((xp, Pp, zp, Pzz, PHt, L, HL, np.zeros((m, m, B))), (zb, vb), sensor, blk)


def _ekf_step(state, obs, prediction, sensor, out):
    """KF / EKF step (Joseph form) on lane-major arrays; linear motion F, Q.

    ``state = (x (n, M), P (n, n, M))``, ``obs = (z (m, M), valid)``,
    ``prediction`` a :class:`~.kernel_args.Prediction`, ``sensor`` the
    packed measurement model, ``out`` a :class:`~.kernel_args.GaussOutputs`.
    """
    x, P = state
    z, valid = obs
    F, Q, lam = prediction
    R = sensor.R
    x_out, P_out, xp_out, Pp_out, cross_out, innov, S_out, nis, dof, loglik, ok = out
    n, M = x.shape
    m = R.shape[0]
    nblocks = (M + BLOCK - 1) // BLOCK
    for bb in prange(nblocks):
        r0 = np.int64(bb) * BLOCK
        B = min(r0 + BLOCK, M) - r0
        xb, Pb, zb, vb = _load(x, P, z, valid, r0, B)
        xp = np.empty((n, B))
        _cmv(F, xb, xp)
        cross = np.empty((n, n, B))
        _mmT_c(Pb, F, cross)
        Pp = np.empty((n, n, B))
        _cmm(F, cross, Pp)
        _add_process_noise(Pp, Q, lam)
        xo, Po = np.empty((n, B)), np.empty((n, n, B))
        inb, Sb = np.empty((m, B)), np.empty((m, m, B))
        nb, lb = np.empty(B), np.empty(B)
        db = np.empty(B, dtype=np.int64)
        okb = np.ones(B, dtype=np.bool_)
        _ekf_correct(xp, Pp, zb, vb, sensor, (xo, Po, inb, Sb, nb, db, lb, okb))
        _store(xo, x_out, r0)
        _store(Po, P_out, r0)
        _store(xp, xp_out, r0)
        _store(Pp, Pp_out, r0)
        _store(cross, cross_out, r0)
        _store(inb, innov, r0)
        _store(Sb, S_out, r0)
        for c in range(B):
            nis[r0 + c] = nb[c]
            dof[r0 + c] = db[c]
            loglik[r0 + c] = lb[c]
            ok[r0 + c] = okb[c]


def _ekf_sequence(prior, obs, prediction, sensor, keep_cov, out):
    """All K steps of the KF / EKF for every run, without returning to Python between steps.

    The same block arithmetic as :func:`_ekf_step`, step after step, with
    each block's state kept in block arrays.  Inputs are lane-major
    (``prior = (x0 (n, M), P0 (n, n, M))``, ``obs = (zs, valid)``, each
    ``(K, m, M)``); ``out`` (a :class:`~.kernel_args.GaussSequenceOutputs`)
    is in the track's layout (``means (K, M, n)``, ``covs (K, M, n, n)``
    when ``keep_cov``, ``innov (K, M, m)``, ``S (K, M, m, m)``, ``nis``,
    ``dof``, ``loglik`` ``(K, M)``).  ``out.ok[r]`` ends False when run r's
    covariance or innovation covariance failed to factor at any step; the
    caller recomputes such runs step by step.
    """
    x0, P0 = prior
    zs, valid = obs
    F, Q, lam = prediction
    R = sensor.R
    means, covs, innov, S_out, nis, dof, loglik, ok = out
    n, M = x0.shape
    m = R.shape[0]
    K = zs.shape[0]
    nblocks = (M + BLOCK - 1) // BLOCK
    for bb in prange(nblocks):
        r0 = np.int64(bb) * BLOCK
        B = min(r0 + BLOCK, M) - r0
        xb, Pb, zb, vb = _load(x0, P0, zs[0], valid[0], r0, B)
        xp = np.empty((n, B))
        cross = np.empty((n, n, B))
        Pp = np.empty((n, n, B))
        zp = np.empty((m, B))
        H = np.empty((m, n, B))
        PHt = np.empty((n, m, B))
        Pzz = np.empty((m, m, B))
        xo, Po = np.empty((n, B)), np.empty((n, n, B))
        inb, Sb = np.empty((m, B)), np.empty((m, m, B))
        nb, lb = np.empty(B), np.empty(B)
        db = np.empty(B, dtype=np.int64)
        okb = np.ones(B, dtype=np.bool_)
        L = np.empty((n, n, B))
        d = np.empty(B)
        HL = np.empty((m, n, B))
        D0 = np.zeros((m, m, B))
        ws = _update_workspace(n, m, B)
        for k in range(K):
            for a in range(m):
                for c in range(B):
                    zb[a, c] = zs[k, a, r0 + c]
                    vb[a, c] = 1.0 if valid[k, a, r0 + c] else 0.0
            _cmv(F, xb, xp)
            _mmT_c(Pb, F, cross)
            _cmm(F, cross, Pp)
            _add_process_noise(Pp, Q, lam)
            _h_block(sensor, xp, zp)
            _jac_block(sensor, xp, H)
            _bmmT(Pp, H, PHt)
            _bmm(H, PHt, Pzz)
            _chol_ws(Pp, L, okb, d)
            _bmm(H, L, HL)
            _update_ws((xp, Pp, zp, Pzz, PHt, L, HL, D0), (zb, vb), sensor, (xo, Po, inb, Sb, nb, db, lb, okb), ws)
            for c in range(B):
                r = r0 + c
                for i in range(n):
                    means[k, r, i] = xo[i, c]
                    if keep_cov:
                        for j in range(n):
                            covs[k, r, i, j] = Po[i, j, c]
                for a in range(m):
                    innov[k, r, a] = inb[a, c]
                    for b in range(m):
                        S_out[k, r, a, b] = Sb[a, b, c]
                nis[k, r] = nb[c]
                dof[k, r] = db[c]
                loglik[k, r] = lb[c]
            xb, xo = xo, xb  # the posterior is the next step's prior: the buffers trade places, nothing is copied
            Pb, Po = Po, Pb
        for c in range(B):
            ok[r0 + c] = okb[c]


@njit(**_NJ)
def _points(x, L, cscale, centre, chi):
    """Sigma points (npts, n, B): [x,] x + c·L[:, j], then x − c·L[:, j]."""
    n = x.shape[0]
    B = x.shape[1]
    off = 1 if centre else 0
    for i in range(n):
        if centre:
            for c in range(B):
                chi[0, i, c] = x[i, c]
        for j in range(n):
            for c in range(B):
                col = cscale * L[i, j, c]
                chi[off + j, i, c] = x[i, c] + col
                chi[off + n + j, i, c] = x[i, c] - col


@njit(**_NJ)
def _sigma_workspace(n, m, npts, B):
    """Scratch arrays of one block's UKF/CKF step (:func:`_sigma_predict_ws`, :func:`_sigma_correct_ws`).

    ``(d, L, chi, Z, zp, dZ, Pzz, Pxz, GT, E, D, update)``: the Cholesky row
    scratch, the factor (P Fᵀ in the prediction, which needs no factor), the
    points, their images, and :func:`_update_workspace`'s arrays.
    """
    return (np.empty(B), np.empty((n, n, B)), np.empty((npts, n, B)), np.empty((npts, m, B)), np.empty((m, B)),
            np.empty((npts, m, B)), np.empty((m, m, B)), np.empty((n, m, B)), np.empty((m, n, B)), np.empty((npts, m, B)),
            np.empty((m, m, B)), _update_workspace(n, m, B))


@njit(**_NJ)
def _sigma_predict_ws(xb, Pb, prediction, pred, with_cross, ws):
    """The UKF/CKF's prediction of one block into ``pred = (xp, Pp, cross)``: F x, F P Fᵀ, without points.

    The motion is linear (F, Q), and the unscented transform of a linear map
    is exact, so the points' moments are F x, F P Fᵀ and P Fᵀ: the
    arithmetic of :func:`_ekf_step`'s prediction, symmetrised as the points'
    sum was (:meth:`pursuit.filters.gaussian._SigmaPointFilter._predict`
    likewise).  ``cross`` (the smoother's cross-covariance) is written only if
    ``with_cross`` (the factor's scratch ``ws[1]`` holds P Fᵀ otherwise);
    ``xp`` and ``Pp`` are the same bits either way.  Nothing is factored: a
    covariance that does not factor is flagged where the update draws its
    points.
    """
    F, Q, lam = prediction
    xp, Pp, cross = pred
    PFt = cross if with_cross else ws[1]
    _cmv(F, xb, xp)
    _mmT_c(Pb, F, PFt)
    _cmm(F, PFt, Pp)
    _symmetrize(Pp)
    _add_process_noise(Pp, Q, lam)


@njit(**_NJ)
def _mean_angles(Z, wm, kind, angle, zp):
    """zp (m, B) = Σ wm[s] · (Z[s] − Z[0]), the differences of an angle component wrapped (the sum before Z[0] is added).

    The remainder is taken only for a difference that needs it (:func:`.common.wrap_inside`).
    """
    npts, m, B = Z.shape
    zp[:] = 0.0
    for s in range(npts):
        w = wm[s]
        for a in range(m):
            for c in range(B):
                dz = Z[s, a, c] - Z[0, a, c]
                if wraps(kind, angle, a):
                    fast, inside = wrap_inside(dz)
                    dz = fast if inside else wrap(dz)
                zp[a, c] += w * dz


@njit(**_NJ)
def _mean_angles_inside(Z, wm, kind, angle, zp):
    """:func:`_mean_angles` through :func:`.common.wrap_inside`; True where some difference was outside [−π, π) (zp unusable)."""
    npts, m, B = Z.shape
    zp[:] = 0.0
    outside = 0
    for s in range(npts):
        w = wm[s]
        for a in range(m):
            if wraps(kind, angle, a):
                for c in range(B):
                    dz, inside = wrap_inside(Z[s, a, c] - Z[0, a, c])
                    zp[a, c] += w * dz
                    outside += 0 if inside else 1
            else:
                for c in range(B):
                    zp[a, c] += w * (Z[s, a, c] - Z[0, a, c])
    return outside > 0


@njit(**_NJ)
def _residuals(Z, zp, kind, angle, dZ):
    """dZ (npts, m, B) = Z − zp, an angle component wrapped (the remainder only where needed, as :func:`_mean_angles`)."""
    npts, m, B = Z.shape
    for s in range(npts):
        for a in range(m):
            for c in range(B):
                dz = Z[s, a, c] - zp[a, c]
                if wraps(kind, angle, a):
                    fast, inside = wrap_inside(dz)
                    dz = fast if inside else wrap(dz)
                dZ[s, a, c] = dz


@njit(**_NJ)
def _residuals_inside(Z, zp, kind, angle, dZ):
    """:func:`_residuals` through :func:`.common.wrap_inside`; True where some residual was outside [−π, π) (dZ unusable)."""
    npts, m, B = Z.shape
    outside = 0
    for s in range(npts):
        for a in range(m):
            if wraps(kind, angle, a):
                for c in range(B):
                    dz, inside = wrap_inside(Z[s, a, c] - zp[a, c])
                    dZ[s, a, c] = dz
                    outside += 0 if inside else 1
            else:
                for c in range(B):
                    dZ[s, a, c] = Z[s, a, c] - zp[a, c]
    return outside > 0


@njit(**_NJ)
def _sigma_correct(xp, Pp, zb, vb, sensor, sigma, blk):
    """The UKF/CKF's measurement update of one block: points redrawn from the prediction ``(xp, Pp)``, then :func:`_update` into ``blk``."""
    n, B = xp.shape
    _sigma_correct_ws(xp, Pp, zb, vb, sensor, sigma, blk, _sigma_workspace(n, zb.shape[0], sigma.wm.shape[0], B))


@njit(**_NJ)
def _sigma_correct_ws(xp, Pp, zb, vb, sensor, sigma, blk, ws):
    """:func:`_sigma_correct` with its scratch arrays ``ws`` from :func:`_sigma_workspace`."""
    cscale, wm, wc, centre = sigma
    angle, kind = sensor.angle, sensor.kind
    n, B = xp.shape
    m = zb.shape[0]
    npts = wm.shape[0]
    okb = blk[7]
    d, L, chi, Z, zp, dZ, Pzz, Pxz, GT, E, D = ws[0], ws[1], ws[2], ws[3], ws[4], ws[5], ws[6], ws[7], ws[8], ws[9], ws[10]
    # measurement: points redrawn from the prediction
    _chol_ws(Pp, L, okb, d)
    _points(xp, L, cscale, centre, chi)
    for s in range(npts):
        _h_sigma_block(sensor, chi[s], Z[s])
    # an angle's differences are wrapped without the remainder where they are already in [−π, π) (the
    # loops vectorise); if any is not, the loop is done again taking the remainder where it is needed
    if _mean_angles_inside(Z, wm, kind, angle, zp):
        _mean_angles(Z, wm, kind, angle, zp)
    for a in range(m):
        for c in range(B):
            zp[a, c] += Z[0, a, c]
    if _residuals_inside(Z, zp, kind, angle, dZ):
        _residuals(Z, zp, kind, angle, dZ)
    Pzz[:] = 0.0
    Pxz[:] = 0.0
    for s in range(npts):
        w = wc[s]
        for a in range(m):
            for b in range(m):
                for c in range(B):
                    Pzz[a, b, c] += dZ[s, a, c] * w * dZ[s, b, c]
            for i in range(n):
                for c in range(B):
                    Pxz[i, a, c] += (chi[s, i, c] - xp[i, c]) * w * dZ[s, a, c]
    # statistical linearisation, factored (as the NumPy filter): with χ = x⁻ + L ξ and the unit
    # points ξ = ±cscale e_j, G = Σ wc ξ dZᵀ = L⁻¹ Pxz, and D = Σ wc e eᵀ with e = dZ − Gᵀ ξ
    off = 1 if centre else 0
    GT[:] = 0.0  # (H L) = Gᵀ
    for j in range(n):
        wp = wc[off + j] * cscale
        wn = wc[off + n + j] * cscale
        for a in range(m):
            for c in range(B):
                GT[a, j, c] = wp * dZ[off + j, a, c] - wn * dZ[off + n + j, a, c]
    for a in range(m):
        for c in range(B):
            if centre:
                E[0, a, c] = dZ[0, a, c]
            for j in range(n):
                g = cscale * GT[a, j, c]
                E[off + j, a, c] = dZ[off + j, a, c] - g
                E[off + n + j, a, c] = dZ[off + n + j, a, c] + g
    D[:] = 0.0
    for s in range(npts):
        w = wc[s]
        for a in range(m):
            for b in range(m):
                for c in range(B):
                    D[a, b, c] += E[s, a, c] * w * E[s, b, c]
    _update_ws((xp, Pp, zp, Pzz, Pxz, L, GT, D), (zb, vb), sensor, blk, ws[11])


def _sigma_step(state, obs, prediction, sensor, sigma, out):
    """UKF / CKF step on lane-major arrays (points x ± cscale · columns of chol P, centre first if ``centre``).

    Arguments as :func:`_ekf_step`'s, with ``sigma`` a :class:`~.kernel_args.SigmaPoints`.
    """
    x, P = state
    z, valid = obs
    R = sensor.R
    wm = sigma.wm
    x_out, P_out, xp_out, Pp_out, cross_out, innov, S_out, nis, dof, loglik, ok = out
    n, M = x.shape
    m = R.shape[0]
    npts = wm.shape[0]
    nblocks = (M + BLOCK - 1) // BLOCK
    for bb in prange(nblocks):
        r0 = np.int64(bb) * BLOCK
        B = min(r0 + BLOCK, M) - r0
        xb, Pb, zb, vb = _load(x, P, z, valid, r0, B)
        okb = np.ones(B, dtype=np.bool_)
        ws = _sigma_workspace(n, m, npts, B)
        xp, Pp, cross = np.empty((n, B)), np.empty((n, n, B)), np.empty((n, n, B))
        _sigma_predict_ws(xb, Pb, prediction, (xp, Pp, cross), True, ws)
        xo, Po = np.empty((n, B)), np.empty((n, n, B))
        inb, Sb = np.empty((m, B)), np.empty((m, m, B))
        nb, lb = np.empty(B), np.empty(B)
        db = np.empty(B, dtype=np.int64)
        _sigma_correct_ws(xp, Pp, zb, vb, sensor, sigma, (xo, Po, inb, Sb, nb, db, lb, okb), ws)
        _store(xo, x_out, r0)
        _store(Po, P_out, r0)
        _store(xp, xp_out, r0)
        _store(Pp, Pp_out, r0)
        _store(cross, cross_out, r0)
        _store(inb, innov, r0)
        _store(Sb, S_out, r0)
        for c in range(B):
            nis[r0 + c] = nb[c]
            dof[r0 + c] = db[c]
            loglik[r0 + c] = lb[c]
            ok[r0 + c] = okb[c]


def _sigma_sequence(prior, obs, prediction, sensor, sigma, keep_cov, out):
    """All K steps of the UKF / CKF for every run, without returning to Python between steps.

    The arithmetic of :func:`_sigma_step` (the same :func:`_sigma_predict_ws`
    and :func:`_sigma_correct_ws`, so the same bits), step after step, with
    each block of :data:`SEQUENCE_BLOCK` runs kept in block arrays and every
    scratch array allocated once per block, not once per step.  Arguments
    and outputs as :func:`_ekf_sequence`'s, with ``sigma`` a
    :class:`~.kernel_args.SigmaPoints`; the smoother's cross-covariance is
    not computed.
    """
    x0, P0 = prior
    zs, valid = obs
    means, covs, innov, S_out, nis, dof, loglik, ok = out
    n, M = x0.shape
    m = sensor.R.shape[0]
    K = zs.shape[0]
    npts = sigma.wm.shape[0]
    nblocks = (M + SEQUENCE_BLOCK - 1) // SEQUENCE_BLOCK
    for bb in prange(nblocks):
        r0 = np.int64(bb) * SEQUENCE_BLOCK
        B = min(r0 + SEQUENCE_BLOCK, M) - r0
        xb, Pb, zb, vb = _load(x0, P0, zs[0], valid[0], r0, B)
        xp, Pp, cross = np.empty((n, B)), np.empty((n, n, B)), np.empty((n, n, 1))
        xo, Po = np.empty((n, B)), np.empty((n, n, B))
        inb, Sb = np.empty((m, B)), np.empty((m, m, B))
        nb, lb = np.empty(B), np.empty(B)
        db = np.empty(B, dtype=np.int64)
        okb = np.ones(B, dtype=np.bool_)
        ws = _sigma_workspace(n, m, npts, B)
        for k in range(K):
            for a in range(m):
                for c in range(B):
                    zb[a, c] = zs[k, a, r0 + c]
                    vb[a, c] = 1.0 if valid[k, a, r0 + c] else 0.0
            _sigma_predict_ws(xb, Pb, prediction, (xp, Pp, cross), False, ws)
            _sigma_correct_ws(xp, Pp, zb, vb, sensor, sigma, (xo, Po, inb, Sb, nb, db, lb, okb), ws)
            for c in range(B):
                r = r0 + c
                for i in range(n):
                    means[k, r, i] = xo[i, c]
                    if keep_cov:
                        for j in range(n):
                            covs[k, r, i, j] = Po[i, j, c]
                for a in range(m):
                    innov[k, r, a] = inb[a, c]
                    for b in range(m):
                        S_out[k, r, a, b] = Sb[a, b, c]
                nis[k, r] = nb[c]
                dof[k, r] = db[c]
                loglik[k, r] = lb[c]
            xb, xo = xo, xb  # the posterior is the next step's prior: the buffers trade places, nothing is copied
            Pb, Po = Po, Pb
        for c in range(B):
            ok[r0 + c] = okb[c]


def _correct_only(prediction, obs, sensor, sigma, out):
    """The measurement update alone, for a filter that predicts by itself (the CS-model filter).

    ``prediction = (xp (n, M), Pp (n, n, M))`` lane-major, ``obs = (z, valid)``
    ``(m, M)``, ``sigma`` a :class:`~.kernel_args.SigmaPoints` (UKF/CKF update)
    or ``None`` (EKF update), ``out`` a :class:`~.kernel_args.GaussUpdateOutputs`.
    The same block arithmetic as the measurement half of :func:`_ekf_step` /
    :func:`_sigma_step`.
    """
    xp_all, Pp_all = prediction
    z, valid = obs
    x_out, P_out, innov, S_out, nis, dof, loglik, ok = out
    n, M = xp_all.shape
    m = sensor.R.shape[0]
    nblocks = (M + BLOCK - 1) // BLOCK
    for bb in prange(nblocks):
        r0 = np.int64(bb) * BLOCK
        B = min(r0 + BLOCK, M) - r0
        xp, Pp, zb, vb = _load(xp_all, Pp_all, z, valid, r0, B)
        xo, Po = np.empty((n, B)), np.empty((n, n, B))
        inb, Sb = np.empty((m, B)), np.empty((m, m, B))
        nb, lb = np.empty(B), np.empty(B)
        db = np.empty(B, dtype=np.int64)
        okb = np.ones(B, dtype=np.bool_)
        blk = (xo, Po, inb, Sb, nb, db, lb, okb)
        if sigma is None:
            _ekf_correct(xp, Pp, zb, vb, sensor, blk)
        else:
            _sigma_correct(xp, Pp, zb, vb, sensor, sigma, blk)
        _store(xo, x_out, r0)
        _store(Po, P_out, r0)
        _store(inb, innov, r0)
        _store(Sb, S_out, r0)
        for c in range(B):
            nis[r0 + c] = nb[c]
            dof[r0 + c] = db[c]
            loglik[r0 + c] = lb[c]
            ok[r0 + c] = okb[c]


ekf_step_serial, ekf_step_parallel = serial_and_parallel(_ekf_step, **_NJ)
ekf_sequence_serial, ekf_sequence_parallel = serial_and_parallel(_ekf_sequence, **_NJ)
sigma_step_serial, sigma_step_parallel = serial_and_parallel(_sigma_step, **_NJ)
sigma_sequence_serial, sigma_sequence_parallel = serial_and_parallel(_sigma_sequence, **_NJ)
correct_serial, correct_parallel = serial_and_parallel(_correct_only, **_NJ)


# --------------------------------------------------------------------------
# one run stepped from Python (pursuit._compiled.online)
# --------------------------------------------------------------------------
_MAX_Z = 2.0**500  # pursuit._validation.MAX_MEASUREMENT


@njit(**_NJ)
def _one_setup(x, P, z, out):
    """The lane-major views of one run for the step kernels, and the outputs as views of ``out``.

    ``out`` has the rows of :func:`pursuit._compiled.kf_codegen.step_rows`
    (x, xp, P, Pp, cross, innov, S, nis, loglik, dof, ok), one lane; ``dof``
    and ``ok`` are written by :func:`_one_finish`.  Returns None for a ``z``
    with an infinity or a value beyond ±2⁵⁰⁰.
    """
    n = x.shape[0]
    m = z.shape[0]
    nn = n * n
    zl = np.empty((m, 1))
    valid = np.empty((m, 1), dtype=np.bool_)
    bad = False
    for a in range(m):
        zl[a, 0] = z[a]
        valid[a, 0] = not np.isnan(z[a])
        bad = bad or abs(z[a]) > _MAX_Z
    o = 2 * n + 3 * nn
    outs = GaussOutputs(out[0:n].reshape((n, 1)), out[2 * n:2 * n + nn].reshape((n, n, 1)), out[n:2 * n].reshape((n, 1)),
                        out[2 * n + nn:2 * n + 2 * nn].reshape((n, n, 1)), out[2 * n + 2 * nn:o].reshape((n, n, 1)),
                        out[o:o + m].reshape((m, 1)), out[o + m:o + m + m * m].reshape((m, m, 1)),
                        out[o + m + m * m:o + m + m * m + 1], np.empty(1, dtype=np.int64),
                        out[o + m + m * m + 1:o + m + m * m + 2], np.ones(1, dtype=np.bool_))
    return (x.reshape((n, 1)), P.reshape((n, n, 1))), (zl, valid), outs, bad


@njit(**_NJ)
def _one_finish(out, outs):
    """dof and ok into the last two rows of ``out``; the return code of :func:`ekf_one` / :func:`sigma_one`."""
    k = out.shape[0] - 2
    out[k] = outs.dof[0]
    out[k + 1] = 1.0 if outs.ok[0] else 0.0
    return 0 if outs.ok[0] else 2


@njit(**_NJ)
def ekf_one(x, P, z, prediction, sensor, out):
    """One KF/EKF step of one run: :func:`ekf_step_serial` on one lane, its results in ``out``; 1 if ``z`` is unusable, 2 if a covariance does not factor, else 0."""
    state, obs, outs, bad = _one_setup(x, P, z, out)
    if bad:
        return 1
    ekf_step_serial(state, obs, prediction, sensor, outs)
    return _one_finish(out, outs)


@njit(**_NJ)
def sigma_one(x, P, z, prediction, sensor, sigma, out):
    """One UKF/CKF step of one run: :func:`sigma_step_serial` on one lane, its results in ``out``; 1 if ``z`` is unusable, 2 if a covariance does not factor, else 0."""
    state, obs, outs, bad = _one_setup(x, P, z, out)
    if bad:
        return 1
    sigma_step_serial(state, obs, prediction, sensor, sigma, outs)
    return _one_finish(out, outs)
