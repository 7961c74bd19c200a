"""Bearings-only tracking from two sensors, with a measurement model written by the user.

Nothing here subclasses or registers anything in pursuit: any object with the
method names of the model protocol (``h``, ``cov``, ``sample``, optionally
``jacobian`` and ``residual``) works with every filter and with the Monte
Carlo engine.  This model gives no ``jacobian``, so the EKF falls back to
central differences.

Run it with::

    .venv/bin/python examples/bearings_only.py
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

import pursuit as pu
from pursuit.engine import monte_carlo
from pursuit.models import ConstantVelocity
from pursuit.scenarios import Simulation, simulate_markov


@dataclass(frozen=True)
class TwoBearings:
    """Bearings (rad, from the x axis) from two fixed sensors to a 2-D target [x, vx, y, vy]."""

    sensors: np.ndarray
    sigma: float
    dim: int = 2

    def h(self, x, k=None):
        dx = x[..., None, 0] - self.sensors[:, 0]
        dy = x[..., None, 2] - self.sensors[:, 1]
        return np.arctan2(dy, dx)

    def cov(self, k=None):
        return self.sigma**2 * np.eye(2)

    def residual(self, a, b):
        return (a - b + np.pi) % (2 * np.pi) - np.pi

    def sample(self, x, k, rng):
        z = self.h(x, k)
        return z + self.sigma * rng.standard_normal(z.shape)


@dataclass(frozen=True)
class BearingsScenario:
    """A target crossing between two bearing sensors; the scenario protocol by duck typing."""

    steps: int = 60
    dt: float = 1.0
    name: str = "two-bearings"
    state_labels: tuple = ("x", "vx", "y", "vy")
    state_units: tuple = ("m", "m/s", "m", "m/s")  # optional: units on the figures' axes
    position_indices: tuple = (0, 2)
    velocity_indices: tuple = (1, 3)
    motion: ConstantVelocity = field(default_factory=lambda: ConstantVelocity(ndim=2, q=0.01))
    measurement: TwoBearings = field(
        default_factory=lambda: TwoBearings(np.array([[0.0, 0.0], [200.0, 0.0]]), np.deg2rad(0.5))
    )
    x0: np.ndarray = field(default_factory=lambda: np.array([50.0, 1.5, 150.0, -0.5]))
    P0: np.ndarray = field(default_factory=lambda: np.diag([25.0, 0.25, 25.0, 0.25]))

    def simulate(self, rng, runs=None):
        runs = len(rng) if runs is None else runs
        offset = rng.standard_normal((runs, 4))
        mean = self.x0 + np.einsum("ij,mj->mi", np.linalg.cholesky(self.P0), offset)
        truth, zs = simulate_markov(self.motion, self.measurement, np.broadcast_to(self.x0, (runs, 4)), self.steps, rng)
        return Simulation(truth, zs, pu.Gaussian(mean, self.P0), self.dt * np.arange(1, self.steps + 1))


def main(runs: int = 200, seed: int = 1) -> pu.results.MonteCarloResult:
    """Compare EKF (numerical Jacobian), UKF and CKF on the user's model."""
    sc = BearingsScenario()
    filters = [cls(sc.motion, sc.measurement) for cls in (pu.ExtendedKalmanFilter, pu.UnscentedKalmanFilter, pu.CubatureKalmanFilter)]
    result = monte_carlo(sc, filters, runs=runs, seed=seed)
    for row in result.summary():
        print(f"{row['filter']:>4}: position RMSE {row['rmse_position']:.3f} m, velocity RMSE {row['rmse_velocity']:.3f} m/s, ANEES {row['anees']:.2f}")
    return result


if __name__ == "__main__":
    main()
