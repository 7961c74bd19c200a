"""Chi-square quantiles without importing ``scipy.stats``.

``scipy.stats`` takes most of a second to import and ``scipy.special`` a
third of one; the filters and metrics need only two chi-square quantiles, so
``scipy.special`` is imported on first use and ``import pursuit`` stays light.
"""

from __future__ import annotations

import numpy as np

__all__ = ["chi2_ppf", "chi2_isf"]


def chi2_ppf(q, df):
    """Quantile of χ²(df) at lower-tail probability ``q`` (``scipy.stats.chi2.ppf``)."""
    from scipy import special

    return special.chdtri(np.asarray(df, dtype=float), 1.0 - np.asarray(q, dtype=float))


def chi2_isf(p, df):
    """Quantile of χ²(df) at upper-tail probability ``p`` (``scipy.stats.chi2.isf``)."""
    from scipy import special

    return special.chdtri(np.asarray(df, dtype=float), np.asarray(p, dtype=float))
