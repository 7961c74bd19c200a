"""A linear-Gaussian scenario: a constant-velocity target measured in position."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .._validation import as_covariance, as_vector, positive, positive_int
from ..gaussian import Gaussian
from ..models.measurement import LinearGaussian
from ..models.motion import ConstantVelocity
from ..rng import RNGLike, RunStreams, as_rng
from .base import Simulation, simulate_markov

__all__ = ["LinearCV"]


@dataclass(frozen=True, eq=False)
class LinearCV:
    """Constant-velocity target in 1-3 D with noisy position measurements.

    The model the Kalman filter is exact for: useful as a reference, for
    consistency checks (NEES/NIS inside their χ² bounds) and for speed
    benchmarks.  State per axis ``[p, v]``, layout ``[x, vx, y, vy, ...]``.

    Parameters
    ----------
    ndim
        Spatial axes (1, 2 or 3).
    dt
        Sampling interval, s.
    q
        Acceleration noise variance, (m/s²)² (discrete white noise).
    sigma
        Position measurement noise standard deviation, m.
    steps
        Number of measurement steps K.
    x0
        True initial state (default: zero position, 1 m/s on every axis).
    P0
        Prior covariance (default: identity).
    prior_mean
        ``"sampled"``: each run's initial estimate ~ N(x0, P0);
        ``"truth"``: every run starts at x0.
    """

    ndim: int = 2
    dt: float = 1.0
    q: float = 0.01
    sigma: float = 1.0
    steps: int = 100
    x0: np.ndarray | None = None
    P0: np.ndarray | None = None
    prior_mean: str = "sampled"
    name: str = "cv-position"
    motion: ConstantVelocity = field(init=False, repr=False)
    measurement: LinearGaussian = field(init=False, repr=False)

    def __post_init__(self) -> None:
        ndim = positive_int("ndim", self.ndim)
        if ndim > 3:
            raise ValueError(f"ndim: must be 1, 2 or 3, got {ndim}")
        n = 2 * ndim
        object.__setattr__(self, "dt", positive("dt", self.dt))
        object.__setattr__(self, "q", positive("q", self.q))
        object.__setattr__(self, "sigma", positive("sigma", self.sigma))
        object.__setattr__(self, "steps", positive_int("steps", self.steps))
        x0 = np.tile([0.0, 1.0], ndim) if self.x0 is None else self.x0
        object.__setattr__(self, "x0", as_vector("x0", x0, n))
        object.__setattr__(self, "P0", as_covariance("P0", np.eye(n) if self.P0 is None else self.P0, n))
        if self.prior_mean not in ("sampled", "truth"):
            raise ValueError(f"prior_mean: must be 'sampled' or 'truth', got {self.prior_mean!r}")
        motion = ConstantVelocity(ndim=ndim, dt=self.dt, q=self.q)
        object.__setattr__(self, "motion", motion)
        object.__setattr__(self, "measurement", LinearGaussian.position(n, motion.position_indices, self.sigma))

    @property
    def state_labels(self) -> tuple[str, ...]:
        """``("x", "vx", "y", "vy", ...)``."""
        axes = "xyz"[: self.ndim]
        return tuple(lbl for a in axes for lbl in (a, f"v{a}"))

    @property
    def state_units(self) -> tuple[str, ...]:
        """``("m", "m/s", ...)``: metres and metres per second on every axis."""
        return ("m", "m/s") * self.ndim

    @property
    def position_indices(self) -> tuple[int, ...]:
        """Position components."""
        return self.motion.position_indices

    @property
    def velocity_indices(self) -> tuple[int, ...]:
        """Velocity components."""
        return self.motion.velocity_indices

    def simulate(self, rng: RNGLike, runs: int | None = None) -> Simulation:
        """Truth and measurements; draw order per run: prior offset, then per step process and measurement noise."""
        rng = as_rng(rng)
        if runs is None:
            if not isinstance(rng, RunStreams):
                raise ValueError("runs: required when rng is a single Generator")
            runs = len(rng)
        runs = positive_int("runs", runs)
        n = self.x0.shape[0]
        offset = rng.standard_normal((runs, n))
        if self.prior_mean == "sampled":
            mean = self.x0 + np.einsum("ij,mj->mi", np.linalg.cholesky(self.P0), offset)
        else:
            mean = np.broadcast_to(self.x0, (runs, n)).copy()
        truth, zs = simulate_markov(self.motion, self.measurement, np.broadcast_to(self.x0, (runs, n)), self.steps, rng)
        times = self.dt * np.arange(1, self.steps + 1)
        return Simulation(truth=truth, measurements=zs, prior=Gaussian(mean, self.P0), times=times)
