"""Small batched linear-algebra helpers used by every filter.

Everything here works on stacks of small matrices, ``(*batch, n, n)``, and is
chosen for two properties the rest of pursuit relies on:

* **Batch invariance.**  The result for one run does not depend on how many
  other runs share the batch, bit for bit.  A single large GEMM over all runs
  does *not* have that property (OpenBLAS takes different kernels for edge
  rows), so vector products go through ``einsum`` and matrix products through
  ``np.matmul`` on explicit stacks, which calls one fixed-size kernel per
  matrix.
* **Speed on tiny matrices.**  LAPACK calls cost about 200 ns per matrix, so
  inverses, determinants and Cholesky factors of 1x1 to 3x3 matrices are
  written out explicitly.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

__all__ = [
    "symmetrize",
    "mv",
    "apply_matrix",
    "quad",
    "quadratic_form",
    "inv_spd",
    "logdet_spd",
    "cholesky_psd",
    "psd_factor",
    "numerical_jacobian",
    "is_shared",
    "small_inv_logdet",
    "small_inv_det",
    "small_cholesky",
]


def symmetrize(P: np.ndarray) -> np.ndarray:
    """Return ``(P + P^T) / 2`` over the last two axes."""
    return 0.5 * (P + np.swapaxes(P, -1, -2))


def mv(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Batched matrix-vector product ``A @ x`` over the last axes.

    ``A`` is ``(*b, p, n)`` or ``(p, n)``, ``x`` is ``(*b, n)``.
    """
    return np.einsum("...ij,...j->...i", A, x)


def apply_matrix(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``A x`` for one matrix ``A`` ``(p, n)`` and a batch of vectors ``x`` ``(*b, n)``.

    With two or more batch axes (sigma points, particles) ``np.matmul`` runs
    one small GEMM per inner matrix, which is fast and batch-invariant; a
    plain ``(M, n)`` batch goes through ``einsum``, because one big GEMM over
    all runs would not be batch-invariant.
    """
    if x.ndim >= 3:
        return np.matmul(x, A.T)
    return np.einsum("ij,...j->...i", A, x)


def quad(x: np.ndarray, A: np.ndarray) -> np.ndarray:
    """Batched quadratic form ``x^T A x``: ``(*b, n), (*b, n, n) -> (*b,)``.

    Up to ``n = 4`` through :func:`quadratic_form` (n² whole-array products:
    several times faster than a three-operand ``einsum``); above, ``einsum``.
    Both sum in a fixed order per entry, so either is batch-invariant.
    """
    if x.shape[-1] <= 4:
        return quadratic_form(x, A)
    return np.einsum("...i,...ij,...j->...", x, A, x)


def quadratic_form(x: np.ndarray, A: np.ndarray) -> np.ndarray:
    """``Σ_ij x_i A_ij x_j`` over the last axis of ``x (..., n)`` and the last two of ``A (..., n, n)``, broadcast.

    Written as n² products of whole arrays, one component at a time:
    ``Σ_j x_j (Σ_i x_i A_ij)``, the inner sum in the order i = 0..n−1.  A
    three-operand ``einsum`` such as ``"...i,ij,...j->..."`` takes a generic
    loop that costs 6-9x more on the stacks the trackers make (PMHT residuals
    ``(M, L, B, D, 2)``, 2-4-dimensional innovations).  Every entry is summed
    in the same order whatever the batch, so the result is batch-invariant.
    Meant for small n: the cost grows as n² array passes.  Overflow and
    invalid operations give inf and NaN without a warning, as ``einsum`` does.
    """
    n = x.shape[-1]
    if A.shape[-2:] != (n, n):
        raise ValueError(f"quadratic_form: A must end in ({n}, {n}) to match x, got shape {A.shape}")
    out = None
    with np.errstate(over="ignore", invalid="ignore"):  # inf and NaN pass through silently, as through einsum
        for j in range(n):
            t = x[..., 0] * A[..., 0, j]
            for i in range(1, n):
                t += x[..., i] * A[..., i, j]
            t *= x[..., j]
            if out is None:
                out = t
            else:
                out += t
    if out is None:  # n = 0: the empty sum
        return np.zeros(np.broadcast_shapes(x.shape[:-1], A.shape[:-2]))
    return out


def inv_spd(S: np.ndarray) -> np.ndarray:
    """Inverse of a stack of symmetric positive-definite matrices.

    Sizes 1 to 3 use closed forms (about 20x faster than LAPACK on stacks of
    tiny matrices); larger sizes call ``np.linalg.inv``.  Cofactor formulas
    lose accuracy when the determinant is tiny against the product of the
    diagonal (an ill-conditioned S, e.g. a huge predicted covariance against
    a tiny R); such matrices are inverted by an eigendecomposition instead.
    For sizes 4 and up, a matrix that is singular in floating point (R lost
    to round-off against an H P Hᵀ more than 1/ε larger, where LAPACK would
    raise) gets the same pseudo-inverse; the others keep LAPACK's inverse,
    bit for bit.
    """
    m = S.shape[-1]
    if m == 1:
        return 1.0 / S
    if m == 2:
        a, b, c, d = S[..., 0, 0], S[..., 0, 1], S[..., 1, 0], S[..., 1, 1]
        det = a * d - b * c
        out = np.empty(S.shape, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            out[..., 0, 0] = d / det
            out[..., 0, 1] = -b / det
            out[..., 1, 0] = -c / det
            out[..., 1, 1] = a / det
        return _fix_lost_precision(S, det, out)
    if m == 3:
        a = S
        c00 = a[..., 1, 1] * a[..., 2, 2] - a[..., 1, 2] * a[..., 2, 1]
        c01 = a[..., 1, 2] * a[..., 2, 0] - a[..., 1, 0] * a[..., 2, 2]
        c02 = a[..., 1, 0] * a[..., 2, 1] - a[..., 1, 1] * a[..., 2, 0]
        det = a[..., 0, 0] * c00 + a[..., 0, 1] * c01 + a[..., 0, 2] * c02
        out = np.empty(S.shape, dtype=float)
        with np.errstate(divide="ignore", invalid="ignore"):
            out[..., 0, 0] = c00 / det
            out[..., 1, 0] = c01 / det
            out[..., 2, 0] = c02 / det
            out[..., 0, 1] = (a[..., 0, 2] * a[..., 2, 1] - a[..., 0, 1] * a[..., 2, 2]) / det
            out[..., 1, 1] = (a[..., 0, 0] * a[..., 2, 2] - a[..., 0, 2] * a[..., 2, 0]) / det
            out[..., 2, 1] = (a[..., 0, 1] * a[..., 2, 0] - a[..., 0, 0] * a[..., 2, 1]) / det
            out[..., 0, 2] = (a[..., 0, 1] * a[..., 1, 2] - a[..., 0, 2] * a[..., 1, 1]) / det
            out[..., 1, 2] = (a[..., 0, 2] * a[..., 1, 0] - a[..., 0, 0] * a[..., 1, 2]) / det
            out[..., 2, 2] = (a[..., 0, 0] * a[..., 1, 1] - a[..., 0, 1] * a[..., 1, 0]) / det
        return _fix_lost_precision(S, det, out)
    try:
        return np.linalg.inv(S)
    except np.linalg.LinAlgError:
        pass
    flat = S.reshape(-1, m, m)
    bad = np.linalg.slogdet(flat)[0] == 0  # the zero pivot LAPACK's inverse refused
    out = np.empty(flat.shape, dtype=float)
    out[~bad] = np.linalg.inv(flat[~bad])
    out[bad] = _pinv_finite(flat[bad])
    return out.reshape(S.shape)


def _pinv_finite(S: np.ndarray) -> np.ndarray:
    """Pseudo-inverse of symmetric matrices; NaN for one with a non-finite entry.

    An overflowed covariance (inf, or inf − inf = NaN) has no inverse, and
    LAPACK's eigensolver raises on it ("Eigenvalues did not converge"): its
    run gets NaN instead, a non-finite estimate that the divergence test flags.
    """
    out = np.full(S.shape, np.nan)
    finite = np.isfinite(S).all(axis=(-2, -1))
    if finite.any():
        out[finite] = np.linalg.pinv(symmetrize(S[finite]), hermitian=True)
    return out


# The cofactor determinant of an SPD matrix has a relative error of about
# eps * prod(diag) / det; below this ratio the closed forms hand over to LAPACK.
_CLOSED_FORM_MIN_RATIO = 1e-6


def _imprecise(S: np.ndarray, det: np.ndarray) -> np.ndarray:
    """True where a closed-form determinant (or inverse) of S cannot be trusted."""
    scale = np.prod(np.diagonal(S, axis1=-2, axis2=-1), axis=-1)
    return ~(det > _CLOSED_FORM_MIN_RATIO * scale)


def _fix_lost_precision(S: np.ndarray, det: np.ndarray, out: np.ndarray) -> np.ndarray:
    """Re-invert, by eigendecomposition, the matrices whose closed form lost precision."""
    bad = _imprecise(S, det)
    if np.any(bad):
        out[bad] = _pinv_finite(S[bad])
    return out


def logdet_spd(S: np.ndarray) -> np.ndarray:
    """Log-determinant of a stack of symmetric positive-definite matrices.

    Closed forms for sizes 1 to 3; where a closed-form determinant cannot be
    trusted (tiny against the product of the diagonal), LAPACK's ``slogdet``
    decides (NaN if the matrix is really not positive definite).
    """
    m = S.shape[-1]
    if m == 1:
        return np.log(S[..., 0, 0])
    if m == 2:
        det = S[..., 0, 0] * S[..., 1, 1] - S[..., 0, 1] * S[..., 1, 0]
    elif m == 3:
        a = S
        det = (
            a[..., 0, 0] * (a[..., 1, 1] * a[..., 2, 2] - a[..., 1, 2] * a[..., 2, 1])
            - a[..., 0, 1] * (a[..., 1, 0] * a[..., 2, 2] - a[..., 1, 2] * a[..., 2, 0])
            + a[..., 0, 2] * (a[..., 1, 0] * a[..., 2, 1] - a[..., 1, 1] * a[..., 2, 0])
        )
    else:
        sign, logdet = np.linalg.slogdet(S)
        return np.where(sign > 0, logdet, np.nan)
    bad = _imprecise(S, det)
    out = np.log(np.where(bad, 1.0, det))
    if np.any(bad):
        out = np.array(out)
        sign, logdet = np.linalg.slogdet(S[bad])
        out[bad] = np.where(sign > 0, logdet, np.nan)
    return out


def cholesky_psd(P: np.ndarray, jitter: float = 1e-12) -> tuple[np.ndarray, np.ndarray]:
    """Lower Cholesky factors of a stack of covariance matrices, repairing bad ones.

    Returns ``(L, repaired)`` where ``repaired`` is a boolean array over the
    batch.  A matrix that is not numerically positive definite (round-off in a
    long run, or a user's singular covariance) is replaced by its nearest
    positive-semidefinite neighbour, eigenvalues clipped at ``jitter`` times
    its largest eigenvalue, before factoring.  Matrices that factor cleanly are
    returned untouched, so the repair never changes a healthy filter.
    """
    P = symmetrize(P)
    batch = P.shape[:-2]
    try:
        return np.linalg.cholesky(P), np.zeros(batch, dtype=bool)
    except np.linalg.LinAlgError:
        pass
    flat = P.reshape(-1, *P.shape[-2:])
    L = np.empty_like(flat)
    repaired = np.zeros(flat.shape[0], dtype=bool)
    for i, Pi in enumerate(flat):  # rare recovery path only; healthy stacks never get here
        try:
            L[i] = np.linalg.cholesky(Pi)
        except np.linalg.LinAlgError:
            w, V = np.linalg.eigh(Pi)
            floor = jitter * max(float(np.max(np.abs(w))), 1.0)
            w = np.maximum(w, floor)
            L[i] = np.linalg.cholesky(symmetrize((V * w) @ V.T))
            repaired[i] = True
    return L.reshape(P.shape), repaired.reshape(batch)


def psd_factor(Q: np.ndarray, tol: float = 1e-12) -> np.ndarray:
    """A factor ``G`` with ``G @ G.T == Q`` for a possibly singular PSD matrix.

    Uses Cholesky when ``Q`` is positive definite, else an eigendecomposition
    that keeps only the directions with eigenvalue above ``tol`` times the
    largest, so a rank-deficient process noise (discrete white-noise
    acceleration) is sampled through its true rank.

    Raises
    ------
    ValueError
        If ``Q`` is not symmetric or has a clearly negative eigenvalue.
    """
    Q = np.asarray(Q, dtype=float)
    if Q.ndim != 2 or Q.shape[0] != Q.shape[1]:
        raise ValueError(f"covariance must be a square matrix, got shape {Q.shape}")
    if not np.allclose(Q, Q.T, rtol=1e-10, atol=1e-14):
        raise ValueError("covariance is not symmetric")
    try:
        return np.linalg.cholesky(Q)
    except np.linalg.LinAlgError:
        pass
    w, V = np.linalg.eigh(symmetrize(Q))
    scale = max(float(np.max(np.abs(w))), np.finfo(float).tiny)
    if np.min(w) < -1e-9 * scale:
        raise ValueError(f"covariance is not positive semidefinite (eigenvalue {np.min(w):.3g})")
    keep = w > tol * scale
    return V[:, keep] * np.sqrt(w[keep])


def numerical_jacobian(
    fun: Callable[[np.ndarray], np.ndarray],
    x: np.ndarray,
    rel_step: float = 6e-6,
    residual: Callable[[np.ndarray, np.ndarray], np.ndarray] | None = None,
) -> np.ndarray:
    """Central-difference Jacobian of a batched function.

    Parameters
    ----------
    fun
        Maps ``(*b, n) -> (*b, m)`` and must accept any leading batch axes
        (every pursuit model does).  All ``2n`` perturbed states are
        evaluated in a single call, so the cost is one model evaluation on
        a ``2n``-times larger batch.
    x
        ``(*b, n)`` points at which to differentiate.
    rel_step
        Step per component: ``rel_step * max(1, |x_j|)``.
    residual
        ``residual(a, b)``: the difference of two values of ``fun`` (a
        measurement model's ``residual``, which wraps angles).  Without it,
        ``a - b``; a bearing then jumps by 2π where the two perturbed
        values straddle the ±π cut, and the derivative is wrong by about
        π / step.

    Returns
    -------
    np.ndarray
        ``(*b, m, n)``.
    """
    x = np.asarray(x, dtype=float)
    n = x.shape[-1]
    h = rel_step * np.maximum(1.0, np.abs(x))  # (*b, n)
    eye = np.eye(n)
    steps = h[..., None, :] * eye  # (*b, n, n): row j perturbs component j
    xs = np.concatenate([x[..., None, :] + steps, x[..., None, :] - steps], axis=-2)
    fx = np.asarray(fun(xs), dtype=float)  # (*b, 2n, m)
    delta = fx[..., :n, :] - fx[..., n:, :] if residual is None else np.asarray(residual(fx[..., :n, :], fx[..., n:, :]), dtype=float)
    diff = delta / (2.0 * h[..., :, None])  # (*b, n, m)
    return np.swapaxes(diff, -1, -2)


def is_shared(A: np.ndarray, core_ndim: int) -> bool:
    """True when ``A`` is one array broadcast over its leading batch axes.

    The Kalman filter keeps a single covariance for all runs while the runs
    cannot tell their covariances apart (same prior, same missing
    measurements, data-independent fading); this detects such broadcast views
    by their zero strides.
    """
    lead = A.ndim - core_ndim
    return lead == 0 or all(s == 0 for s in A.strides[:lead])


# --------------------------------------------------------------------------
# one small matrix at a time (the step of a single run)
# --------------------------------------------------------------------------
# On one small matrix a call through numpy.linalg costs several microseconds of
# wrapper (error-state context, gufunc dispatch), more than the arithmetic.
# Used by the Gaussian filters' step of one run, never on batches.


def small_inv_logdet(S: np.ndarray) -> tuple[np.ndarray, float] | None:
    """``(S⁻¹, log det S)`` of one symmetric positive-definite matrix of size 1 to 3, or None.

    ``S`` is ``(m, m)`` or ``(1, m, m)``; the inverse has its shape.  The
    closed forms and their operation order are those of :func:`inv_spd` and
    :func:`logdet_spd` (so both agree with them bit for bit); None where those closed forms
    hand over to LAPACK (size above 3, or a determinant below
    ``_CLOSED_FORM_MIN_RATIO`` times the product of the diagonal, which also
    catches a non-positive or NaN determinant): the caller then uses
    :func:`inv_spd` and :func:`logdet_spd`.
    """
    m = S.shape[-1]
    got = small_inv_det(S.ravel().tolist(), m)
    if got is None:
        return None
    rows, det = got
    # np.log, not math.log: the bits of logdet_spd (NumPy's SIMD log may differ from libm's in the last bit)
    return np.array(rows).reshape(S.shape), float(np.log(det))


def small_inv_det(s: list[float], m: int) -> tuple[list[list[float]], float] | None:
    """S⁻¹ as rows of Python floats and the determinant of one SPD matrix of size 1 to 3 given as floats, or None.

    ``s`` holds the ``m * m`` entries of S row by row.  The closed forms of
    :func:`small_inv_logdet` (which calls this): their operation order is that
    of :func:`inv_spd` and :func:`logdet_spd`, so the inverse has their bits
    and ``np.log(det)`` is the log det; the one-run step forms S in Python
    floats and takes the log only when the log-likelihood is asked for.  None
    where those closed forms hand over to LAPACK.
    """
    if m == 1:
        a = s[0]
        if not a > 0.0:
            return None
        return [[1.0 / a]], a
    if m == 2:
        a, b, c, d = s
        det = a * d - b * c
        if not det > _CLOSED_FORM_MIN_RATIO * (a * d):
            return None
        return [[d / det, -b / det], [-c / det, a / det]], det
    if m != 3:
        return None
    a00, a01, a02, a10, a11, a12, a20, a21, a22 = s
    c00 = a11 * a22 - a12 * a21
    c01 = a12 * a20 - a10 * a22
    c02 = a10 * a21 - a11 * a20
    det = a00 * c00 + a01 * c01 + a02 * c02
    scale = _CLOSED_FORM_MIN_RATIO * (a00 * a11 * a22)
    det_log = a00 * (a11 * a22 - a12 * a21) - a01 * (a10 * a22 - a12 * a20) + a02 * (a10 * a21 - a11 * a20)
    if not (det > scale and det_log > scale):
        return None
    return [
        [c00 / det, (a02 * a21 - a01 * a22) / det, (a01 * a12 - a02 * a11) / det],
        [c01 / det, (a00 * a22 - a02 * a20) / det, (a02 * a10 - a00 * a12) / det],
        [c02 / det, (a01 * a20 - a00 * a21) / det, (a00 * a11 - a01 * a10) / det],
    ], det_log


def small_cholesky(P: np.ndarray) -> np.ndarray | None:
    """Lower Cholesky factor of one ``(n, n)`` or ``(1, n, n)`` matrix, or None where it is not positive definite.

    LAPACK's ``potrf`` called through ``scipy.linalg.lapack`` (a fraction of
    the cost of ``np.linalg.cholesky``'s wrapper on one small matrix).  Reads
    the lower triangle; None where a pivot is not positive or is NaN (where
    ``np.linalg.cholesky`` raises).
    """
    global _potrf
    if _potrf is None:
        from scipy.linalg.lapack import dpotrf as _potrf
    n = P.shape[-1]
    L, info = _potrf(P if P.ndim == 2 else P.reshape(n, n), lower=1, clean=1)
    if info != 0:
        return None
    return L if P.ndim == 2 else L.reshape(P.shape)


_potrf = None  # scipy.linalg.lapack.dpotrf, imported on first use
