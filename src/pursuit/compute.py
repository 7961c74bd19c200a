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
"""

from __future__ import annotations

import importlib.util
import os
import warnings

__all__ = [
    "BACKENDS",
    "CompiledBackendWarning",
    "default_backend",
    "set_default_backend",
    "numba_available",
    "resolve_backend",
]

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
