"""Chi-square gating of outlying measurements.

A Gaussian filter's innovation ν with covariance S has NIS = νᵀ S⁻¹ ν ~ χ²(dof)
when the model is right.  A gate with probability ``p`` rejects a measurement
whose NIS exceeds the χ²(dof) quantile ``p``: a correct measurement is
rejected with probability ``1 − p``, while a gross outlier is almost always
rejected.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np

__all__ = ["chi2_gate_thresholds"]


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
