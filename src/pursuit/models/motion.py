"""Motion (process) models.

A motion model is any object with

* ``dim``: state dimension n;
* ``f(x, k, dt=None)``: noise-free transition, ``(*b, n) -> (*b, n)``;
* ``jacobian(x, k, dt=None)``: ``(*b, n, n)`` or a shared ``(n, n)``
  (optional: filters fall back to a numerical Jacobian);
* ``cov(k, dt=None)``: process-noise covariance Q, ``(n, n)``;
* ``sample(x, k, rng, dt=None)``: a draw from p(x_k | x_{k-1}).

Linear models also give ``transition_matrix(k, dt=None)``, which the plain
Kalman filter requires.  ``k`` is the index of the step being predicted
(1, 2, ...); ``dt`` overrides the model's sampling interval for irregular
time steps.  Nothing needs to subclass anything: a user's model with these
names works everywhere.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from typing import Literal

import numpy as np

from .._linalg import apply_matrix, psd_factor
from .._validation import positive, positive_int
from ..rng import RNGLike, as_rng

__all__ = ["ConstantVelocity", "ConstantAcceleration", "kinematic_matrices"]

NoiseKind = Literal["discrete", "continuous"]
Order = Literal["axis", "derivative"]


def _axis_blocks(order: int, dt: float, q: float, noise: str) -> tuple[np.ndarray, np.ndarray]:
    """Per-axis F and Q for a kinematic model of derivative order 1 (CV) or 2 (CA)."""
    if order == 1:
        F = np.array([[1.0, dt], [0.0, 1.0]])
        if noise == "discrete":  # DWNA: piecewise-constant white acceleration, Q = q G G^T
            G = np.array([dt**2 / 2, dt])
            Q = q * np.outer(G, G)
        else:  # CWNA: continuous white acceleration with spectral density q
            Q = q * np.array([[dt**3 / 3, dt**2 / 2], [dt**2 / 2, dt]])
    elif order == 2:
        F = np.array([[1.0, dt, dt**2 / 2], [0.0, 1.0, dt], [0.0, 0.0, 1.0]])
        if noise == "discrete":  # DWPA: piecewise-constant white jerk increments
            G = np.array([dt**2 / 2, dt, 1.0])
            Q = q * np.outer(G, G)
        else:
            Q = q * np.array(
                [
                    [dt**5 / 20, dt**4 / 8, dt**3 / 6],
                    [dt**4 / 8, dt**3 / 3, dt**2 / 2],
                    [dt**3 / 6, dt**2 / 2, dt],
                ]
            )
    else:  # pragma: no cover - guarded by the callers
        raise ValueError(f"unsupported derivative order {order}")
    return F, Q


@lru_cache(maxsize=256)
def kinematic_matrices(
    ndim: int, order: int, dt: float, q: float, noise: str, layout: str
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """F, Q and a noise factor G (Q = G G^T) for an ``ndim``-axis kinematic model.

    ``layout="axis"`` orders the state per axis, ``[x, vx, y, vy, ...]``;
    ``layout="derivative"`` groups by derivative, ``[x, y, ..., vx, vy, ...]``.
    The arrays are cached and read-only.
    """
    Fa, Qa = _axis_blocks(order, dt, q, noise)
    F = np.kron(np.eye(ndim), Fa)
    Q = np.kron(np.eye(ndim), Qa)
    if layout == "derivative":
        perm = _derivative_permutation(ndim, order)
        F = F[np.ix_(perm, perm)]
        Q = Q[np.ix_(perm, perm)]
    G = psd_factor(Q)
    for A in (F, Q, G):
        A.setflags(write=False)
    return F, Q, G


def _derivative_permutation(ndim: int, order: int) -> np.ndarray:
    """Map from derivative-grouped index to axis-grouped index."""
    per = order + 1
    return np.array([axis * per + d for d in range(per) for axis in range(ndim)])


@dataclass(frozen=True)
class _Kinematic:
    ndim: int = 2
    dt: float = 1.0
    q: float = 1.0
    noise: NoiseKind = "discrete"
    layout: Order = "axis"

    _order = 1

    def __post_init__(self) -> None:
        positive_int("ndim", self.ndim)
        if self.ndim > 3:
            raise ValueError(f"ndim: must be 1, 2 or 3, got {self.ndim}")
        object.__setattr__(self, "dt", positive("dt", self.dt))
        object.__setattr__(self, "q", positive("q", self.q))
        if self.noise not in ("discrete", "continuous"):
            raise ValueError(f"noise: must be 'discrete' or 'continuous', got {self.noise!r}")
        if self.layout not in ("axis", "derivative"):
            raise ValueError(f"layout: must be 'axis' or 'derivative', got {self.layout!r}")

    # -- state layout -------------------------------------------------------
    @property
    def dim(self) -> int:
        """State dimension."""
        return self.ndim * (self._order + 1)

    def _indices(self, derivative: int) -> tuple[int, ...]:
        per = self._order + 1
        if self.layout == "axis":
            return tuple(axis * per + derivative for axis in range(self.ndim))
        return tuple(derivative * self.ndim + axis for axis in range(self.ndim))

    @property
    def position_indices(self) -> tuple[int, ...]:
        """Indices of the position components in the state."""
        return self._indices(0)

    @property
    def velocity_indices(self) -> tuple[int, ...]:
        """Indices of the velocity components in the state."""
        return self._indices(1)

    # -- model functions ----------------------------------------------------
    def _matrices(self, dt: float | None):
        return kinematic_matrices(
            self.ndim, self._order, float(self.dt if dt is None else dt), self.q, self.noise, self.layout
        )

    def transition_matrix(self, k: int | None = None, dt: float | None = None) -> np.ndarray:
        """State transition matrix F, ``(n, n)``."""
        return self._matrices(dt)[0]

    def f(self, x: np.ndarray, k: int | None = None, dt: float | None = None) -> np.ndarray:
        """Noise-free transition ``F x`` for a batch of states."""
        return apply_matrix(self._matrices(dt)[0], x)

    def jacobian(self, x: np.ndarray | None = None, k: int | None = None, dt: float | None = None) -> np.ndarray:
        """Jacobian of ``f``: the shared matrix F."""
        return self._matrices(dt)[0]

    def cov(self, k: int | None = None, dt: float | None = None) -> np.ndarray:
        """Process-noise covariance Q, ``(n, n)``."""
        return self._matrices(dt)[1]

    def noise_factor(self, k: int | None = None, dt: float | None = None) -> np.ndarray:
        """G with ``G @ G.T == Q``; rank-deficient for discrete white noise."""
        return self._matrices(dt)[2]

    def sample(self, x: np.ndarray, k: int | None, rng: RNGLike, dt: float | None = None) -> np.ndarray:
        """Draw x_k ~ N(F x, Q) for a batch of states (``rng`` may be RunStreams)."""
        F, _, G = self._matrices(dt)
        xi = as_rng(rng).standard_normal((*x.shape[:-1], G.shape[1]))
        return apply_matrix(F, x) + apply_matrix(G, xi)


@dataclass(frozen=True)
class ConstantVelocity(_Kinematic):
    """Nearly constant velocity model in 1, 2 or 3 dimensions.

    Parameters
    ----------
    ndim
        Number of spatial axes (1, 2 or 3); the state has ``2*ndim`` entries.
    dt
        Sampling interval in seconds.
    q
        Acceleration noise: variance in (m/s^2)^2 for ``noise="discrete"``,
        spectral density in m^2/s^3 for ``noise="continuous"``.
    noise
        ``"discrete"`` (default): discrete white-noise acceleration,
        ``Q = q G G^T`` with ``G = [dt^2/2, dt]`` per axis (rank ``ndim``).
        ``"continuous"``: continuous white-noise acceleration,
        ``Q = q [[dt^3/3, dt^2/2], [dt^2/2, dt]]`` per axis (full rank).
    layout
        ``"axis"`` (default) orders the state ``[x, vx, y, vy, z, vz]``;
        ``"derivative"`` orders it ``[x, y, z, vx, vy, vz]``.
    """

    _order = 1


@dataclass(frozen=True)
class ConstantAcceleration(_Kinematic):
    """Nearly constant acceleration model in 1, 2 or 3 dimensions.

    The state has ``3*ndim`` entries (position, velocity, acceleration per
    axis).  ``noise="discrete"`` uses the discrete Wiener-process
    acceleration Q = q G G^T with ``G = [dt^2/2, dt, 1]`` per axis;
    ``"continuous"`` the continuous white-noise jerk model.  ``layout`` and
    ``dt`` as in :class:`ConstantVelocity`.
    """

    _order = 2

    @property
    def acceleration_indices(self) -> tuple[int, ...]:
        """Indices of the acceleration components in the state."""
        return self._indices(2)
