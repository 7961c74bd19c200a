"""Global nearest neighbour (GNN) tracker: one best assignment of detections to tracks per scan.

Per run and scan, GNN picks the one-to-one assignment of gated detections
to tracks that maximises the joint log-likelihood::

    Σ_(t,r) assigned [log P_D + log N(z_r; ẑ_t, S_t)] + Σ_t missed log(1 − P_D P_G) + Σ_r unassigned log λ,

which is Σ log g_tr over the assigned pairs plus a constant
(:mod:`pursuit.multitarget.association`): a pair is worth taking only when
g_tr > 1, i.e. the detection explains the track better than "missed and
clutter".  The problem is a 2-D assignment on the (L + D) × (D + L) matrix::

    [ −log g_tr (∞ outside the gate)   diag 0 (track t missed)     ]
    [ diag 0 (detection r is clutter)  0                            ]

solved by :func:`scipy.optimize.linear_sum_assignment`
(docs/spec/05-multi-target-pmht.md §4).  Each track then takes the
posterior of its hypothesis (or the prediction when missed) from the
hypothesis batch.

Cost: runs in which no track gates two detections and no detection is gated
by two tracks need no solver (take a pair iff g_tr > 1) and are decided
for all runs at once; the solver is called once per remaining run, a Python
loop over those runs only, each call on the gated tracks and detections of
that run (a few tens of microseconds for a handful of each).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.optimize import linear_sum_assignment

from .association import Hypotheses, select_state
from .tracking import TrackerBase

__all__ = ["GNNTracker", "gnn_assign"]


def gnn_assign(log_g: np.ndarray) -> np.ndarray:
    """The GNN assignment ``(M, L)``: 0 = missed, r + 1 = detection r.

    Parameters
    ----------
    log_g
        ``(M, L, D)`` log weights, −inf where a pair is impossible.
    """
    M, L, D = log_g.shape
    gated = np.isfinite(log_g)
    index = np.zeros((M, L), dtype=np.int64)
    simple = (gated.sum(axis=2) <= 1).all(axis=1) & (gated.sum(axis=1) <= 1).all(axis=1)  # (M,)
    take = gated & (log_g > 0.0) & simple[:, None, None]
    t_m, t_t, t_r = np.nonzero(take)
    index[t_m, t_t] = t_r + 1
    for run in np.nonzero(~simple)[0]:
        tracks = np.nonzero(gated[run].any(axis=1))[0]
        dets = np.nonzero(gated[run].any(axis=0))[0]
        nt, nd = tracks.size, dets.size
        cost = np.full((nt + nd, nd + nt), np.inf)
        cost[:nt, :nd] = -log_g[run][np.ix_(tracks, dets)]
        cost[np.arange(nt), nd + np.arange(nt)] = 0.0
        cost[nt + np.arange(nd), np.arange(nd)] = 0.0
        cost[nt:, nd:] = 0.0
        rows, cols = linear_sum_assignment(cost)
        pair = (rows < nt) & (cols < nd)
        index[run, tracks[rows[pair]]] = dets[cols[pair]] + 1
    return index


@dataclass(frozen=True)
class GNNTracker(TrackerBase):
    """Global nearest neighbour tracker with track management.

    Parameters are those of :class:`pursuit.multitarget.tracking.TrackerBase`.
    The per-track filter may be any pursuit filter whose state is a tree of
    batched arrays with ``mean`` and ``cov`` (KF, EKF, UKF, CKF, IMM).
    """

    def associate(self, hyp: Hypotheses, log_g: np.ndarray) -> tuple[Any, np.ndarray]:
        """The assigned hypothesis's posterior per track; hit = a detection was assigned."""
        index = gnn_assign(log_g)
        if hyp.states is None:  # no detection in any run
            return hyp.missed, index > 0
        position = np.take_along_axis(hyp.pair, np.maximum(index - 1, 0)[..., None], axis=2)[..., 0]
        position = np.where(index > 0, position, -1)
        return select_state(hyp.missed, hyp.states, position), index > 0
