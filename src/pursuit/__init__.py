"""pursuit: tracking and positioning filters with a fair, fast Monte Carlo engine."""

from __future__ import annotations

import os
from typing import TYPE_CHECKING

from .engine.montecarlo import monte_carlo
from .engine.run import run
from .examples import examples_dir
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

if TYPE_CHECKING:
    from .experiment import ExperimentOutput


def load(folder: str | os.PathLike[str]) -> ExperimentOutput:
    """Read an output folder written by ``pursuit run`` / ``reproduce`` back.

    Parameters
    ----------
    folder
        The output folder (the one holding ``run.json``).

    Returns
    -------
    ExperimentOutput
        ``load(DIR).result`` is the result object when the experiment has
        one; ``load(DIR).results`` maps every saved result's name to it;
        ``tables``, ``figures`` (PNG paths) and ``sidecar`` hold the rest.
        See :func:`pursuit.storage.load`.

    Raises
    ------
    ValueError
        If the folder has no ``run.json`` or a file it lists is missing or
        damaged (the message names the file).
    """
    from .storage import load as _load

    return _load(folder)


__all__ = [
    "examples_dir",
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
