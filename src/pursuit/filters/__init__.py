"""Filters: each has ``init(prior, batch, rng)`` and ``step(state, z, k) -> (state, info)``."""

from .base import CompiledPath, FilterBase
from .cs import AdaptiveCSFilter, CurrentStatisticalFilter, ModifiedSingerFilter
from .cs_nonlinear import NonlinearCSFilter
from .cuckoo import CSPF, ICSPF, CuckooParticleFilter, CuckooSearch
from .fading import Constant, Fade, FadingContext, FadingStrategy, NoFading
from .fading_adaptive import ExponentiallyWeighted, StrongTracking
from .gaussian import (
    CubatureKalmanFilter,
    ExtendedKalmanFilter,
    GaussianState,
    KalmanFilter,
    UnscentedKalmanFilter,
)
from .ifmkf import Improved
from .imm import InteractingMultipleModel, StateMap, kinematic_map
from .particle import SIR, BootstrapParticleFilter, ParticleState
from .smoother import SmoothedTrack, rts_smooth
from .upf import PartialUPF

__all__ = [
    "FilterBase",
    "CompiledPath",
    "KalmanFilter",
    "ExtendedKalmanFilter",
    "UnscentedKalmanFilter",
    "CubatureKalmanFilter",
    "GaussianState",
    "CurrentStatisticalFilter",
    "AdaptiveCSFilter",
    "ModifiedSingerFilter",
    "NonlinearCSFilter",
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
