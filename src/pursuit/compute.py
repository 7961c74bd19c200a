"""The compute backend of a filter: NumPy (always there) or compiled with numba (optional).

Not to be confused with the *execution* backend of the Monte Carlo engine
(:mod:`pursuit.engine.backends`: serial, local processes, Dask), which decides
*where* chunks of runs are computed.  The compute backend decides *how* one
filter step is computed:

``"numpy"``
    Vectorised NumPy over the batch of runs (and particles).  Every filter,
    every model.
``"numba"``
    Compiled loops (``pip install 'pursuit[fast]'``), for the built-in models
    only (see :func:`pursuit._compiled.specs.particle_spec` and
    :func:`~pursuit._compiled.specs.gaussian_spec`).  Same random streams as
    NumPy, estimates equal to about 1e-12 relative, still batch invariant.

A filter takes ``backend="numpy" | "numba"``; ``backend=None`` (the default)
takes the process default, which is ``"numpy"`` unless the environment
variable ``PURSUIT_COMPUTE_BACKEND`` or :func:`set_default_backend` (the
CLI's ``--compute-backend``) says otherwise.  The choice is fixed when the
filter is built, so a filter pickled to another process keeps it.

A filter asked for ``"numba"`` whose models (or options) have no compiled
path computes with NumPy and emits a :class:`CompiledBackendWarning` naming
the reason; its ``compiled`` attribute is then ``False``.  Asking for
``"numba"`` when numba is not installed raises ``ImportError``.

This module is also the one seam to the compiled side: a filter names its
compiled implementation by a string (its ``compiled_path`` class attribute,
see :class:`pursuit.filters.base.FilterBase`), and :func:`compiled_implementation`
loads it with :mod:`importlib` on first use, so nothing imports
:mod:`pursuit._compiled` (or numba) until a filter computes with it, and the
compiled side may import the filters without an import cycle.
"""

from __future__ import annotations

import importlib
import importlib.util
import os
import warnings
from functools import lru_cache
from typing import Any

__all__ = [
    "BACKENDS",
    "CompiledBackendWarning",
    "default_backend",
    "set_default_backend",
    "numba_available",
    "resolve_backend",
    "compiled_specs",
    "compiled_implementation",
]

_COMPILED_PACKAGE = "pursuit._compiled"

BACKENDS = ("numpy", "numba")
"""The compute backends a filter accepts."""

ENV_VAR = "PURSUIT_COMPUTE_BACKEND"

_default: str | None = None


class CompiledBackendWarning(UserWarning):
    """A filter asked for the compiled backend computes with NumPy instead (the reason is in the message)."""


def _check(name: str, where: str) -> str:
    if name not in BACKENDS:
        raise ValueError(f"{where}: must be one of {', '.join(map(repr, BACKENDS))}, got {name!r}")
    return name


def default_backend() -> str:
    """The backend a filter built with ``backend=None`` gets.

    :func:`set_default_backend` if called, else the environment variable
    ``PURSUIT_COMPUTE_BACKEND``, else ``"numpy"``.
    """
    if _default is not None:
        return _default
    env = os.environ.get(ENV_VAR, "").strip()
    return _check(env, ENV_VAR) if env else "numpy"


def set_default_backend(name: str | None) -> None:
    """Set (or with ``None`` clear) the process-wide default compute backend."""
    global _default
    _default = None if name is None else _check(name, "backend")


def numba_available() -> bool:
    """Whether numba can be imported (without importing it)."""
    return importlib.util.find_spec("numba") is not None


def resolve_backend(backend: str | None) -> str:
    """The backend name a filter uses: checks it, fills in the default, and needs numba for ``"numba"``."""
    name = default_backend() if backend is None else _check(backend, "backend")
    if name == "numba" and not numba_available():
        raise ImportError("backend: 'numba' needs numba; install it with pip install 'pursuit[fast]'")
    return name


def fallback_warning(filt: object, reason: str) -> None:
    """Warn that ``filt`` computes with NumPy although the compiled backend was asked for."""
    name = getattr(filt, "name", "") or type(filt).__name__
    warnings.warn(
        f"{name}: backend 'numba' has no compiled path for {reason}; computing with NumPy",
        CompiledBackendWarning,
        stacklevel=4,
    )


def compiled_specs(
    motion: Any, measurement: Any, *, need_diagonal: bool, linear_motion: bool = False, step_sensor: bool = False
) -> tuple[Any, Any] | str:
    """The compiled form of a model pair (:func:`pursuit._compiled.specs.model_specs`), or the reason there is none.

    Imports no numba.  ``linear_motion`` also refuses a motion model that is
    not linear (the compiled Gaussian filters propagate with ``F``);
    ``motion=None`` asks for the measurement's spec alone (a filter with its
    own prediction).  ``step_sensor``: the compiled path packs the sensor per
    step, so a moving observer's is accepted.
    """
    specs_module = importlib.import_module(f"{_COMPILED_PACKAGE}.specs")
    specs = specs_module.model_specs(motion, measurement, need_diagonal=need_diagonal, step_sensor=step_sensor)
    if isinstance(specs, str):
        return specs
    if linear_motion and specs[0] is not None and specs[0].kind != specs_module.LINEAR:
        return f"motion model {type(motion).__name__} in a Gaussian filter (compiled: linear motion)"
    return specs


@lru_cache(maxsize=None)
def compiled_implementation(path: str) -> Any:
    """The compiled implementation named ``"module:attribute"`` inside :mod:`pursuit._compiled` (imports numba).

    For example ``"gaussian:EKF"`` is ``pursuit._compiled.gaussian.EKF``, a
    :class:`pursuit.filters.base.CompiledPath`.
    """
    module, _, attribute = path.partition(":")
    return getattr(importlib.import_module(f"{_COMPILED_PACKAGE}.{module}"), attribute)
