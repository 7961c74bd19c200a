"""Unlabelled detections and multi-target truth, batched over Monte Carlo runs.

The representation of docs/spec/05-multi-target-pmht.md §1, time-major like
the rest of pursuit (K scans, M runs):

* :class:`Scans`: the detections of every scan of every run in one padded
  array ``z (K, M, D, m)``; a row is either a detection (all components
  finite) or padding (all NaN); D is the largest count over the batch.  The
  order of the rows within a scan carries no meaning.  A simulation also
  records each row's ``origin`` (the truth target slot, −1 for clutter, −2
  for padding); trackers never read it.
* :class:`MultiTargetTruth`: the true states ``(K, M, N, n)`` of N target
  slots, NaN where the target does not exist, with the existence mask and
  one persistent label per slot.

:func:`pad_scans` builds :class:`Scans` from ragged per-scan, per-run lists.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

__all__ = ["Scans", "MultiTargetTruth", "pad_scans", "CLUTTER", "PADDING"]

CLUTTER = -1
"""``origin`` of a false alarm."""

PADDING = -2
"""``origin`` of a padding row (no detection)."""


def _times(times, steps: int) -> np.ndarray:
    try:
        t = np.array(times, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"times: expected numbers, got {times!r}") from None
    if t.shape != (steps,):
        raise ValueError(f"times: expected shape ({steps},) (one time per scan), got {t.shape}")
    if not np.all(np.isfinite(t)):
        raise ValueError("times: contains NaN or infinity")
    if steps > 1 and not np.all(np.diff(t) > 0):
        k = int(np.argmax(~(np.diff(t) > 0))) + 1
        raise ValueError(f"times: must increase strictly, but scan {k} at {t[k]!r} does not come after {t[k - 1]!r}")
    t.setflags(write=False)
    return t


def _rows_valid(name: str, z: np.ndarray, axes: str) -> np.ndarray:
    """The mask of detection rows of ``z`` (last axis = components); raises on inf or half-NaN rows."""
    if np.isinf(z).any():
        where = tuple(int(i) for i in np.argwhere(np.isinf(z))[0])
        raise ValueError(f"{name}: infinity at {where} ({axes}); padding rows are NaN")
    nan = np.isnan(z)
    present = ~nan.any(axis=-1)
    mixed = nan.any(axis=-1) & ~nan.all(axis=-1)
    if mixed.any():
        where = tuple(int(i) for i in np.argwhere(mixed)[0])
        raise ValueError(
            f"{name}: row {where} ({axes[: axes.rfind(',')]}) is partly NaN; a row is a detection (all finite) or padding (all NaN)"
        )
    return present


@dataclass(frozen=True, eq=False)
class Scans:
    """Detections of K scans for M runs, padded to D rows per scan.

    Attributes
    ----------
    z
        ``(K, M, D, m)`` float64 detections; NaN rows are padding.  Rows of
        one scan are in no particular order (the built-in simulators shuffle
        them and put the padding last).
    times
        ``(K,)`` strictly increasing scan times, s.
    origin
        ``(K, M, D)`` int: the truth target slot a row came from, ``-1``
        (:data:`CLUTTER`) for a false alarm, ``-2`` (:data:`PADDING`) exactly
        on the padding rows; or None (recorded data).  For scoring and
        figures only: a tracker never reads it.

    Raises
    ------
    ValueError
        Naming the field, for a wrong shape, an infinity, a row that is
        partly NaN, times that do not increase, or an origin that does not
        match the padding.
    """

    z: np.ndarray
    times: np.ndarray
    origin: np.ndarray | None = None

    def __post_init__(self) -> None:
        try:
            z = np.array(self.z, dtype=float)
        except (TypeError, ValueError):
            raise ValueError("z: expected a (K, M, D, m) array of numbers") from None
        if z.ndim != 4:
            raise ValueError(f"z: expected shape (K, M, D, m), got {z.shape}")
        if z.shape[0] < 1 or z.shape[1] < 1 or z.shape[3] < 1:
            raise ValueError(f"z: needs at least one scan, one run and one component, got shape {z.shape}")
        present = _rows_valid("z", z, "scan, run, row, component")
        z.setflags(write=False)
        object.__setattr__(self, "z", z)
        object.__setattr__(self, "times", _times(self.times, z.shape[0]))
        if self.origin is not None:
            origin = _origin(self.origin, z.shape[:3], present)
            object.__setattr__(self, "origin", origin)
        count = present.sum(axis=-1)
        count.setflags(write=False)
        object.__setattr__(self, "_count", count)

    @property
    def steps(self) -> int:
        """Number of scans K."""
        return self.z.shape[0]

    @property
    def runs(self) -> int:
        """Number of runs M."""
        return self.z.shape[1]

    @property
    def dim(self) -> int:
        """Components per detection m."""
        return self.z.shape[3]

    @property
    def capacity(self) -> int:
        """Rows per scan D (the largest count over the batch, or more)."""
        return self.z.shape[2]

    @property
    def count(self) -> np.ndarray:
        """``(K, M)`` number of detections (non-NaN rows) per scan and run."""
        return self._count

    @property
    def present(self) -> np.ndarray:
        """``(K, M, D)`` bool: which rows are detections."""
        return ~np.isnan(self.z[..., 0])

    def select_runs(self, idx) -> "Scans":
        """The scans of runs ``idx`` (an index array, a slice or a boolean mask over M).

        The padding is trimmed to the largest row still used, so a selection
        of one run is as narrow as that run's busiest scan allows.
        """
        z = self.z[:, idx]
        origin = None if self.origin is None else self.origin[:, idx]
        if z.ndim != 4:
            raise ValueError("idx: select runs with an index array, a slice or a mask, not a single integer")
        used = ~np.isnan(z[..., 0])
        width = int(np.max(np.nonzero(used.any(axis=(0, 1)))[0], initial=-1)) + 1
        z = z[:, :, :width]
        origin = None if origin is None else origin[:, :, :width]
        return Scans(z, self.times, origin)

    def per_run(self, k: int, run: int) -> np.ndarray:
        """The ``(n, m)`` detections of scan ``k`` (from 0) in run ``run``, padding removed."""
        z = self.z[k, run]
        return z[~np.isnan(z[:, 0])]


def _origin(value, shape: tuple[int, ...], present: np.ndarray) -> np.ndarray:
    origin = np.asarray(value)
    if origin.shape != shape:
        raise ValueError(f"origin: expected shape {shape} (scan, run, row), got {origin.shape}")
    if origin.dtype.kind not in "iu":
        if origin.dtype.kind == "f" and np.all(np.isfinite(origin)) and np.all(origin == np.round(origin)):
            origin = origin.astype(np.int64)
        else:
            raise ValueError(f"origin: expected integers, got dtype {origin.dtype}")
    origin = origin.astype(np.int64, copy=True)
    if (origin < PADDING).any():
        raise ValueError(f"origin: values must be a target slot (>= 0), -1 (clutter) or -2 (padding), got {int(origin.min())}")
    wrong = (origin == PADDING) != ~present
    if wrong.any():
        where = tuple(int(i) for i in np.argwhere(wrong)[0])
        what = "a padding (NaN) row" if not present[where] else "a detection"
        raise ValueError(f"origin: -2 (padding) must mark exactly the NaN rows; {what} at {where} has origin {int(origin[where])}")
    origin.setflags(write=False)
    return origin


@dataclass(frozen=True, eq=False)
class MultiTargetTruth:
    """True states of N target slots over K scans and M runs.

    Attributes
    ----------
    states
        ``(K, M, N, n)`` float64; all NaN where the slot's target does not
        exist, all finite where it does.
    exists
        ``(K, M, N)`` bool existence mask.
    labels
        ``(N,)`` distinct int labels, one per slot (the same in every run).

    Raises
    ------
    ValueError
        Naming the field, for a wrong shape, an infinity, states that are
        NaN where a target exists (or finite where it does not), or repeated
        labels.
    """

    states: np.ndarray
    exists: np.ndarray
    labels: np.ndarray

    def __post_init__(self) -> None:
        try:
            states = np.array(self.states, dtype=float)
        except (TypeError, ValueError):
            raise ValueError("states: expected a (K, M, N, n) array of numbers") from None
        if states.ndim != 4 or states.shape[0] < 1 or states.shape[1] < 1 or states.shape[3] < 1:
            raise ValueError(f"states: expected shape (K, M, N, n) with K, M, n >= 1, got {states.shape}")
        present = _rows_valid("states", states, "scan, run, target, component")
        exists = np.asarray(self.exists)
        if exists.shape != states.shape[:3]:
            raise ValueError(f"exists: expected shape {states.shape[:3]} (scan, run, target), got {exists.shape}")
        if exists.dtype != bool:
            raise ValueError(f"exists: expected booleans, got dtype {exists.dtype}")
        if (exists != present).any():
            where = tuple(int(i) for i in np.argwhere(exists != present)[0])
            what = "exists but its state is NaN" if exists[where] else "does not exist but has a finite state"
            raise ValueError(f"exists: target at {where} (scan, run, target) {what}")
        labels = np.asarray(self.labels)
        if labels.shape != (states.shape[2],):
            raise ValueError(f"labels: expected shape ({states.shape[2]},) (one per target slot), got {labels.shape}")
        if labels.size and labels.dtype.kind not in "iu":
            raise ValueError(f"labels: expected integers, got dtype {labels.dtype}")
        labels = labels.astype(np.int64)
        if np.unique(labels).size != labels.size:
            raise ValueError(f"labels: must be distinct, got {labels.tolist()}")
        for name, arr in (("states", states), ("exists", exists.copy()), ("labels", labels)):
            arr.setflags(write=False)
            object.__setattr__(self, name, arr)

    @property
    def steps(self) -> int:
        """Number of scans K."""
        return self.states.shape[0]

    @property
    def runs(self) -> int:
        """Number of runs M."""
        return self.states.shape[1]

    @property
    def targets(self) -> int:
        """Number of target slots N."""
        return self.states.shape[2]

    @property
    def count(self) -> np.ndarray:
        """``(K, M)`` number of targets that exist per scan and run."""
        return self.exists.sum(axis=-1)

    def positions(self, indices: Sequence[int]) -> np.ndarray:
        """``(K, M, N, d)`` the state components ``indices`` (NaN where absent); the mask is :attr:`exists`."""
        idx = list(indices)
        n = self.states.shape[3]
        for i in idx:
            if isinstance(i, bool) or not isinstance(i, (int, np.integer)) or not 0 <= i < n:
                raise ValueError(f"indices: expected state indices in [0, {n}), got {i!r}")
        return self.states[..., idx]

    def select_runs(self, idx) -> "MultiTargetTruth":
        """The truth of runs ``idx`` (an index array, a slice or a boolean mask over M)."""
        states = self.states[:, idx]
        if states.ndim != 4:
            raise ValueError("idx: select runs with an index array, a slice or a mask, not a single integer")
        return MultiTargetTruth(states, self.exists[:, idx], self.labels)


def pad_scans(
    detections: Sequence[Sequence[object]],
    times: Sequence[float],
    origins: Sequence[Sequence[object]] | None = None,
    *,
    dim: int | None = None,
) -> Scans:
    """:class:`Scans` from ragged lists: ``detections[k][i]`` is scan k of run i, an ``(n, m)`` array.

    Parameters
    ----------
    detections
        K lists (one per scan) of M arrays (one per run), each ``(n, m)``
        with its own n (0 allowed: an empty list or a ``(0, m)`` array).
    times
        ``(K,)`` scan times.
    origins
        Optional, the same nesting of ``(n,)`` int arrays (target slot or −1).
    dim
        Components per detection m; needed only when every scan is empty
        and shapeless.

    Returns
    -------
    Scans
        ``z (K, M, D, m)`` with the detections first in each scan and NaN
        padding after them, D the largest n.

    Raises
    ------
    ValueError
        Naming the field, for ragged run counts, a wrong component count, or
        a non-finite detection.
    """
    if not isinstance(detections, Sequence) or not detections:
        raise ValueError("detections: expected a non-empty list (one entry per scan) of lists (one per run)")
    K = len(detections)
    M = len(detections[0]) if isinstance(detections[0], Sequence) else -1
    rows: list[list[np.ndarray]] = []
    widths: set[int] = set() if dim is None else {int(dim)}
    for k, scan in enumerate(detections):
        if not isinstance(scan, Sequence) or len(scan) != M or M < 1:
            raise ValueError(f"detections[{k}]: expected a list of {max(M, 1)} per-run arrays (as detections[0])")
        blocks = [_detection_block(f"detections[{k}][{i}]", d) for i, d in enumerate(scan)]
        widths.update(b.shape[1] for b in blocks if b is not None)
        rows.append(blocks)
    if len(widths) > 1:
        raise ValueError(f"detections: every detection needs the same number of components, got {sorted(widths)}")
    if not widths:
        raise ValueError("dim: every scan is empty; give dim (components per detection)")
    m = widths.pop()
    rows = [[np.empty((0, m)) if b is None else b for b in scan] for scan in rows]
    D = max(r.shape[0] for scan in rows for r in scan)
    z = np.full((K, M, D, m), np.nan)
    for k, scan in enumerate(rows):
        for i, r in enumerate(scan):
            z[k, i, : r.shape[0]] = r
    origin = None
    if origins is not None:
        origin = np.full((K, M, D), -2, dtype=np.int64)
        if len(origins) != K:
            raise ValueError(f"origins: expected {K} scans as detections, got {len(origins)}")
        for k in range(K):
            if len(origins[k]) != M:
                raise ValueError(f"origins[{k}]: expected {M} runs as detections, got {len(origins[k])}")
            for i in range(M):
                o = np.asarray(origins[k][i]).reshape(-1)
                if o.shape[0] != rows[k][i].shape[0]:
                    raise ValueError(f"origins[{k}][{i}]: expected {rows[k][i].shape[0]} entries (one per detection), got {o.shape[0]}")
                origin[k, i, : o.shape[0]] = o
    return Scans(z, times, origin)


def _detection_block(name: str, value) -> np.ndarray | None:
    """An ``(n, m)`` float array, or None for an empty entry of unknown width (``[]``)."""
    try:
        d = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name}: expected an (n, m) array of numbers") from None
    if d.size == 0 and d.ndim < 2:
        return None
    if d.ndim != 2:
        raise ValueError(f"{name}: expected an (n, m) array, got shape {d.shape}")
    if not np.all(np.isfinite(d)):
        raise ValueError(f"{name}: contains NaN or infinity (a detection is all finite)")
    return d
