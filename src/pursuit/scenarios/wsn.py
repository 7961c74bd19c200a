"""WSN range-only tracking: a 2-D constant-velocity target ranged by fixed anchors."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from .._validation import as_covariance, as_matrix, as_vector, positive, positive_int
from ..gaussian import Gaussian
from ..models.measurement import RangeSensors
from ..models.motion import ConstantVelocity
from ..rng import RNGLike, RunStreams, as_rng
from .base import Simulation, simulate_markov

__all__ = ["WSNRange"]

_DEFAULT_ANCHORS = ((0.0, 0.0), (100.0, 0.0), (0.0, 100.0), (100.0, 100.0))


def _number(name: str, v: object) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise ValueError(f"{name}: expected a number, got {v!r}")
    return float(v)


@dataclass(frozen=True, eq=False)
class WSNRange:
    """A constant-velocity target in a wireless sensor network, ranged by anchors.

    State ``[x, vx, y, vy]`` (m, m/s).  Each step every anchor (node) within
    ``sensing_radius`` of the target detects it with probability
    ``p_detect`` and measures its range with Gaussian noise; the range of a
    node that does not detect the target is NaN in the measurement vector
    (a missing component, which every filter leaves out of its update).
    The defaults (infinite radius, ``p_detect = 1``) let every anchor
    measure at every step.

    Parameters
    ----------
    anchors
        ``(s, 2)`` anchor positions in metres (default: the corners of a
        100 m square).
    sigma
        Range noise standard deviation, m.
    steps
        Number of measurement steps K.
    dt
        Sampling interval, s.
    q
        Acceleration noise variance, (m/s²)² (discrete white-noise
        acceleration).
    x0
        True initial state at time 0.
    P0
        Prior covariance.
    prior_mean
        ``"sampled"`` (default): each run's initial estimate is drawn from
        N(x0, P0), so the prior is consistent with the truth;
        ``"truth"``: every run starts at x0 (the convention of paper P1).
    noise
        ``"discrete"`` or ``"continuous"`` white-noise acceleration.
    sensing_radius
        A node measures only when the true target lies within this range of
        it, m (default ``inf``: always).  The filters are not told why a
        range is missing: they treat it as missing at random and do not use
        the negative information "out of range".
    p_detect
        Probability that a node within range detects the target at a step,
        in (0, 1] (default 1).
    """

    anchors: np.ndarray = field(default_factory=lambda: np.array(_DEFAULT_ANCHORS))
    sigma: float = 1.0
    steps: int = 100
    dt: float = 1.0
    q: float = 0.01
    x0: np.ndarray = field(default_factory=lambda: np.array([10.0, 0.5, 40.0, 0.8]))
    P0: np.ndarray = field(default_factory=lambda: np.diag([4.0, 0.25, 4.0, 0.25]))
    prior_mean: Literal["sampled", "truth"] = "sampled"
    noise: Literal["discrete", "continuous"] = "discrete"
    sensing_radius: float = math.inf
    p_detect: float = 1.0
    name: str = "wsn-range"

    def __post_init__(self) -> None:
        object.__setattr__(self, "anchors", as_matrix("anchors", np.atleast_2d(self.anchors), (None, 2)))
        object.__setattr__(self, "sigma", positive("sigma", self.sigma))
        object.__setattr__(self, "steps", positive_int("steps", self.steps))
        object.__setattr__(self, "dt", positive("dt", self.dt))
        object.__setattr__(self, "q", positive("q", self.q))
        object.__setattr__(self, "x0", as_vector("x0", self.x0, 4))
        object.__setattr__(self, "P0", as_covariance("P0", self.P0, 4))
        if self.prior_mean not in ("sampled", "truth"):
            raise ValueError(f"prior_mean: must be 'sampled' or 'truth', got {self.prior_mean!r}")
        radius = _number("sensing_radius", self.sensing_radius)
        if not radius > 0:  # also rejects NaN; inf is allowed
            raise ValueError(f"sensing_radius: must be positive (inf: no limit), got {self.sensing_radius!r}")
        object.__setattr__(self, "sensing_radius", radius)
        p_detect = _number("p_detect", self.p_detect)
        if not 0.0 < p_detect <= 1.0:
            raise ValueError(f"p_detect: must lie in (0, 1], got {self.p_detect!r}")
        object.__setattr__(self, "p_detect", p_detect)
        # Build the models now so that a bad parameter fails at construction.
        object.__setattr__(self, "_motion", ConstantVelocity(ndim=2, dt=self.dt, q=self.q, noise=self.noise))
        object.__setattr__(self, "_measurement", RangeSensors(self.anchors, self.sigma, (0, 2)))

    state_labels = ("x", "vx", "y", "vy")
    state_units = ("m", "m/s", "m", "m/s")
    position_indices = (0, 2)
    velocity_indices = (1, 3)

    @property
    def motion(self) -> ConstantVelocity:
        """The true (and matched) motion model."""
        return self._motion

    @property
    def measurement(self) -> RangeSensors:
        """The true (and matched) measurement model."""
        return self._measurement

    def simulate(self, rng: RNGLike, runs: int | None = None) -> Simulation:
        """Truth and range measurements for ``runs`` runs.

        With :class:`pursuit.RunStreams`, ``runs`` defaults to its length and
        run i draws only from stream i: first its prior perturbation, then
        per step the process noise and the range noise, and last, only when
        ``p_detect < 1``, one uniform per step and node (step-major: all
        nodes of step 1, then step 2, ...) deciding the detections.  So the
        truth and the measured ranges do not depend on ``sensing_radius`` or
        ``p_detect``; those only blank ranges to NaN, and with the defaults
        the output is that of a scenario without them, bit for bit.
        """
        rng = as_rng(rng)
        if runs is None:
            if not isinstance(rng, RunStreams):
                raise ValueError("runs: required when rng is a single Generator")
            runs = len(rng)
        runs = positive_int("runs", runs)
        offset = rng.standard_normal((runs, 4))
        L = np.linalg.cholesky(self.P0)
        if self.prior_mean == "sampled":
            mean = self.x0 + np.einsum("ij,mj->mi", L, offset)
        else:
            mean = np.broadcast_to(self.x0, (runs, 4)).copy()
        x0 = np.broadcast_to(self.x0, (runs, 4))
        truth, zs = simulate_markov(self.motion, self.measurement, x0, self.steps, rng)
        zs = self._detections(truth, zs, rng, runs)
        times = self.dt * np.arange(1, self.steps + 1)
        return Simulation(truth=truth, measurements=zs, prior=Gaussian(mean, self.P0), times=times)

    def _detections(self, truth: np.ndarray, zs: np.ndarray, rng, runs: int) -> np.ndarray:
        """``zs`` with the ranges of nodes that miss the target set to NaN."""
        missed = np.zeros(zs.shape, dtype=bool)
        if self.p_detect < 1.0:
            u = rng.random((runs, self.steps, self.measurement.dim))  # run-major: row i from run i's stream
            missed |= np.moveaxis(u, 0, 1) >= self.p_detect
        if math.isfinite(self.sensing_radius):
            missed |= self.measurement.h(truth) > self.sensing_radius
        if not missed.any():
            return zs
        return np.where(missed, np.nan, zs)
