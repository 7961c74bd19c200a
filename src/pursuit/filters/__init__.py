"""Filters: each has ``init(prior, batch, rng)`` and ``step(state, z, k) -> (state, info)``."""

from .fading import Constant, Fade, FadingContext, FadingStrategy, NoFading
from .gaussian import (
    CubatureKalmanFilter,
    ExtendedKalmanFilter,
    GaussianState,
    KalmanFilter,
    UnscentedKalmanFilter,
)
from .smoother import SmoothedTrack, rts_smooth

__all__ = [
    "KalmanFilter",
    "ExtendedKalmanFilter",
    "UnscentedKalmanFilter",
    "CubatureKalmanFilter",
    "GaussianState",
    "Constant",
    "NoFading",
    "Fade",
    "FadingContext",
    "FadingStrategy",
    "rts_smooth",
    "SmoothedTrack",
]
