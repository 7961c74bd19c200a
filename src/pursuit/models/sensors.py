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

__all__ = ["BearingSensors", "ObserverBearings", "StackedMeasurement"]


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
class ObserverBearings(_GaussianNoise):
    """Angles to the target from one moving observer: azimuth (2-D) or azimuth and elevation (3-D).

    With ``d = p − o_k`` the target position minus the observer's at step k,

    * 2-D: ``z = atan2(d_y, d_x) + v`` (azimuth from the x axis);
    * 3-D: ``z = [atan2(d_y, d_x), atan2(d_z, hypot(d_x, d_y))] + v``
      (azimuth, then elevation above the x-y plane).

    The azimuth residual is wrapped to [−π, π), so a target crossing the
    ±π line (behind the observer, on the −x side) gives small residuals;
    the elevation lies in [−π/2, π/2] and its differences need no wrap (the
    same wrap leaves them unchanged).  A bearings-only target is observable
    only from a maneuvering observer, so the observer's track is part of the
    model: row ``k − 1`` of ``observer`` is its position at step ``k``
    (steps start at 1, as in :func:`pursuit.run`), or ``observer(k)`` gives it.

    Parameters
    ----------
    observer
        ``(K, d)`` observer positions, d = 2 or 3, for steps 1 … K; or a
        callable ``observer(k) -> (d,)`` for any step k ≥ 1 (a track known in
        closed form, with no length to store).
    sigma
        Angle noise standard deviation (rad): one value, or one per angle.
    position_indices
        Indices of the target position (x, y[, z]) in the state; default
        ``(0, 3[, 6])``, the ``[x, vx, ax, y, vy, ay, ...]`` layout of the
        CS-model filters.
    """

    observer: np.ndarray
    sigma: float | np.ndarray
    position_indices: tuple[int, ...] | None = None
    R: np.ndarray = field(init=False, repr=False)

    def __post_init__(self) -> None:
        if callable(self.observer):
            d = np.shape(self.observer(1))[-1] if np.ndim(self.observer(1)) == 1 else 0
            if d not in (2, 3):
                raise ValueError(f"observer: observer(k) must return a position of 2 or 3 coordinates, got {self.observer(1)!r}")
        else:
            obs = np.array(self.observer, dtype=float)
            if obs.ndim != 2 or obs.shape[1] not in (2, 3) or obs.shape[0] < 1:
                raise ValueError(f"observer: expected a (K, 2) or (K, 3) array of positions, got shape {obs.shape}")
            if not np.all(np.isfinite(obs)):
                raise ValueError("observer: positions must be finite")
            d = obs.shape[1]
        idx = tuple(3 * i for i in range(d)) if self.position_indices is None else tuple(int(i) for i in self.position_indices)
        if len(idx) != d:
            raise ValueError(f"position_indices: expected {d} indices for a {d}-D observer, got {len(idx)}")
        if any(i < 0 for i in idx) or len(set(idx)) != len(idx):
            raise ValueError(f"position_indices: expected distinct non-negative state indices, got {list(idx)}")
        m = d - 1
        sig = as_vector("sigma", self.sigma)
        if sig.shape[0] not in (1, m):
            raise ValueError(f"sigma: expected 1 or {m} values, got {sig.shape[0]}")
        for s in sig:
            positive("sigma", s)
        if not callable(self.observer):
            _freeze(self, "observer", obs)
        object.__setattr__(self, "position_indices", idx)
        self._set_noise(np.diag(np.broadcast_to(sig, (m,)) ** 2))

    @property
    def dim(self) -> int:
        """Number of angles: 1 (2-D) or 2 (3-D)."""
        return self.R.shape[0]

    @property
    def steps(self) -> int | None:
        """Number of steps the observer's track covers (None for a callable track)."""
        return None if callable(self.observer) else self.observer.shape[0]

    def observer_at(self, k: int | None) -> np.ndarray:
        """The observer's position at step ``k`` (≥ 1; at most K for a stored track), ``(d,)``."""
        if k is None:
            raise ValueError("k: the moving observer's angles need the step index")
        k = int(k)
        if k < 1 or (self.steps is not None and k > self.steps):
            raise ValueError(f"k: the observer's track covers steps 1 to {self.steps or 'any'}, got {k}")
        if callable(self.observer):
            return np.asarray(self.observer(k), dtype=float)
        return self.observer[k - 1]

    def _deltas(self, x: np.ndarray, k: int | None) -> np.ndarray:
        return _positions(x, self.position_indices) - self.observer_at(k)

    def h(self, x: np.ndarray, k: int | None = None) -> np.ndarray:
        """Azimuth (and elevation), ``(*b, dim)``."""
        d = self._deltas(x, k)
        az = np.arctan2(d[..., 1], d[..., 0])
        if self.dim == 1:
            return az[..., None]
        return np.stack([az, np.arctan2(d[..., 2], np.hypot(d[..., 0], d[..., 1]))], axis=-1)

    def residual(self, a: np.ndarray, b: np.ndarray) -> np.ndarray:
        """``a − b`` wrapped to [−π, π) (the azimuth's wrap; an elevation difference is unchanged)."""
        return wrap_angle(np.asarray(a, dtype=float) - b)

    def jacobian(self, x: np.ndarray, k: int | None = None) -> np.ndarray:
        """``(*b, dim, n)``; zero rows for a target on the observer's vertical (azimuth undefined)."""
        d = self._deltas(x, k)
        r2 = d[..., 0] ** 2 + d[..., 1] ** 2
        ok = r2 > 0
        safe = np.where(ok, r2, 1.0)
        J = np.zeros((*x.shape[:-1], self.dim, x.shape[-1]))
        ix, iy = self.position_indices[:2]
        J[..., 0, ix] = np.where(ok, -d[..., 1] / safe, 0.0)
        J[..., 0, iy] = np.where(ok, d[..., 0] / safe, 0.0)
        if self.dim == 2:
            iz = self.position_indices[2]
            rho = np.sqrt(safe)
            R2 = safe + d[..., 2] ** 2
            # d(el)/d(x, y) = −d_z d_{x,y} / (ρ R²), d(el)/dz = ρ / R²
            J[..., 1, ix] = np.where(ok, -d[..., 2] * d[..., 0] / (rho * R2), 0.0)
            J[..., 1, iy] = np.where(ok, -d[..., 2] * d[..., 1] / (rho * R2), 0.0)
            J[..., 1, iz] = np.where(ok, rho / R2, 0.0)
        return J

    def sample(self, x: np.ndarray, k: int | None, rng: RNGLike) -> np.ndarray:
        """Noisy angles; the azimuth wrapped to [−π, π)."""
        z = super().sample(x, k, rng)
        z[..., 0] = wrap_angle(z[..., 0])
        return z


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

