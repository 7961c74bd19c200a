"""pursuit: tracking and positioning filters with a fair, fast Monte Carlo engine."""

from .engine.montecarlo import monte_carlo
from .engine.run import run
from .filters import (
    CSPF,
    ICSPF,
    SIR,
    BootstrapParticleFilter,
    Constant,
    CubatureKalmanFilter,
    CuckooSearch,
    ExponentiallyWeighted,
    ExtendedKalmanFilter,
    Improved,
    KalmanFilter,
    PartialUPF,
    StrongTracking,
    UnscentedKalmanFilter,
    rts_smooth,
)
from .gaussian import Gaussian
from .results import FilterResult, MonteCarloResult
from .rng import RunStreams
from .track import Track

__version__ = "0.1.0.dev0"


def load(folder):
    """Read an output folder written by ``pursuit run`` / ``reproduce`` back into an ExperimentOutput.

    ``load(DIR).result`` is the result object when the experiment has one;
    ``load(DIR).results`` maps every saved result's name to it.  See
    :func:`pursuit.storage.load`.
    """
    from .storage import load as _load

    return _load(folder)


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
    "load",
    "BootstrapParticleFilter",
    "SIR",
    "PartialUPF",
    "CuckooSearch",
    "CSPF",
    "ICSPF",
    "__version__",
]
