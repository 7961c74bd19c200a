"""Fading-strategy registrations: ``fading = {type = "...", ...}`` in a filter entry.

The constant strategies (``constant``, ``tfmkf``) are registered with the filters, which also
accept a bare number; the adaptive strategies are here.
"""

from __future__ import annotations

from ..filters.fading_adaptive import LAM_MAX, ExponentiallyWeighted, StrongTracking
from ..filters.ifmkf import SEARCHES, TESTS, UNREACHABLE, Improved
from ..registry import Param, register

LAM_MAX_PARAM = Param("lam_max", "float", LAM_MAX, "upper bound on the fading factor (e.g. 1e300: only the numerical ceiling)")


@register(
    "fading",
    "ewfmkf",
    "Exponentially weighted adaptive fading factor (EWFMKF), the baseline of Ma & Zheng's underwater TOA paper, as we reconstructed it",
    params=(Param("b", "float", 0.95, "forgetting factor in (0, 1); larger remembers longer"), LAM_MAX_PARAM),
    aliases=("exponentially-weighted",),
)
def _ewfmkf(**kw) -> ExponentiallyWeighted:
    return ExponentiallyWeighted(**kw)


@register(
    "fading",
    "stf",
    "Strong tracking suboptimal fading factor (Zhou Donghua)",
    params=(
        Param("rho", "float", 0.95, "forgetting factor in (0, 1]"),
        Param("beta", "float", 1.0, "weakening factor on R, at least 1"),
        LAM_MAX_PARAM,
    ),
    aliases=("strong-tracking",),
)
def _stf(**kw) -> StrongTracking:
    return StrongTracking(**kw)


@register(
    "fading",
    "ifmkf",
    "Improved fading memory (IFMKF; Ma & Zheng, \"Improvement of memory fading filter applied in the underwater acoustic location algorithm\"): fade only on abnormal divergence, just enough to fit the observation",
    params=(
        Param("beta", "float", 3.0, "reserve coefficient of the divergence threshold beta*(w' + v)"),
        Param("window", "int", 5, "window length L of the divergence test"),
        Param("test", "str", "window", "divergence test: windowed median and slope, instantaneous, or whole-process mean", choices=TESTS),
        Param("hysteresis", "bool", True, "stay diverging while the windowed median exceeds the threshold"),
        Param("search", "str", "consistent", "lambda when diverging: noise-consistent bisection, grid minimum, or strong tracking", choices=SEARCHES),
        Param("lam_max", "float", LAM_MAX, "largest fading factor considered"),
        Param("iterations", "int", 20, "bisection steps on log lambda"),
        Param("grid", "int", 200, "log-grid points (search = minimise, and the bisection's fallback)"),
        Param("gate", "bool", True, "skip the update for an isolated outlier"),
        Param("gate_factor", "float", 10.0, "a residual above gate_factor * threshold is an outlier"),
        Param("gate_max", "int", 2, "at most this many consecutive gated steps"),
        Param("rho", "float", 0.95, "forgetting factor for search = stf"),
        Param(
            "unreachable",
            "str",
            "innovation",
            "if lam_max cannot fit the observation: the one-step innovation-matching factor, lam_max, or the grid minimiser",
            choices=UNREACHABLE,
        ),
    ),
    aliases=("improved",),
)
def _ifmkf(**kw) -> Improved:
    return Improved(**kw)
