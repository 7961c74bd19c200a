"""What a scenario is: a seeded simulator of truth and measurements.

A scenario is any object with

* ``name``, ``steps`` (K), ``dt``;
* ``state_labels``: one label per state component (``("x", "vx", ...)``);
* ``position_indices`` and ``velocity_indices`` (either may be empty);
* optionally ``state_units``: the unit of each component (``("m", "m/s", ...)``,
  ``""`` for a dimensionless one), shown on figure axes; without it the axes
  show no units (they are not guessed);
* ``motion`` and ``measurement``: the models a matched filter should use;
* ``simulate(rng, runs) -> Simulation``.

Scenarios know nothing of filters.  ``simulate`` must draw all of run i's
randomness from row i of ``rng`` when ``rng`` is a :class:`pursuit.RunStreams`,
so that a run's truth and measurements do not depend on how runs are
chunked.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._validation import positive_int
from ..gaussian import Gaussian
from ..rng import RunStreams, as_rng

__all__ = ["Simulation", "simulate_markov", "resolve_runs"]


@dataclass(frozen=True)
class Simulation:
    """Truth and measurements for a batch of runs.

    Attributes
    ----------
    truth
        ``(K, M, n)`` true states at steps 1..K.
    measurements
        ``(K, M, m)`` measurements; NaN = missing.
    prior
        The filters' prior: a :class:`pursuit.Gaussian` whose mean may be
        ``(M, n)`` (one initial estimate per run).
    times
        ``(K,)`` measurement times in seconds.
    extra
        Scenario-specific arrays (for figures), keyed by name.
    """

    truth: np.ndarray
    measurements: np.ndarray
    prior: Gaussian
    times: np.ndarray
    extra: dict[str, np.ndarray] = field(default_factory=dict)

    @property
    def runs(self) -> int:
        """Number of runs M."""
        return self.truth.shape[1]


def simulate_markov(
    motion: Any, measurement: Any, x0: np.ndarray, steps: int, rng: np.random.Generator | RunStreams
) -> tuple[np.ndarray, np.ndarray]:
    """Roll a Markov model forward: truth ``(K, *b, n)`` and measurements ``(K, *b, m)``.

    Draw order per run and step: process noise, then measurement noise.

    Parameters
    ----------
    motion
        A motion model with ``sample(x, k, rng)`` (the next state, drawn).
    measurement
        A measurement model with ``sample(x, k, rng)`` (a noisy measurement).
    x0
        ``(*b, n)`` initial states (step 0; not part of the output).
    steps
        Number of steps K; the steps are numbered ``k = 1 .. K``.
    rng
        A Generator, or :class:`pursuit.RunStreams` with one stream per
        entry of the leading batch axis (then run i's draws come from its
        own stream).

    Returns
    -------
    truth, measurements
        ``(K, *b, n)`` states and ``(K, *b, m)`` measurements at steps 1..K.

    Raises
    ------
    ValueError
        If ``steps`` is not a positive integer.
    """
    steps = positive_int("steps", steps)
    x = np.asarray(x0, dtype=float)
    truth = np.empty((steps, *x.shape))
    zs = None
    for i in range(steps):
        k = i + 1
        x = motion.sample(x, k, rng)
        z = measurement.sample(x, k, rng)
        if zs is None:
            zs = np.empty((steps, *z.shape))
        truth[i] = x
        zs[i] = z
    return truth, zs


def resolve_runs(rng, runs: int | None):
    """``(rng, runs)`` for a scenario's ``simulate``: ``runs`` defaults to the number of streams.

    Raises ``ValueError`` naming ``runs`` when it is missing with a single
    Generator or is not a positive integer.
    """
    rng = as_rng(rng)
    if runs is None:
        if not isinstance(rng, RunStreams):
            raise ValueError("runs: required when rng is a single Generator")
        runs = len(rng)
    return rng, positive_int("runs", runs)
