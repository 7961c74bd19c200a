"""pursuit: tracking and positioning filters with a fair, fast Monte Carlo engine."""

from __future__ import annotations

import importlib
import os
from typing import TYPE_CHECKING, Any

# Public names and the modules that define them, imported on first use (PEP 562) so that
# `import pursuit` (and so `pursuit list`, `pursuit --version`) does not load NumPy, SciPy and
# every filter first: that took seconds.
_LAZY = {
    "monte_carlo": "pursuit.engine.montecarlo",
    "run": "pursuit.engine.run",
    **dict.fromkeys(
        (
            "CSPF",
            "ICSPF",
            "SIR",
            "BootstrapParticleFilter",
            "Constant",
            "CubatureKalmanFilter",
            "CuckooSearch",
            "ExponentiallyWeighted",
            "ExtendedKalmanFilter",
            "Improved",
            "KalmanFilter",
            "PartialUPF",
            "StrongTracking",
            "UnscentedKalmanFilter",
            "rts_smooth",
        ),
        "pursuit.filters",
    ),
    "Gaussian": "pursuit.gaussian",
    "FilterResult": "pursuit.results",
    "MonteCarloResult": "pursuit.results",
    "RunStreams": "pursuit.rng",
    "Track": "pursuit.track",
    "examples_dir": "pursuit.examples",
}

if TYPE_CHECKING:
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


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:  # a sub-package (pursuit.filters, pursuit.scenarios, ...), as when they were imported eagerly
        try:
            return importlib.import_module(f"{__name__}.{name}")
        except ModuleNotFoundError as e:
            if e.name != f"{__name__}.{name}":
                raise
            raise AttributeError(f"module 'pursuit' has no attribute {name!r}") from None
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # later look-ups skip this function
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_LAZY))


__version__ = "0.1.0.dev0"

if TYPE_CHECKING:
    from .tables import ExperimentOutput


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
