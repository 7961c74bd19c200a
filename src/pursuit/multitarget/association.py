"""Data association for the multi-target trackers: hypothesis evaluation, gating and JPDA marginals.

Every (track, detection) pair of a scan, for every Monte Carlo run, is one
*hypothesis*.  :func:`evaluate_hypotheses` evaluates them all with **one**
call of the per-track filter's ``step`` on the flat batch of all pairs (each
track's state repeated for each detection) and one call with all-NaN
measurements (the missed-detection hypothesis, predict only).  So any
pursuit filter (KF, EKF, UKF, CKF, IMM) gives the NIS, the log-likelihood
and each hypothesis's posterior without a line of filter-specific code here.
A Gaussian filter whose update reads the detection only through its
innovation (no gate, a constant fading factor) offers ``update_moments``:
the prediction, S, the gain and the updated covariance once per track, and
per pair only the innovation (the model's residual, so angles wrap), the
mean, NIS and log-likelihood; the pairs of a track share its covariance.
The result equals the per-pair step to round-off
(``tests/multitarget/test_association_shared.py``).

The association weight of a pair is the likelihood ratio of "detection r
comes from track t" against "track t was missed and r is clutter"
(Bar-Shalom & Fortmann; docs/spec/05-multi-target-pmht.md §4)::

    log g_tr = log P_D + log N(z_r; ẑ_t, S_t) − log(1 − P_D P_G) − log λ

with P_G the gate probability and λ the clutter density (false alarms per
unit measurement volume per scan); g_tr = 0 outside the χ² gate.  GNN
maximises Σ log g over one-to-one assignments; JPDA weighs every joint event
by Π g (:func:`jpda_marginals`).

Filter states are small dataclass trees of arrays (``GaussianState``,
``IMMState``); :func:`select_state`, :func:`gather_state`,
:func:`scatter_state` and :func:`where_state` act on every batched array of
such a tree, so the trackers select and replace whole states whatever the
filter.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Any, Callable

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from ..filters.gating import chi2_gate_thresholds
from ..filters.gaussian import GaussianState, UpdateMoments

__all__ = [
    "Hypotheses",
    "evaluate_hypotheses",
    "log_weights",
    "jpda_marginals",
    "jpda_marginals_lbp",
    "select_state",
    "gather_state",
    "scatter_state",
    "where_state",
    "MAX_EVENTS",
]

MAX_EVENTS = 20_000
"""Default cap on the joint events JPDA enumerates in one cluster (beyond it: loopy belief propagation)."""


# --------------------------------------------------------------------------
# filter states as trees of batched arrays
# --------------------------------------------------------------------------
def _map_state(fn: Callable[..., Any], nb: int, state: Any, *others: Any) -> Any:
    """Apply ``fn(leaf, *other_leaves)`` to every array of ``state`` whose first ``nb`` axes are the batch."""
    if isinstance(state, np.ndarray):
        return fn(state, *others) if state.ndim >= nb else state
    if isinstance(state, tuple):
        return tuple(_map_state(fn, nb, s, *(o[i] for o in others)) for i, s in enumerate(state))
    if dataclasses.is_dataclass(state) and not isinstance(state, type):
        changes = {}
        for f in dataclasses.fields(state):
            if not f.init:
                continue
            value = getattr(state, f.name)
            if isinstance(value, (np.ndarray, tuple)) or dataclasses.is_dataclass(value):
                changes[f.name] = _map_state(fn, nb, value, *(getattr(o, f.name) for o in others))
        return dataclasses.replace(state, **changes)
    return state  # step index, a strategy's scalar memory: shared by the whole batch


def select_state(missed: Any, pairs: Any, position: np.ndarray) -> Any:
    """Per track, the missed-detection state (``position < 0``) or the pair state at ``position``.

    ``missed`` has batch ``(M, L)``, ``pairs`` the flat batch ``(P,)`` of
    :attr:`Hypotheses.states`; ``position (M, L)`` indexes it (−1: missed).
    """
    if pairs is None or not (position >= 0).any():
        return missed
    pick = np.maximum(position, 0)
    missed_here = position < 0

    def take(a: np.ndarray, p: np.ndarray) -> np.ndarray:
        return np.where(missed_here.reshape(*missed_here.shape, *(1,) * (a.ndim - 2)), a, p[pick])

    return _map_state(take, 2, missed, pairs)


def gather_state(state: Any, runs: np.ndarray, tracks: np.ndarray) -> Any:
    """The tracks ``(runs[i], tracks[i])`` of a state of batch ``(M, L)``, as a flat batch ``(P,)``."""
    return _map_state(lambda a: a[runs, tracks], 2, state)


def scatter_state(flat: Any, state: Any, runs: np.ndarray, tracks: np.ndarray) -> Any:
    """``state`` (batch ``(M, L)``) with the tracks ``(runs[i], tracks[i])`` replaced by ``flat`` (batch ``(P,)``).

    Scalar fields (the step index) come from ``state``.
    """

    def put(full: np.ndarray, part: np.ndarray) -> np.ndarray:
        out = np.array(full)
        out[runs, tracks] = part
        return out

    return _map_state(put, 2, state, flat)


def where_state(mask: np.ndarray, a: Any, b: Any) -> Any:
    """State ``a`` where ``mask (M, L)`` is True, ``b`` elsewhere (both of batch ``(M, L)``)."""
    return _map_state(lambda x, y: np.where(mask.reshape(*mask.shape, *(1,) * (x.ndim - 2)), x, y), 2, a, b)


# --------------------------------------------------------------------------
# hypothesis evaluation
# --------------------------------------------------------------------------
@dataclass(frozen=True)
class Hypotheses:
    """Every (track, detection) hypothesis of one scan, batched over runs.

    Attributes
    ----------
    missed
        The filter state after a step without a measurement (the missed
        hypothesis), batch ``(M, L)``.
    states
        The filter state after updating with each detection, for the pairs of
        an alive track and a real detection only: flat batch ``(P,)``
        (None when there is no pair).
    pair
        ``(M, L, D)`` position of each pair in ``states``, −1 for none.
    runs, tracks, dets
        ``(P,)`` the run, track slot and detection row of each pair.
    nis, loglik
        ``(M, L, D)`` NIS and log-likelihood of each pair (NaN / 0 where
        none): log N(ν; 0, S), or for an IMM its mixture likelihood
        ``loglik_mixture``.
    detected
        ``(M, D)``: True for a real detection (not a NaN padding row).
    gated
        ``(M, L, D)``: the pair is possible: a real detection, an alive track
        and NIS within the χ² gate.
    """

    missed: Any
    states: Any
    pair: np.ndarray
    runs: np.ndarray
    tracks: np.ndarray
    dets: np.ndarray
    nis: np.ndarray
    loglik: np.ndarray
    detected: np.ndarray
    gated: np.ndarray


def evaluate_hypotheses(
    filt: Any, state: Any, z: np.ndarray, alive: np.ndarray, gate: float, k: int, dt: float | None = None
) -> Hypotheses:
    """Evaluate all hypotheses of one scan with two calls of ``filt.step``, or one prediction per track.

    The pairs of an alive track and a real detection are gathered into one
    flat batch ``(P,)`` (free slots and padding rows are skipped: with a
    capacity well above the number of tracks most of ``(M, L, D)`` is
    empty) and stepped once; the missed hypothesis is one step of the alive
    tracks with NaN measurements (a free slot keeps its state).  Where the
    filter's ``update_moments`` applies (a Gaussian filter without gate or
    adaptive fading) the alive tracks are predicted once instead, the missed
    hypothesis is that prediction, and each pair costs one innovation; the
    pair states then share their track's covariance (a read-only broadcast
    view where all tracks share one).

    Parameters
    ----------
    filt
        The per-track filter (``step(state, z, k, dt) -> (state, info)``).
    state
        Track states, batch ``(M, L)``.
    z
        ``(M, D, m)`` detections, NaN rows = padding.
    alive
        ``(M, L)`` slots holding a track.
    gate
        χ² gate probability P_G in (0, 1).
    k, dt
        Step index and time since the previous scan (None: the model's own).
    """
    M, D, m = z.shape
    L = alive.shape[1]
    detected = ~np.isnan(z).any(axis=-1)
    runs, tracks, dets = np.nonzero(alive[:, :, None] & detected[:, None, :])
    P = runs.size
    nis = np.full((M, L, D), np.nan)
    loglik = np.zeros((M, L, D))
    dof = np.zeros((M, L, D), dtype=np.int64)
    pair = np.full((M, L, D), -1, dtype=np.int64)
    pair[runs, tracks, dets] = np.arange(P)
    states = None
    fast = _shared_moments(filt, state, alive, m, k, dt)
    if fast is not None:
        # A Gaussian filter whose update sees z only through the innovation: predict and form S, K and
        # the updated covariance once per track, then per pair only the innovation, mean, NIS and loglik.
        moments, missed, where = fast
        if P:
            index = (runs, tracks) if where is None else where[runs, tracks]
            mean, nis[runs, tracks, dets], loglik[runs, tracks, dets] = moments.update(z[runs, dets], index)
            states = GaussianState(mean=mean, cov=moments.covariance(index, P), k=missed.k, memory=None)
            dof[runs, tracks, dets] = m
    else:
        missed = _predict_alive(filt, state, alive, m, k, dt)
        if P:
            states, info = filt.step(gather_state(state, runs, tracks), z[runs, dets], k=k, dt=dt)
            nis[runs, tracks, dets] = np.broadcast_to(info["nis"], (P,))
            # An IMM's exact likelihood is the mixture's, log Σ_j c̄_j Λ_j (its "loglik" is of the moment-matched Gaussian).
            loglik[runs, tracks, dets] = np.broadcast_to(info.get("loglik_mixture", info["loglik"]), (P,))
            dof[runs, tracks, dets] = np.broadcast_to(info["dof"], (P,))
    within = nis <= chi2_gate_thresholds(gate, m)[dof]  # NaN NIS (no pair) compares False
    gated = within & detected[:, None, :] & alive[:, :, None]
    return Hypotheses(missed, states, pair, runs, tracks, dets, nis, loglik, detected, gated)


def _shared_moments(
    filt: Any, state: Any, alive: np.ndarray, m: int, k: int, dt: float | None
) -> tuple[UpdateMoments, GaussianState, np.ndarray | None] | None:
    """The fast path of :func:`evaluate_hypotheses`, or None where it does not apply.

    Returns the alive tracks' :class:`UpdateMoments`, the missed hypothesis
    (the prediction; a free slot keeps its state) and the ``(M, L)`` position
    of each track in the moments' flat batch (None: the moments have batch
    ``(M, L)``, every slot alive).  None for a filter that is not a plain
    Gaussian one (IMM, CS filters, a gate, adaptive fading), when no track
    is alive, or when ``m`` is not the filter's (its ``step`` says why).
    """
    update_moments = getattr(filt, "update_moments", None)  # the Gaussian filters (KF, EKF, UKF, CKF) have it
    if update_moments is None or not isinstance(state, GaussianState) or not alive.any():
        return None
    everywhere = bool(alive.all())
    if everywhere:
        part, where = state, None
    else:
        runs, tracks = np.nonzero(alive)
        part = gather_state(state, runs, tracks)
        where = np.full(alive.shape, -1, dtype=np.int64)
        where[runs, tracks] = np.arange(runs.size)
    moments = update_moments(part, k, dt)
    if moments is None or moments.zp.shape[-1] != m:
        return None
    batch, n = part.mean.shape[:-1], part.mean.shape[-1]
    predicted = GaussianState(mean=moments.pred_mean, cov=np.broadcast_to(moments.pred_cov, (*batch, n, n)), k=int(k), memory=None)
    if everywhere:
        return moments, predicted, None
    missed = dataclasses.replace(scatter_state(predicted, state, runs, tracks), k=int(k))
    return moments, missed, where


def _predict_alive(filt: Any, state: Any, alive: np.ndarray, m: int, k: int, dt: float | None) -> Any:
    """The missed hypothesis: a step without a measurement for the alive tracks (free slots keep their state)."""
    runs, tracks = np.nonzero(alive)
    if runs.size == alive.size:
        return filt.step(state, np.full((*alive.shape, m), np.nan), k=k, dt=dt)[0]
    if runs.size == 0:
        return state
    stepped, _ = filt.step(gather_state(state, runs, tracks), np.full((runs.size, m), np.nan), k=k, dt=dt)
    return dataclasses.replace(scatter_state(stepped, state, runs, tracks), k=stepped.k)


def log_weights(hyp: Hypotheses, p_detect: float, clutter_density: float, gate: float) -> np.ndarray:
    """``(M, L, D)`` log g_tr (see the module notes); −inf outside the gate."""
    base = np.log(p_detect) - np.log1p(-p_detect * gate) - np.log(clutter_density)
    return np.where(hyp.gated, base + hyp.loglik, -np.inf)


# --------------------------------------------------------------------------
# JPDA marginals
# --------------------------------------------------------------------------
def jpda_marginals(log_g: np.ndarray, max_events: int = MAX_EVENTS) -> tuple[np.ndarray, np.ndarray]:
    """Marginal association probabilities of JPDA, exact within clusters.

    A joint event assigns each track at most one detection and each
    detection at most one track; its weight is Π g_tr over its pairs
    (a missed track and a clutter detection weigh 1).  β_tr is the
    normalised sum of the weights of the events holding (t, r) and
    β_t0 = 1 − Σ_r β_tr.

    Tracks that share no gated detection are independent, so the events
    factor over *clusters* (connected components of the gating graph,
    found for all runs at once).  A cluster of one track has the closed form
    β_tr = g_tr / (1 + Σ_r g_tr) (vectorised over runs); larger clusters are
    enumerated exactly, one cluster at a time (a Python loop over those
    clusters only, each enumerated with array operations, track by track).
    A cluster whose partial event count exceeds ``max_events`` is not
    enumerated: its marginals come from loopy belief propagation
    (:func:`jpda_marginals_lbp`, Williams & Lau 2014), an approximation
    that is exact on clusters without cycles.

    Parameters
    ----------
    log_g
        ``(M, L, D)`` log weights; −inf where a pair is impossible.
    max_events
        Cap on the joint events of one cluster.

    Returns
    -------
    beta, beta0
        ``(M, L, D)`` and ``(M, L)``.
    """
    M, L, D = log_g.shape
    gated = np.isfinite(log_g)
    beta = np.zeros((M, L, D))
    # One track per cluster (the common case): the single-target PDA form, for all runs at once.
    n_tracks_per_det = gated.sum(axis=1)  # (M, D)
    shared = (gated & (n_tracks_per_det[:, None, :] > 1)).any(axis=2)  # (M, L): shares a detection
    solo = ~shared
    top = np.maximum(np.max(np.where(gated, log_g, -np.inf), axis=2, initial=0.0), 0.0)  # (M, L), for stability
    w = np.where(gated, np.exp(log_g - top[..., None]), 0.0)
    denom = np.exp(-top) + w.sum(axis=2)
    beta = np.where(solo[..., None], w / denom[..., None], 0.0)
    if shared.any():
        for run, tracks, dets in _clusters(gated, shared):
            sub = log_g[run][np.ix_(tracks, dets)]
            b = _enumerate(sub, max_events)
            if b is None:
                b = jpda_marginals_lbp(sub[None])[0][0]
            beta[run][np.ix_(tracks, dets)] = b
    beta0 = np.clip(1.0 - beta.sum(axis=2), 0.0, 1.0)
    return beta, beta0


def _clusters(gated: np.ndarray, shared: np.ndarray):
    """``(run, tracks, detections)`` of every cluster holding more than one track."""
    M, L, D = gated.shape
    m, t, r = np.nonzero(gated & shared[..., None])
    # Nodes: tracks m*L + t, detections M*L + m*D + r; one graph for all runs (block-diagonal).
    n = M * L + M * D
    graph = coo_matrix((np.ones(m.size), (m * L + t, M * L + m * D + r)), shape=(n, n))
    _, comp = connected_components(graph, directed=False)
    track_comp = comp[: M * L].reshape(M, L)
    det_comp = comp[M * L :].reshape(M, D)
    # Group the shared tracks and their detections by component with one sort each (no scan per cluster).
    tm, tt = np.nonzero(shared)
    dm, dr = np.nonzero((gated & shared[..., None]).any(axis=1))
    t_key, d_key = track_comp[tm, tt], det_comp[dm, dr]
    t_order, d_order = np.argsort(t_key, kind="stable"), np.argsort(d_key, kind="stable")
    comps, t_start = np.unique(t_key[t_order], return_index=True)
    d_start = np.searchsorted(d_key[d_order], comps)
    d_stop = np.searchsorted(d_key[d_order], comps, side="right")
    t_stop = np.append(t_start[1:], t_order.size)
    for i in range(comps.size):
        ts = t_order[t_start[i] : t_stop[i]]
        ds = d_order[d_start[i] : d_stop[i]]
        yield int(tm[ts[0]]), tt[ts], dr[ds]


def _enumerate(log_g: np.ndarray, max_events: int) -> np.ndarray | None:
    """Exact marginals ``(nt, nd)`` of one cluster, or None beyond ``max_events``.

    Events are built track by track as arrays: ``choice (E, t)`` (−1 =
    missed) with a bitmask of the detections already taken and the event's
    log weight.
    """
    nt, nd = log_g.shape
    if nd > 62:
        return None  # the bitmask holds 62 detections
    choice = np.zeros((1, 0), dtype=np.int64)
    used = np.zeros(1, dtype=np.int64)
    logw = np.zeros(1)
    for t in range(nt):
        parts_c = [np.concatenate([choice, np.full((choice.shape[0], 1), -1)], axis=1)]
        parts_u, parts_w = [used], [logw]
        for r in np.nonzero(np.isfinite(log_g[t]))[0]:
            free = (used >> r) & 1 == 0
            if not free.any():
                continue
            parts_c.append(np.concatenate([choice[free], np.full((int(free.sum()), 1), r)], axis=1))
            parts_u.append(used[free] | (1 << int(r)))
            parts_w.append(logw[free] + log_g[t, r])
        choice = np.concatenate(parts_c)
        used = np.concatenate(parts_u)
        logw = np.concatenate(parts_w)
        if choice.shape[0] > max_events:
            return None
    w = np.exp(logw - logw.max())
    w /= w.sum()
    beta = np.zeros((nt, nd))
    rows = np.nonzero(choice >= 0)
    np.add.at(beta, (rows[1], choice[rows]), w[rows[0]])
    return beta


def jpda_marginals_lbp(log_g: np.ndarray, iterations: int = 100, tol: float = 1e-12) -> tuple[np.ndarray, np.ndarray]:
    """Approximate JPDA marginals by loopy belief propagation (Williams & Lau 2014), batched.

    Messages μ_{t→r} = g_tr / (1 + Σ_{r'≠r} g_tr' ν_{r'→t}) and
    ν_{r→t} = 1 / (1 + Σ_{t'≠t} μ_{t'→r}), iterated from ν = 1 until they
    change by less than ``tol``; then β_tr ∝ g_tr ν_{r→t} against 1 for
    "missed".  Exact when the gating graph has no cycle.

    Parameters
    ----------
    log_g
        ``(..., L, D)`` log weights, −inf where a pair is impossible.

    Returns
    -------
    beta, beta0
        ``(..., L, D)`` and ``(..., L)``.
    """
    g = np.where(np.isfinite(log_g), np.exp(np.minimum(log_g, 700.0)), 0.0)
    nu = np.ones_like(g)
    for _ in range(iterations):
        gn = g * nu
        mu = g / (1.0 + gn.sum(axis=-1, keepdims=True) - gn)
        nu_new = 1.0 / (1.0 + mu.sum(axis=-2, keepdims=True) - mu)
        done = np.max(np.abs(nu_new - nu), initial=0.0) < tol
        nu = nu_new
        if done:
            break
    gn = g * nu
    denom = 1.0 + gn.sum(axis=-1, keepdims=True)
    return gn / denom, 1.0 / denom[..., 0]
