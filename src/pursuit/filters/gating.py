"""Chi-square gating of outlying measurements.

A Gaussian filter's innovation ν with covariance S has NIS = νᵀ S⁻¹ ν ~ χ²(dof)
when the model is right.  A gate with probability ``p`` rejects a measurement
whose NIS exceeds the χ²(dof) quantile ``p``: a correct measurement is
rejected with probability ``1 − p``, while a gross outlier is almost always
rejected.

Every filter with a ``gate`` option decides with :func:`gate_exceeded`; the
Gaussian filters (NumPy and compiled steps alike) then keep the prediction
with :func:`apply_gate`, the CS-model axis filters and the IMM keep it in
their own state layouts.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

from .._linalg import symmetrize

__all__ = ["chi2_gate_thresholds", "gate_exceeded", "keep_prediction", "apply_gate"]


@lru_cache(maxsize=64)
def chi2_gate_thresholds(gate: float, max_dof: int) -> np.ndarray:
    """NIS thresholds indexed by degrees of freedom, ``(max_dof + 1,)``.

    ``thresholds[d]`` is the χ²(d) quantile ``gate``; ``thresholds[0]`` is
    infinite (nothing measured, nothing to reject).  The array is cached and
    read-only.

    Parameters
    ----------
    gate
        Gate probability in (0, 1), e.g. 0.99.
    max_dof
        Largest number of measured components (the measurement dimension).
    """
    if not 0.0 < gate < 1.0:
        raise ValueError(f"gate: must lie in (0, 1), got {gate!r}")
    from .._chi2 import chi2_ppf

    out = np.full(max_dof + 1, np.inf)
    if max_dof > 0:
        out[1:] = chi2_ppf(gate, np.arange(1, max_dof + 1))
    out.setflags(write=False)
    return out


def gate_exceeded(gate: float, nis: np.ndarray, dof: np.ndarray, max_dof: int) -> np.ndarray:
    """True where NIS exceeds the χ²(dof) quantile ``gate``; a NaN NIS (nothing measured) is never gated.

    Parameters
    ----------
    gate
        Gate probability in (0, 1).
    nis
        Normalised innovation squared, broadcasting against ``dof``.
    dof
        Number of measured components (integer array, at most ``max_dof``).
    max_dof
        The measurement dimension.
    """
    return np.asarray(nis > chi2_gate_thresholds(gate, max_dof)[dof])


def keep_prediction(
    mask: np.ndarray, x_pred: np.ndarray, P_pred: np.ndarray, mean: np.ndarray, cov: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """The predicted mean and covariance where ``mask`` (``(*b,)``) is True, the update elsewhere.

    ``x_pred``, ``mean`` are ``(*b, n)``; ``P_pred``, ``cov`` ``(*b, n, n)``
    (or one ``(n, n)`` matrix).  The kept covariance is symmetrised like
    every updated one (F P Fᵀ is symmetric only to round-off).
    """
    if not mask.any():
        return mean, cov
    n = mean.shape[-1]
    mean = np.where(mask[..., None], x_pred, mean)
    cov = np.where(mask[..., None, None], np.broadcast_to(symmetrize(P_pred), (*mask.shape, n, n)), cov)
    return mean, cov


def apply_gate(
    gate: float, info: dict[str, np.ndarray], x_pred: np.ndarray, P_pred: np.ndarray, mean: np.ndarray, cov: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The χ² gate of a Gaussian filter's step: ``(mean, cov, gated)``.

    Keeps the prediction where the step's NIS (``info["nis"]``, with
    ``info["dof"]`` and the measurement dimension from
    ``info["innovation"]``) exceeds the χ²(dof) quantile ``gate``; see
    :func:`keep_prediction` for the shapes.
    """
    gated = gate_exceeded(gate, info["nis"], info["dof"], info["innovation"].shape[-1])
    mean, cov = keep_prediction(gated, x_pred, P_pred, mean, cov)
    return mean, cov, gated
