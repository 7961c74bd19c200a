"""Registration of paper P2's underwater TOA positioning scenario."""

from __future__ import annotations

from ..registry import params_from, register
from ..scenarios.underwater import UnderwaterTOA
from .scenarios import _checked


@register(
    "scenario",
    "underwater-toa",
    "Underwater TOA positioning with an L-shaped three-hydrophone array (Ma & Zheng 2022); conditions ideal, actual, abnormal",
    params=params_from(
        UnderwaterTOA,
        exclude=("name",),
        types={"P0": "matrix"},
        docs={
            "condition": "the paper's test condition; sets initial_error, mismatch and outlier_time",
            "mode": "what the filter receives: ranges (m), travel times (s) or the closed-form position fix",
            "d": "array spacing, m: A(0,0), B(0,d), C(d,0)",
            "c": "sound speed, m/s",
            "sigma_r": "range noise standard deviation, m (travel times: sigma_r / c)",
            "q": "process-noise variance of every state component (Q = q I)",
            "state": "state: cv = [x, y, vx, vy], position = [x, y] random walk",
            "steps": "number of pings",
            "dt": "ping interval, s",
            "x0": "true initial state S0 (default [10, 20, 0.5, 0.4], or [10, 20])",
            "P0": "prior covariance (default identity)",
            "initial_error": "relative initial error e: filters start at (1 + e) S0 (default from condition)",
            "mismatch": "[low, high] of the uniform B_k added to true positions each step (default from condition)",
            "outlier_time": "time of the one outlier, s (default from condition)",
            "outlier_size": "added to every range at the outlier, m (0: no outlier)",
        },
    ),
    target=UnderwaterTOA,
)
def _underwater(where: str = "scenario", **kw) -> UnderwaterTOA:
    return _checked(where, lambda: UnderwaterTOA(**kw))
