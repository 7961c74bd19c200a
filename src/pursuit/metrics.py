"""Error and consistency metrics over Monte Carlo runs.

Arrays are time-major: estimates and truth ``(K, M, n)``, covariances
``(K, M, n, n)``.  Definitions:

* squared error of a component group at (k, i): Σ_{j in group} (x̂_kij − x_kij)²;
* RMSE per step: sqrt( mean over runs of the squared error );
* pooled RMSE: sqrt( mean over runs *and* steps ) — papers' "cumulative" RMSE;
* per-run RMSE: sqrt( mean over steps ) per run, then averaged over runs —
  paper P1's UNGM metric;
* NEES: eᵀ P⁻¹ e, χ²(n) on a consistent filter; ANEES its average over runs;
* NIS: νᵀ S⁻¹ ν, χ²(m).

The χ² bounds for an average of M independent χ²(d) values are
``chi2.ppf([α/2, 1 − α/2], M d) / M``: exact for one step's ANEES or ANIS
over M runs, not for an average over time steps (correlated values).
"""

from __future__ import annotations

from typing import Sequence

import numpy as np

from ._chi2 import chi2_ppf

__all__ = [
    "squared_error",
    "rmse_per_step",
    "rmse_pooled",
    "rmse_per_run",
    "nees",
    "average_consistency",
    "chi2_bounds",
]


def squared_error(estimates: np.ndarray, truth: np.ndarray, indices: Sequence[int] | None = None) -> np.ndarray:
    """Summed squared error over ``indices`` (all components if None): ``(K, M)``."""
    e = np.asarray(estimates, dtype=float) - np.asarray(truth, dtype=float)
    if indices is not None:
        e = e[..., list(indices)]
    return np.einsum("...i,...i->...", e, e)


def rmse_per_step(sq_err: np.ndarray) -> np.ndarray:
    """RMSE at each step from ``(K, M)`` squared errors: ``(K,)``."""
    return np.sqrt(np.mean(sq_err, axis=1))


def rmse_pooled(sq_err: np.ndarray, steps: slice | None = None) -> float:
    """RMSE pooled over runs and steps (optionally a slice of steps)."""
    sq = sq_err if steps is None else sq_err[steps]
    return float(np.sqrt(np.mean(sq)))


def rmse_per_run(sq_err: np.ndarray) -> np.ndarray:
    """Each run's time-averaged RMSE: ``(M,)``."""
    return np.sqrt(np.mean(sq_err, axis=0))


def nees(estimates: np.ndarray, covariances: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """Normalised estimation error squared eᵀ P⁻¹ e: ``(K, M)``.

    Uses a Cholesky solve; a covariance that is not positive definite gives
    NaN for that entry rather than an exception.
    """
    e = np.asarray(estimates, dtype=float) - np.asarray(truth, dtype=float)
    P = np.asarray(covariances, dtype=float)
    # A degenerate filter (a particle filter whose weights collapsed on one particle) can
    # report a nearly singular covariance: its NEES then overflows to inf, its honest value.
    with np.errstate(over="ignore"):
        return _nees(e, P)


def _nees(e: np.ndarray, P: np.ndarray) -> np.ndarray:
    out = np.full(e.shape[:-1], np.nan)
    try:
        L = np.linalg.cholesky(P)
        y = np.linalg.solve(L, e[..., None])[..., 0]
        return np.einsum("...i,...i->...", y, y)
    except np.linalg.LinAlgError:
        flat_e = e.reshape(-1, e.shape[-1])
        flat_P = P.reshape(-1, *P.shape[-2:])
        flat = out.reshape(-1)
        for i in range(flat.size):  # rare recovery path: only when some P is not positive definite
            try:
                Li = np.linalg.cholesky(flat_P[i])
            except np.linalg.LinAlgError:
                continue
            yi = np.linalg.solve(Li, flat_e[i])
            flat[i] = yi @ yi
        return out


def average_consistency(values: np.ndarray, dof: np.ndarray | int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Average NEES or NIS over runs at each step.

    ``values`` is ``(K, M)``; NaN entries (nothing measured) are left out.
    Returns ``(average, dof_per_value, count)``, each ``(K,)``: the mean,
    the mean χ² degrees of freedom of the averaged values and how many were
    averaged, ready for :func:`chi2_bounds`.
    """
    v = np.asarray(values, dtype=float)
    d = np.broadcast_to(np.asarray(dof, dtype=float), v.shape)
    ok = np.isfinite(v)
    count = ok.sum(axis=1)
    safe = np.maximum(count, 1)
    avg = np.where(count > 0, np.where(ok, v, 0.0).sum(axis=1) / safe, np.nan)
    dof_mean = np.where(ok, d, 0.0).sum(axis=1) / safe
    return avg, dof_mean, count


def chi2_bounds(dof_per_value: float | np.ndarray, count: int | np.ndarray, level: float = 0.95) -> tuple[np.ndarray, np.ndarray]:
    """Two-sided χ² bounds for the average of ``count`` independent χ²(dof) values."""
    alpha = 1.0 - level
    total = np.asarray(dof_per_value, dtype=float) * np.asarray(count, dtype=float)
    lo = chi2_ppf(alpha / 2.0, total) / count
    hi = chi2_ppf(1.0 - alpha / 2.0, total) / count
    return lo, hi
