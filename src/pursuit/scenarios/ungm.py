"""The UNGM benchmark scenario (paper P1 §4.1, docs/spec/01-particle-filters.md §6; Gordon, Salmond & Smith 1993)."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from .._validation import as_float_array, positive, positive_int
from ..gaussian import Gaussian
from ..models.ungm import UNGMMeasurement, UNGMMotion
from ..rng import RNGLike
from .base import Simulation, resolve_runs, simulate_markov

__all__ = ["UNGM"]


@dataclass(frozen=True, eq=False)
class UNGM:
    """Univariate nonstationary growth model runs.

    Parameters
    ----------
    steps
        Number of measurement steps K (default 50; paper P1's figures run to
        about 50, the classic demo uses 75 or 100).
    q, r
        Process and measurement noise variances (paper P1: Q = 1; R = 1 is
        read from an OCR fragment and matches the classic demo).
    x0
        True initial state (default 0.1).
    P0
        Prior variance of the filters (default 2).
    prior_mean
        ``"truth"`` (default, the classic demo and paper P1): the filters'
        prior is N(x0, P0); ``"sampled"``: each run's prior mean is drawn
        from N(x0, P0).
    """

    steps: int = 50
    q: float = 1.0
    r: float = 1.0
    x0: float = 0.1
    P0: float = 2.0
    prior_mean: Literal["truth", "sampled"] = "truth"
    name: str = "ungm"
    motion: UNGMMotion = field(init=False, repr=False)
    measurement: UNGMMeasurement = field(init=False, repr=False)

    state_labels = ("x",)
    state_units = ("",)  # the UNGM benchmark's state is dimensionless
    position_indices: tuple[int, ...] = ()
    velocity_indices: tuple[int, ...] = ()
    dt = 1.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "steps", positive_int("steps", self.steps))
        x0 = as_float_array("x0", self.x0)
        if x0.size != 1:
            raise ValueError(f"x0: expected one number, got shape {x0.shape}")
        object.__setattr__(self, "x0", float(x0.reshape(())))
        P0 = as_float_array("P0", self.P0)
        if P0.size != 1:
            raise ValueError(f"P0: expected one variance, got shape {P0.shape}")
        object.__setattr__(self, "P0", positive("P0", float(P0.reshape(()))))
        if self.prior_mean not in ("truth", "sampled"):
            raise ValueError(f"prior_mean: must be 'truth' or 'sampled', got {self.prior_mean!r}")
        object.__setattr__(self, "motion", UNGMMotion(q=self.q))
        object.__setattr__(self, "measurement", UNGMMeasurement(r=self.r))

    def simulate(self, rng: RNGLike, runs: int | None = None) -> Simulation:
        """Truth ``(K, M, 1)`` and measurements ``(K, M, 1)``.

        Draw order per run: the prior-mean offset (drawn even when unused, so
        both settings see the same truth), then per step the process noise
        and the measurement noise.
        """
        rng, runs = resolve_runs(rng, runs)
        offset = rng.standard_normal((runs, 1))
        if self.prior_mean == "sampled":
            mean = self.x0 + np.sqrt(self.P0) * offset
        else:
            mean = np.full((runs, 1), self.x0)
        x0 = np.full((runs, 1), self.x0)
        truth, zs = simulate_markov(self.motion, self.measurement, x0, self.steps, rng)
        times = np.arange(1, self.steps + 1, dtype=float)
        return Simulation(truth=truth, measurements=zs, prior=Gaussian(mean, [[self.P0]]), times=times)
