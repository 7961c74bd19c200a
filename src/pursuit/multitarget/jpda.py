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
unchanged.  The IMM is refused: its mode probabilities would need a
per-mode combination (IMM-JPDA), which this tracker does not do; use the
GNN tracker with an IMM.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._linalg import symmetrize
from .._validation import positive_int
from ..filters.gaussian import GaussianState
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
        must be a Gaussian filter (KF, EKF, UKF, CKF), not an IMM.
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
        if hasattr(self.filter, "filters") and hasattr(self.filter, "transition"):
            raise ValueError("filter: JPDA combines Gaussian hypotheses per track; the IMM needs IMM-JPDA, not built (use GNNTracker)")
        positive_int("max_events", self.max_events)
        super().__post_init__()

    def associate(self, hyp: Hypotheses, log_g: np.ndarray) -> tuple[Any, np.ndarray]:
        """The moment-matched posterior per track; hit = 1 − β_t0 ≥ 1/2."""
        if not isinstance(hyp.missed, GaussianState):
            raise ValueError(f"filter: JPDA needs a Gaussian filter's state, got {type(hyp.missed).__name__}")
        beta, beta0 = jpda_marginals(log_g, self.max_events)
        M, L, _ = beta.shape
        n = hyp.missed.mean.shape[-1]
        missed_cov = np.broadcast_to(hyp.missed.cov, (M, L, n, n))
        if hyp.states is None:
            mean, cov = hyp.missed.mean, missed_cov
        else:
            P = hyp.runs.size
            mean, cov = combine(
                hyp.missed.mean,
                missed_cov,
                np.broadcast_to(hyp.states.mean, (P, n)),
                np.broadcast_to(hyp.states.cov, (P, n, n)),
                hyp.runs,
                hyp.tracks,
                beta[hyp.runs, hyp.tracks, hyp.dets],
                beta0,
            )
        state = GaussianState(mean=mean, cov=cov, k=hyp.missed.k, memory=hyp.missed.memory)
        return state, (1.0 - beta0) >= 0.5
