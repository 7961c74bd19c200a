"""Fading-strategy registrations: ``fading = {type = "...", ...}`` in a filter entry.

The constant strategies (``constant``, ``tfmkf``) are registered with the filters, which also
accept a bare number; the adaptive strategies are here.
"""

from __future__ import annotations

from ..filters.fading_adaptive import ExponentiallyWeighted, StrongTracking
from ..filters.ifmkf import SEARCHES, TESTS, UNREACHABLE, Improved
from ..registry import params_from, register

_LAM_MAX_DOC = "upper bound on the fading factor (e.g. 1e300: only the numerical ceiling)"


register(
    "fading",
    "ewfmkf",
    "Exponentially weighted adaptive fading factor (EWFMKF), the baseline of Ma & Zheng's underwater TOA paper, as we reconstructed it",
    params=params_from(
        ExponentiallyWeighted, docs={"b": "forgetting factor in (0, 1); larger remembers longer", "lam_max": _LAM_MAX_DOC}
    ),
    aliases=("exponentially-weighted",),
)(ExponentiallyWeighted)


register(
    "fading",
    "stf",
    "Strong tracking suboptimal fading factor (Zhou Donghua)",
    params=params_from(
        StrongTracking,
        docs={"rho": "forgetting factor in (0, 1]", "beta": "weakening factor on R, at least 1", "lam_max": _LAM_MAX_DOC},
    ),
    aliases=("strong-tracking",),
)(StrongTracking)


register(
    "fading",
    "ifmkf",
    "Improved fading memory (IFMKF; Ma & Zheng, \"Improvement of memory fading filter applied in the underwater acoustic location algorithm\"): fade only on abnormal divergence, just enough to fit the observation",
    params=params_from(
        Improved,
        choices={"test": TESTS, "search": SEARCHES, "unreachable": UNREACHABLE},
        docs={
            "beta": "reserve coefficient of the divergence threshold beta*(w' + v)",
            "window": "window length L of the divergence test",
            "test": "divergence test: windowed median and slope, instantaneous, or whole-process mean",
            "hysteresis": "stay diverging while the windowed median exceeds the threshold",
            "search": "lambda when diverging: noise-consistent bisection, grid minimum, or strong tracking",
            "lam_max": "largest fading factor considered",
            "iterations": "bisection steps on log lambda",
            "grid": "log-grid points (search = minimise, and the bisection's fallback)",
            "gate": "skip the update for an isolated outlier",
            "gate_factor": "a residual above gate_factor * threshold is an outlier",
            "gate_max": "at most this many consecutive gated steps",
            "rho": "forgetting factor for search = stf",
            "unreachable": "if lam_max cannot fit the observation: the one-step innovation-matching factor, lam_max, or the grid minimiser",
        },
    ),
    aliases=("improved",),
)(Improved)
