"""pursuit: tracking and positioning filters with a fair, fast Monte Carlo engine."""

from .engine.montecarlo import monte_carlo
from .engine.run import run
from .filters import (
    Constant,
    CubatureKalmanFilter,
    ExponentiallyWeighted,
    ExtendedKalmanFilter,
    Improved,
    KalmanFilter,
    StrongTracking,
    UnscentedKalmanFilter,
    rts_smooth,
)
from .gaussian import Gaussian
from .results import FilterResult, MonteCarloResult
from .rng import RunStreams
from .track import Track

__version__ = "0.1.0.dev0"

__all__ = [
    "Gaussian",
    "RunStreams",
    "Track",
    "run",
    "monte_carlo",
    "MonteCarloResult",
    "FilterResult",
    "KalmanFilter",
    "ExtendedKalmanFilter",
    "UnscentedKalmanFilter",
    "CubatureKalmanFilter",
    "Constant",
    "ExponentiallyWeighted",
    "StrongTracking",
    "Improved",
    "rts_smooth",
    "__version__",
]
