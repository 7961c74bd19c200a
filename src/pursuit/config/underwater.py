"""Registration of paper P2's underwater TOA positioning scenario."""

from __future__ import annotations

from ..registry import Param, register
from ..scenarios.underwater import CONDITIONS, MODES, STATES, UnderwaterTOA
from .scenarios import _checked


@register(
    "scenario",
    "underwater-toa",
    "Underwater TOA positioning with an L-shaped three-hydrophone array (Ma & Zheng 2022); conditions ideal, actual, abnormal",
    params=(
        Param("condition", "str", "ideal", "the paper's test condition; sets initial_error, mismatch and outlier_time", choices=tuple(CONDITIONS)),
        Param("mode", "str", "ranges", "what the filter receives: ranges (m), travel times (s) or the closed-form position fix", choices=MODES),
        Param("d", "float", 50.0, "array spacing, m: A(0,0), B(0,d), C(d,0)"),
        Param("c", "float", 1500.0, "sound speed, m/s"),
        Param("sigma_r", "float", 0.002, "range noise standard deviation, m (travel times: sigma_r / c)"),
        Param("q", "float", 1.0e-4, "process-noise variance of every state component (Q = q I)"),
        Param("state", "str", "cv", "state: cv = [x, y, vx, vy], position = [x, y] random walk", choices=STATES),
        Param("steps", "int", 60, "number of pings"),
        Param("dt", "float", 1.0, "ping interval, s"),
        Param("x0", "vector", None, "true initial state S0 (default [10, 20, 0.5, 0.4], or [10, 20])"),
        Param("P0", "matrix", None, "prior covariance (default identity)"),
        Param("initial_error", "float", None, "relative initial error e: filters start at (1 + e) S0 (default from condition)"),
        Param("mismatch", "vector", None, "[low, high] of the uniform B_k added to true positions each step (default from condition)"),
        Param("outlier_time", "float", None, "time of the one outlier, s (default from condition)"),
        Param("outlier_size", "float", 1.0, "added to every range at the outlier, m (0: no outlier)"),
    ),
)
def _underwater(where: str = "scenario", **kw) -> UnderwaterTOA:
    return _checked(where, lambda: UnderwaterTOA(**kw))
