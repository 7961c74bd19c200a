"""Track management: the track table, two-point initiation, M-of-N confirmation and deletion.

Tracks of every Monte Carlo run live in fixed-capacity arrays: ``L`` slots
per run, batch ``(M, L)``, with the per-track filter's state and the flags
and counters below.  Rules (docs/spec/05-multi-target-pmht.md §4, defaults
from there):

* **initiation**: detections of two consecutive scans that no track gated
  are paired by *mutual nearest neighbours* within ``max_speed · dt``; a
  pair starts a tentative track from two-point differencing
  (:func:`pursuit.initiation.two_point`) at the later scan; the detections
  of that pair are used up;
* **confirmation**: a tentative track is confirmed when at least M of the
  N scans after its initiation (default 2 of 3) were hits; once it can no
  longer reach M hits within N scans it is deleted;
* **deletion**: a track (tentative or confirmed) is deleted after
  ``max_misses`` (default 3) consecutive misses;
* **labels**: each run numbers its tracks 0, 1, 2, ... in order of
  initiation, never reusing a label; tracks of one scan are numbered in
  lexicographic order of their positions, so the labels do not depend on the
  order of the detections;
* **capacity**: a new track needs a free slot (deleted slots are reused);
  candidates beyond the free slots are dropped, lexicographically last
  first, and counted in ``dropped`` (the result reports it per scan).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any, Callable

import numpy as np

from ..initiation import polar_to_cartesian, two_point
from .association import scatter_state, where_state

__all__ = ["TrackTable", "new_table", "detection_positions", "update_counts", "initiate"]


@dataclass(frozen=True)
class TrackTable:
    """The tracks of all runs, ``L`` slots per run.

    Attributes
    ----------
    state
        The per-track filter's state, batch ``(M, L)`` (free slots hold a parked state).
    alive, confirmed
        ``(M, L)`` the slot holds a track; the track is confirmed.
    label
        ``(M, L)`` persistent label, −1 for a free slot.
    age, hits, misses
        ``(M, L)`` scans since initiation, hits among them, current run of misses.
    next_label
        ``(M,)`` the label the next track of each run gets.
    pending, pending_cov
        Positions ``(M, D, d)`` and covariances ``(M, D, d, d)`` of the last
        scan's detections that no track used (NaN rows: none).
    dropped
        ``(M,)`` candidates dropped at the last scan for want of a free slot.
    """

    state: Any
    alive: np.ndarray
    confirmed: np.ndarray
    label: np.ndarray
    age: np.ndarray
    hits: np.ndarray
    misses: np.ndarray
    next_label: np.ndarray
    pending: np.ndarray | None = None
    pending_cov: np.ndarray | None = None
    dropped: np.ndarray | None = None


def new_table(state: Any, runs: int, capacity: int, given: int = 0) -> TrackTable:
    """A table whose first ``given`` slots hold confirmed tracks labelled 0..given−1."""
    M, L = runs, capacity
    alive = np.zeros((M, L), dtype=bool)
    alive[:, :given] = True
    label = np.where(alive, np.arange(L), -1)
    zeros = np.zeros((M, L), dtype=np.int64)
    return TrackTable(
        state, alive, alive.copy(), label, zeros, zeros, zeros, np.full(M, given, dtype=np.int64), dropped=np.zeros(M, dtype=np.int64)
    )


def detection_positions(measurement: Any, motion: Any) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] | None:
    """A detection's position and covariance, for the built-in position and range-bearing sensors.

    Returns ``to_position(z (*b, m)) -> (p (*b, d), C (*b, d, d))``, or None
    when the measurement model is neither a linear model that measures
    exactly the motion model's position components nor a
    :class:`pursuit.models.RangeBearing` on them (then the tracker needs a
    ``position`` function).
    """
    pos = tuple(getattr(motion, "position_indices", ()) or ())
    n = getattr(motion, "dim", None)
    if not pos or n is None:
        return None
    d = len(pos)
    if callable(getattr(measurement, "matrix", None)):
        H = np.asarray(measurement.matrix(1), dtype=float)
        sel = np.zeros((d, int(n)))
        sel[np.arange(d), list(pos)] = 1.0
        if H.shape == sel.shape and np.array_equal(H, sel):
            R = np.asarray(measurement.cov(1), dtype=float)
            return lambda z: (np.asarray(z, dtype=float), np.broadcast_to(R, (*np.shape(z)[:-1], d, d)))
    if all(hasattr(measurement, a) for a in ("sensor", "sigma_range", "sigma_bearing")) and tuple(
        getattr(measurement, "position_indices", ())
    ) == pos:
        sr, sb, site = float(measurement.sigma_range), float(measurement.sigma_bearing), measurement.sensor
        return lambda z: polar_to_cartesian(z[..., 0], z[..., 1], sr, sb, site)
    return None


def update_counts(
    table: TrackTable, state: Any, hit: np.ndarray, parking: Any, confirm: tuple[int, int], max_misses: int
) -> TrackTable:
    """One scan's bookkeeping: counters, confirmation, deletion; freed slots get the parked state."""
    m_hits, n_scans = confirm
    alive = table.alive
    age = np.where(alive, table.age + 1, 0)
    hits = np.where(alive, table.hits + hit, 0)
    misses = np.where(alive & ~hit, table.misses + 1, 0)
    confirmed = alive & (table.confirmed | ((hits >= m_hits) & (age <= n_scans)))
    hopeless = ~confirmed & (age - hits > n_scans - m_hits)  # can no longer reach M of N
    alive = alive & ~hopeless & (misses < max_misses)
    confirmed &= alive
    return replace(
        table,
        state=where_state(alive, state, parking),
        alive=alive,
        confirmed=confirmed,
        label=np.where(alive, table.label, -1),
        age=np.where(alive, age, 0),
        hits=np.where(alive, hits, 0),
        misses=np.where(alive, misses, 0),
    )


def initiate(
    table: TrackTable,
    filt: Any,
    z: np.ndarray,
    unused: np.ndarray,
    to_position: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]],
    motion: Any,
    max_speed: float,
    dt: float,
    rng: Any = None,
) -> TrackTable:
    """Start tentative tracks from the unused detections of this scan and the last one.

    Parameters
    ----------
    table
        The table after this scan's update.
    filt
        The per-track filter (its ``init`` builds the new tracks' states).
    z, unused
        ``(M, D, m)`` this scan's detections and ``(M, D)`` those no track gated.
    to_position
        Detection to position and covariance (:func:`detection_positions`).
    motion
        The motion model whose state layout the new tracks take.
    max_speed, dt
        Largest speed of a target; time since the previous scan.
    """
    M, D, _ = z.shape
    L = table.alive.shape[1]
    zu = np.where(unused[..., None], z, 0.0)
    with np.errstate(invalid="ignore"):
        p2, C2 = to_position(zu)
    d = p2.shape[-1]
    p2 = np.where(unused[..., None], p2, np.nan)
    C2 = np.broadcast_to(C2, (M, D, d, d))
    dropped = np.zeros(M, dtype=np.int64)
    if table.pending is None:
        return replace(table, pending=p2, pending_cov=np.array(C2), dropped=dropped)
    p1, C1 = table.pending, table.pending_cov

    # Mutual nearest neighbours within reach: each detection starts at most one track.
    dist = np.linalg.norm(p2[:, :, None, :] - p1[:, None, :, :], axis=-1)  # (M, D2, D1)
    dist = np.where(dist <= max_speed * dt, dist, np.inf)  # NaN (a missing row) is out of reach too
    D1 = p1.shape[1]
    if D1 == 0 or D == 0:
        return replace(table, pending=p2, pending_cov=np.array(C2), dropped=dropped)
    near1 = np.argmin(dist, axis=2)  # (M, D2): nearest previous for each current
    near2 = np.argmin(dist, axis=1)  # (M, D1)
    best = np.take_along_axis(dist, near1[..., None], axis=2)[..., 0]
    mutual = np.take_along_axis(near2, near1, axis=1) == np.arange(D)
    cand = np.isfinite(best) & mutual  # (M, D2)

    # Candidates in lexicographic order of position (padding last), free slots in index order.
    key = np.where(cand[..., None], p2, 0.0)
    order = np.lexsort([*(key[..., i] for i in range(d - 1, -1, -1)), ~cand], axis=-1)  # (M, D2)
    free_order = np.argsort(table.alive, axis=1, kind="stable")  # free slots first
    n_cand = cand.sum(axis=1)
    n_free = (~table.alive).sum(axis=1)
    R = min(D, L)
    rank = np.arange(R)
    ok = (rank < n_cand[:, None]) & (rank < n_free[:, None])  # (M, R)
    dropped = np.maximum(n_cand - n_free, 0)
    runs, ranks = np.nonzero(ok)
    cur = order[runs, ranks]
    prev = near1[runs, cur]
    slot = free_order[runs, ranks]

    used = np.zeros((M, D), dtype=bool)
    used[runs, cur] = True
    pending = np.where(used[..., None], np.nan, p2)
    if not runs.size:
        return replace(table, pending=pending, pending_cov=np.array(C2), dropped=dropped)

    # Two-point priors for the chosen pairs, initialised as a flat batch and placed into their slots.
    prior = two_point(p1[runs, prev], C1[runs, prev], p2[runs, cur], C2[runs, cur], float(dt), motion)
    fresh = filt.init(prior, batch=(runs.size,), rng=rng)
    started = np.zeros((M, L), dtype=bool)
    started[runs, slot] = True
    label = table.label.copy()
    label[runs, slot] = table.next_label[runs] + ranks
    return replace(
        table,
        state=scatter_state(fresh, table.state, runs, slot),
        alive=table.alive | started,
        label=label,
        next_label=table.next_label + ok.sum(axis=1),
        pending=pending,
        pending_cov=np.array(C2),
        dropped=dropped,
    )
