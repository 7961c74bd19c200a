"""The packed arguments of the compiled kernels: small named tuples of arrays and scalars (no numba import here).

A kernel takes a few of these instead of dozens of positional arguments.
numba passes a named tuple of arrays and scalars to compiled code as one
value (fields read by name, ``sensor.R``; nothing is copied), caches kernels
that take them, and builds them inside compiled code too (the sequence
kernels pack each step's slices).  The glue (:mod:`.particle`,
:mod:`.gaussian`) builds them; :mod:`.specs` builds the two model tuples
:class:`Motion` and :class:`Sensor`, which :mod:`.model_math` evaluates.

Field order is part of the compiled signature: add a field at the end and
every kernel that takes the tuple recompiles (once; the cache keys on it).
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

__all__ = [
    "Motion",
    "Sensor",
    "Prediction",
    "Draws",
    "PFOptions",
    "PFOutputs",
    "SearchArgs",
    "CuckooOptions",
    "CuckooOutputs",
    "MHOptions",
    "UPFArgs",
    "UPFOutputs",
    "SigmaPoints",
    "GaussOutputs",
    "GaussSequenceOutputs",
    "GaussUpdateOutputs",
]


# ---------------------------------------------------------------- the models
class Motion(NamedTuple):
    """A built-in motion model for one step (or, in the sequence kernels, every step stacked on a first axis).

    ``kind`` is a motion code of :mod:`.specs`; linear models use
    x_k = F x + G ξ, UNGM uses ``par = [a, b, c cos(ω (k − 1)), √Q]``
    (``F``, ``G`` 1 × 1 placeholders).
    """

    kind: int
    F: np.ndarray
    G: np.ndarray
    par: np.ndarray


class Sensor(NamedTuple):
    """A built-in measurement model (see :class:`.specs.MeasurementSpec` for the meaning of each field)."""

    kind: int
    A: np.ndarray
    idx: np.ndarray
    scale: float
    R: np.ndarray
    angle: bool


class Prediction(NamedTuple):
    """The Kalman filters' linear prediction ``P⁻ = λ F P Fᵀ + Q``."""

    F: np.ndarray
    Q: np.ndarray
    lam: float


# ---------------------------------------------------------- particle filters
class Draws(NamedTuple):
    """Where a run's random numbers come from.

    ``addrs`` are the runs' PCG64 state addresses (:mod:`.streams`) when
    ``per_run``; otherwise the caller drew them with NumPy into the kernel's
    noise buffers.
    """

    addrs: np.ndarray
    per_run: bool


class PFOptions(NamedTuple):
    """Resampling: the resampler code (``common.R_*``) and the ESS threshold (−1: every step)."""

    resampler: int
    threshold: float


class PFOutputs(NamedTuple):
    """What a particle-filter step writes, one row per run (the sequence kernel packs step k's slices)."""

    particles: np.ndarray  # (B, N, n)
    logw: np.ndarray  # (B, N)
    mean: np.ndarray  # (B, n)
    cov: np.ndarray  # (B, n, n)
    innov: np.ndarray  # (B, m)
    S: np.ndarray  # (B, m, m)
    nis: np.ndarray  # (B,)
    dof: np.ndarray  # (B,) int64
    loglik: np.ndarray  # (B,)
    reset: np.ndarray  # (B,) bool
    ess: np.ndarray  # (B,)
    need: np.ndarray  # (B,) bool: resampled


class SearchArgs(NamedTuple):
    """The cuckoo search of :class:`pursuit.filters.cuckoo.CuckooSearch` as numbers (codes in :mod:`.cuckoo_kernels`)."""

    n_iter: int
    alphas: np.ndarray  # α of each iteration
    pas: np.ndarray  # discovery probability of each iteration
    alpha_min: float
    alpha_max: float
    trend: int
    kappa: float
    beta: float
    sigma_u: float
    scaling: int
    yang: bool
    log_stop: float
    use_stop: bool
    lower: np.ndarray  # (n,)
    upper: np.ndarray  # (n,)


class CuckooOptions(NamedTuple):
    """The CS-PF / ICS-PF step's switches."""

    state_uniform: bool
    sequential: bool
    include_const: bool
    best_estimate: bool
    resampler: int
    threshold: float


class CuckooOutputs(NamedTuple):
    """A cuckoo step's outputs: the particle filter's and the search's statistics."""

    pf: PFOutputs
    fitness_best: np.ndarray  # (B,)
    iterations: np.ndarray  # (B,) int64
    accepted: np.ndarray  # (B,) int64


class MHOptions(NamedTuple):
    """The switches of a CS-PF / ICS-PF step with ``acceptance="mh"``."""

    include_const: bool  # every run's fitness carries the normalising constant (angle models; else runs with a missing component)
    weighted_estimate: bool  # estimate="weighted": the weighted moments before resampling
    resampler: int


class UPFArgs(NamedTuple):
    """The partial UPF's step (:mod:`.upf_kernels`): the UKF group, the unscented transform and the transition density."""

    n_u: int  # particles with a UKF proposal
    select: int  # SELECT_* code of upf_kernels
    uniform: bool  # every previous weight is exactly 1/N (the state's flag)
    cov_mode: int  # COV_* code of upf_kernels
    cscale: float  # sigma points x ± cscale · columns of chol P, the centre first
    wm: np.ndarray  # (2n + 1,)
    wc: np.ndarray  # (2n + 1,)
    Q: np.ndarray  # (n, n) process noise of the filter's full-rank model
    Q_inv_chol: np.ndarray  # (n, n) inverse of chol Q (the transition density)
    Q_logdiag: float  # Σ log diag chol Q
    R_chol: np.ndarray  # (m, m) chol R, for the Gram form of the Joseph update
    gram: bool  # whether the Gram form applies (wc ≥ 0 and R factors)
    P0: np.ndarray  # (B, n, n) the prior covariance of each run (cov_mode "reset")


class UPFOutputs(NamedTuple):
    """What a partial-UPF step writes besides its :class:`PFOutputs`: the per-particle covariances and the repair flags."""

    particle_cov: np.ndarray  # (B, N, n·n)
    repaired: np.ndarray  # (B,) bool


# ---------------------------------------------------------- Gaussian filters
class SigmaPoints(NamedTuple):
    """Points x ± ``cscale`` · columns of chol P (the centre first if ``centre``) and their weights."""

    cscale: float
    wm: np.ndarray
    wc: np.ndarray
    centre: bool


class GaussOutputs(NamedTuple):
    """What a Kalman-family step writes, lane-major (last axis the run)."""

    x: np.ndarray  # (n, M)
    P: np.ndarray  # (n, n, M)
    xp: np.ndarray  # (n, M)
    Pp: np.ndarray  # (n, n, M)
    cross: np.ndarray  # (n, n, M)
    innov: np.ndarray  # (m, M)
    S: np.ndarray  # (m, m, M)
    nis: np.ndarray  # (M,)
    dof: np.ndarray  # (M,) int64
    loglik: np.ndarray  # (M,)
    ok: np.ndarray  # (M,) bool


class GaussSequenceOutputs(NamedTuple):
    """What the whole-sequence KF/EKF kernel writes, in the track's layout (time first)."""

    means: np.ndarray  # (K, M, n)
    covs: np.ndarray  # (K, M, n, n), or (1, 1, 1, 1) without keep_cov
    innov: np.ndarray  # (K, M, m)
    S: np.ndarray  # (K, M, m, m)
    nis: np.ndarray  # (K, M)
    dof: np.ndarray  # (K, M) int64
    loglik: np.ndarray  # (K, M)
    ok: np.ndarray  # (M,) bool


class GaussUpdateOutputs(NamedTuple):
    """What the measurement update alone writes (:func:`.gauss_kernels.correct_serial`), lane-major."""

    x: np.ndarray  # (n, M)
    P: np.ndarray  # (n, n, M)
    innov: np.ndarray  # (m, M)
    S: np.ndarray  # (m, m, M)
    nis: np.ndarray  # (M,)
    dof: np.ndarray  # (M,) int64
    loglik: np.ndarray  # (M,)
    ok: np.ndarray  # (M,) bool
