"""Bearing sensors, and several sensor models stacked into one measurement.

A recorded data set usually mixes sensors: ranges from some anchors, bearings
from others, a position fix now and then.  :class:`StackedMeasurement` joins
any measurement models into one whose measurement vector is the
concatenation of theirs, so a filter sees a single model and a sensor that
did not report at a step is simply a NaN block of z.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np
from scipy.linalg import block_diag

from .._linalg import numerical_jacobian
from .._validation import as_matrix, as_vector, positive
from ..rng import RNGLike
from .measurement import _freeze, _GaussianNoise, _positions, gaussian_loglik, wrap_angle

__all__ = ["BearingSensors", "StackedMeasurement"]


@dataclass(frozen=True, eq=False)
class BearingSensors(_GaussianNoise):
    """Bearings from fixed 2-D sensors: z_i = atan2(y − y_i, x − x_i) + v_i.

    Bearings are in radians from the x axis; residuals are wrapped to
    [−π, π), so a measurement of 3.1 and a prediction of −3.1 differ by
    about 0.08, not 6.2.

    Parameters
    ----------
    sensors
        ``(s, 2)`` sensor positions.
    sigma
        Bearing noise standard deviation (rad), one value or one per sensor.
    position_indices
        Indices of (x, y) in the state; default ``(0, 2)``.
    """

    sensors: np.ndarray
    sigma: float | np.ndarray
    position_indices: tuple[int, ...] = (0, 2)
    R: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        sensors = np.array(self.sensors, dtype=float)
        if sensors.ndim == 1:
            sensors = sensors[None, :]
        sensors = as_matrix("sensors", sensors, (None, 2))
        idx = tuple(int(i) for i in self.position_indices)
        if len(idx) != 2:
            raise ValueError("position_indices: bearings need exactly two position components")
        sig = as_vector("sigma", self.sigma)
        if sig.shape[0] not in (1, sensors.shape[0]):
            raise ValueError(f"sigma: expected 1 or {sensors.shape[0]} values, got {sig.shape[0]}")
        for s in sig:
            positive("sigma", s)
        _freeze(self, "sensors", sensors)
        object.__setattr__(self, "position_indices", idx)
        self._set_noise(np.diag(np.broadcast_to(sig, (sensors.shape[0],)) ** 2))

    @property
    def dim(self) -> int:
        """Number of sensors."""
        return self.sensors.shape[0]

    def _deltas(self, x: np.ndarray) -> np.ndarray:
        return _positions(x, self.position_indices)[..., None, :] - self.sensors  # (*b, s, 2)

    def h(self, x: np.ndarray, k: int | None = None) -> np.ndarray:
        """Bearings from every sensor, ``(*b, s)``."""
        d = self._deltas(x)
        return np.arctan2(d[..., 1], d[..., 0])

    def residual(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """``a − b`` wrapped to [−π, π)."""
        return wrap_angle(a - b)

    def jacobian(self, x: np.ndarray, k: int | None = None) -> np.ndarray:
        """``(*b, s, n)``; zero for a target on top of a sensor."""
        d = self._deltas(x)
        r2 = d[..., 0] ** 2 + d[..., 1] ** 2
        safe = np.where(r2 > 0, r2, 1.0)
        J = np.zeros((*x.shape[:-1], self.dim, x.shape[-1]))
        ix, iy = self.position_indices
        J[..., ix] = np.where(r2 > 0, -d[..., 1] / safe, 0.0)
        J[..., iy] = np.where(r2 > 0, d[..., 0] / safe, 0.0)
        return J

    def sample(self, x: np.ndarray, k: int | None, rng: RNGLike) -> np.ndarray:
        """Noisy bearings, wrapped to [−π, π)."""
        return wrap_angle(super().sample(x, k, rng))


@dataclass(frozen=True, eq=False)
class StackedMeasurement:
    """Several measurement models read as one: z = [z_1, z_2, ...].

    Each part keeps its own ``h``, ``jacobian`` (or a numerical one),
    ``residual`` and noise; the noise covariance is block diagonal (the
    sensors' errors are independent).  NaN components of z are missing, as
    everywhere in pursuit, so a sensor that did not report is a NaN block.

    Parameters
    ----------
    parts
        The measurement models, in the order of their blocks in z.
    """

    parts: tuple[Any, ...]
    R: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        parts = tuple(self.parts)
        if not parts:
            raise ValueError("parts: need at least one measurement model")
        for i, p in enumerate(parts):
            for attr in ("h", "cov"):
                if not callable(getattr(p, attr, None)):
                    raise TypeError(f"parts[{i}]: {type(p).__name__} has no method {attr}()")
        object.__setattr__(self, "parts", parts)
        covs = [np.atleast_2d(np.asarray(p.cov(None), dtype=float)) for p in parts]
        dims = [c.shape[0] for c in covs]
        stops = np.cumsum(dims)
        object.__setattr__(self, "_slices", tuple(slice(int(b - d), int(b)) for b, d in zip(stops, dims)))
        # Pursuit's own sensor models have constant noise: skip rebuilding R each step.
        object.__setattr__(self, "_constant_noise", all(isinstance(p, _GaussianNoise) for p in parts))
        _freeze(self, "R", block_diag(*covs))
        _freeze(self, "_chol_R", np.linalg.cholesky(self.R))

    @property
    def dim(self) -> int:
        """Total measurement dimension."""
        return self.R.shape[0]

    @property
    def slices(self) -> tuple[slice, ...]:
        """Where each part's block lies in z."""
        return self._slices

    def cov(self, k: int | None = None) -> np.ndarray:
        """Block-diagonal noise covariance."""
        if k is None or self._constant_noise:
            return self.R
        return block_diag(*[np.atleast_2d(np.asarray(p.cov(k), dtype=float)) for p in self.parts])

    def h(self, x: np.ndarray, k: int | None = None) -> np.ndarray:
        """Concatenated predictions, ``(*b, m)``."""
        return np.concatenate([np.asarray(p.h(x, k), dtype=float) for p in self.parts], axis=-1)

    def jacobian(self, x: np.ndarray, k: int | None = None) -> np.ndarray:
        """Stacked Jacobians, ``(*b, m, n)``."""
        blocks = [_jacobian(p, x, k) for p in self.parts]
        batch = x.shape[:-1]
        blocks = [np.broadcast_to(b, (*batch, *b.shape[-2:])) for b in blocks]
        return np.concatenate(blocks, axis=-2)

    def residual(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """Part by part ``a − b``, each with its own wrapping."""
        a, b = np.broadcast_arrays(np.asarray(a, dtype=float), np.asarray(b, dtype=float))
        out = []
        for p, s in zip(self.parts, self._slices):
            res = getattr(p, "residual", None)
            out.append(res(a[..., s], b[..., s]) if res is not None else a[..., s] - b[..., s])
        return np.concatenate(out, axis=-1)

    def loglik(self, z: np.ndarray, x: np.ndarray, k: int | None = None) -> np.ndarray:
        """log p(z | x); NaN components are skipped (the noise is diagonal per sensor block)."""
        return gaussian_loglik(self.residual(z, self.h(x, k)), self.cov(k))

    def sample(self, x: np.ndarray, k: int | None, rng: RNGLike) -> np.ndarray:
        """Noisy measurements from every part, drawn in block order."""
        return np.concatenate([p.sample(x, k, rng) for p in self.parts], axis=-1)


def _jacobian(model: Any, x: np.ndarray, k: int | None) -> np.ndarray:
    jac = getattr(model, "jacobian", None)
    if jac is not None:
        return np.asarray(jac(x, k), dtype=float)
    return numerical_jacobian(lambda xs: model.h(xs, k), x, residual=getattr(model, "residual", None))


def stack(parts: Sequence[Any]) -> Any:
    """One part as itself, several as a :class:`StackedMeasurement`."""
    parts = tuple(parts)
    return parts[0] if len(parts) == 1 else StackedMeasurement(parts)

