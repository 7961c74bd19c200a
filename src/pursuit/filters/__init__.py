"""Filters: each has ``init(prior, batch, rng)`` and ``step(state, z, k) -> (state, info)``."""

from .cs import AdaptiveCSFilter, CurrentStatisticalFilter, ModifiedSingerFilter
from .fading import Constant, Fade, FadingContext, FadingStrategy, NoFading
from .fading_adaptive import ExponentiallyWeighted, StrongTracking
from .gaussian import (
    CubatureKalmanFilter,
    ExtendedKalmanFilter,
    GaussianState,
    KalmanFilter,
    UnscentedKalmanFilter,
)
from .cuckoo import CSPF, ICSPF, CuckooParticleFilter, CuckooSearch
from .particle import SIR, BootstrapParticleFilter, ParticleState
from .imm import InteractingMultipleModel, StateMap, kinematic_map
from .ifmkf import Improved
from .smoother import SmoothedTrack, rts_smooth
from .upf import PartialUPF

__all__ = [
    "KalmanFilter",
    "ExtendedKalmanFilter",
    "UnscentedKalmanFilter",
    "CubatureKalmanFilter",
    "GaussianState",
    "CurrentStatisticalFilter",
    "AdaptiveCSFilter",
    "ModifiedSingerFilter",
    "InteractingMultipleModel",
    "StateMap",
    "kinematic_map",
    "Constant",
    "NoFading",
    "ExponentiallyWeighted",
    "StrongTracking",
    "Improved",
    "Fade",
    "FadingContext",
    "FadingStrategy",
    "rts_smooth",
    "SmoothedTrack",
    "BootstrapParticleFilter",
    "SIR",
    "ParticleState",
    "PartialUPF",
    "CuckooSearch",
    "CuckooParticleFilter",
    "CSPF",
    "ICSPF",
]
