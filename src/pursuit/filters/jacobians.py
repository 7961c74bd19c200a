"""Jacobians of the motion and measurement models: the model's own, else central differences.

Shared by the Gaussian filters, the fading strategies and the unscented
particle filter (a leaf module, so that none of them imports another for it).
"""

from __future__ import annotations

from typing import Any, Callable

import numpy as np

from .._linalg import numerical_jacobian

__all__ = ["motion_jacobian", "measurement_jacobian", "call_with_dt"]


def call_with_dt(fn: Callable[..., Any], *args: Any, dt: float | None = None) -> Any:
    """``fn(*args)``, or ``fn(*args, dt=dt)`` when a time step is given (a model without ``dt`` keeps its own)."""
    return fn(*args) if dt is None else fn(*args, dt=dt)


def motion_jacobian(motion: Any, x: np.ndarray, k: int, dt: float | None = None) -> np.ndarray:
    """∂f/∂x at ``x``: the model's own Jacobian, else central differences."""
    jac = getattr(motion, "jacobian", None)
    if jac is not None:
        return np.asarray(call_with_dt(jac, x, k, dt=dt), dtype=float)
    return numerical_jacobian(lambda xs: call_with_dt(motion.f, xs, k, dt=dt), x)


def measurement_jacobian(measurement: Any, x: np.ndarray, k: int) -> np.ndarray:
    """∂h/∂x at ``x``: the model's own Jacobian, else central differences (through its ``residual``, if any)."""
    jac = getattr(measurement, "jacobian", None)
    if jac is not None:
        return np.asarray(jac(x, k), dtype=float)
    return numerical_jacobian(lambda xs: measurement.h(xs, k), x, residual=getattr(measurement, "residual", None))
