"""Joint probabilistic data association (JPDA) tracker.

Per scan, the marginal probabilities β_tr (track t took detection r) and
β_t0 (track t was missed) come from the joint association events, exact
within clusters (:func:`pursuit.multitarget.association.jpda_marginals`,
with its documented cap ``max_events``).  Each track's posterior is the
moment-matched mixture of its hypothesis posteriors (x_0, P_0 the
prediction; x_r, P_r the update with detection r)::

    x = Σ_r β_tr x_r,        P = Σ_r β_tr [P_r + (x_r − x)(x_r − x)ᵀ]      (r = 0..D)

For the Kalman filter this equals the textbook combined update with the
spread-of-means term (Bar-Shalom & Fortmann;
docs/spec/05-multi-target-pmht.md §4), and it serves the EKF, UKF and CKF
unchanged.

With an IMM as the per-track filter (IMM-JPDA) each hypothesis r carries
mode posteriors (x_jr, P_jr) with probabilities μ_jr; the joint hypothesis
(r, j) has weight β_tr μ_jr, so the new mode probability is
μ_j = Σ_r β_tr μ_jr and each mode is the moment-matched mixture of its
hypotheses with weights β_tr μ_jr / μ_j.  The combined estimate is the
mixture of the hypotheses' IMM outputs with weights β_tr, which has the same
two moments as the mixture over (r, j).  The modes must be Gaussian filters.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._linalg import symmetrize
from .._validation import positive_int
from ..filters.gaussian import GaussianState
from ..filters.imm import IMMState
from .association import MAX_EVENTS, Hypotheses, jpda_marginals
from .tracking import TrackerBase

__all__ = ["JPDATracker", "combine"]


def combine(
    missed_mean: np.ndarray,
    missed_cov: np.ndarray,
    means: np.ndarray,
    covs: np.ndarray,
    runs: np.ndarray,
    tracks: np.ndarray,
    beta: np.ndarray,
    beta0: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Moment-match each track's hypotheses: ``(mean (M, L, n), cov (M, L, n, n))``.

    Parameters
    ----------
    missed_mean, missed_cov
        ``(M, L, n)``, ``(M, L, n, n)``: the missed hypothesis (the prediction).
    means, covs
        ``(P, n)``, ``(P, n, n)``: the posterior of each (track, detection) pair.
    runs, tracks
        ``(P,)``: the track each pair belongs to.
    beta, beta0
        ``(P,)`` the pairs' probabilities, ``(M, L)`` the missed ones.
    """
    on = beta > 0.0  # pairs outside the gate add nothing (and may hold anything)
    runs, tracks, w = runs[on], tracks[on], beta[on]
    xs, Ps = means[on], covs[on]
    mean = beta0[..., None] * missed_mean
    np.add.at(mean, (runs, tracks), w[:, None] * xs)
    d0 = missed_mean - mean
    cov = beta0[..., None, None] * (missed_cov + d0[..., :, None] * d0[..., None, :])
    d = xs - mean[runs, tracks]
    np.add.at(cov, (runs, tracks), w[:, None, None] * (Ps + d[:, :, None] * d[:, None, :]))
    return mean, symmetrize(cov)


@dataclass(frozen=True)
class JPDATracker(TrackerBase):
    """JPDA tracker with track management.

    Parameters
    ----------
    filter, p_detect, clutter_density, gate, capacity, confirm, max_misses, max_speed, position, name
        As :class:`pursuit.multitarget.tracking.TrackerBase`; the filter
        is a Gaussian filter (KF, EKF, UKF, CKF) or an IMM of them.
    max_events
        Cap on the joint events enumerated in one cluster (keyword only,
        default :data:`pursuit.multitarget.association.MAX_EVENTS`); a larger
        cluster gets loopy belief propagation marginals.

    Notes
    -----
    A track counts a *hit* when its probability of detection this scan,
    1 − β_t0, is at least 1/2 (for confirmation and deletion).
    """

    max_events: int = field(default=MAX_EVENTS, kw_only=True)

    def __post_init__(self) -> None:
        positive_int("max_events", self.max_events)
        super().__post_init__()

    def associate(self, hyp: Hypotheses, log_g: np.ndarray) -> tuple[Any, np.ndarray]:
        """The moment-matched posterior per track; hit = 1 − β_t0 ≥ 1/2."""
        beta, beta0 = jpda_marginals(log_g, self.max_events)
        pair_beta = beta[hyp.runs, hyp.tracks, hyp.dets]
        missed, pairs = hyp.missed, hyp.states
        if isinstance(missed, GaussianState):
            state = _combined(missed, pairs, hyp, pair_beta, beta0)
        elif isinstance(missed, IMMState) and all(isinstance(s, GaussianState) for s in missed.modes):
            state = _combined_imm(missed, pairs, hyp, pair_beta, beta0)
        else:
            raise ValueError(f"filter: JPDA needs a Gaussian filter or an IMM of Gaussian filters, got a {type(missed).__name__}")
        return state, (1.0 - beta0) >= 0.5


def _moments(missed: Any, pairs: Any, hyp: Hypotheses, pair_beta: np.ndarray, beta0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """:func:`combine` of the ``mean``/``cov`` of a missed state ``(M, L)`` and the pair states ``(P,)``."""
    M, L = beta0.shape
    n = missed.mean.shape[-1]
    missed_cov = np.broadcast_to(missed.cov, (M, L, n, n))
    if pairs is None:
        return missed.mean, missed_cov
    P = hyp.runs.size
    means = np.broadcast_to(pairs.mean, (P, n))
    covs = np.broadcast_to(pairs.cov, (P, n, n))
    return combine(missed.mean, missed_cov, means, covs, hyp.runs, hyp.tracks, pair_beta, beta0)


def _combined(missed: GaussianState, pairs: Any, hyp: Hypotheses, pair_beta: np.ndarray, beta0: np.ndarray) -> GaussianState:
    mean, cov = _moments(missed, pairs, hyp, pair_beta, beta0)
    return GaussianState(mean=mean, cov=cov, k=missed.k, memory=missed.memory)


def _combined_imm(missed: IMMState, pairs: Any, hyp: Hypotheses, pair_beta: np.ndarray, beta0: np.ndarray) -> IMMState:
    """IMM-JPDA: each mode moment-matched over the hypotheses with weights β_tr μ_jr (see the module notes)."""
    runs, tracks = hyp.runs, hyp.tracks
    r = missed.probs.shape[-1]
    w0 = beta0[..., None] * missed.probs  # (M, L, r)
    mu = w0.copy()
    wp = None
    if pairs is not None:
        wp = pair_beta[:, None] * np.broadcast_to(pairs.probs, (runs.size, r))  # (P, r)
        np.add.at(mu, (runs, tracks), wp)
    safe = np.where(mu > 0.0, mu, 1.0)
    modes = []
    for j, mode in enumerate(missed.modes):
        b0 = np.where(mu[..., j] > 0.0, w0[..., j] / safe[..., j], 1.0)  # a mode no hypothesis holds keeps its prediction
        bp = None if wp is None else wp[:, j] / safe[runs, tracks, j]
        mode_pairs = None if pairs is None else pairs.modes[j]
        modes.append(_combined(mode, mode_pairs, hyp, bp, b0))
    mean, cov = _moments(missed, pairs, hyp, pair_beta, beta0)
    probs = mu / mu.sum(axis=-1, keepdims=True)
    return IMMState(mean, cov, missed.k, tuple(modes), probs)
