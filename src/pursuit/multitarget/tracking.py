"""The multi-target tracker base, the driver over scans and its result.

A tracker (:class:`pursuit.multitarget.GNNTracker`,
:class:`pursuit.multitarget.JPDATracker`) is a frozen dataclass holding the
per-track filter, the detection and clutter model, the gate and the track
management parameters.  :func:`track_scans` runs it over a sequence of scans
``z (K, M, D, m)`` for all Monte Carlo runs at once, and
:func:`track_stream` the same scan by scan as the scans arrive (both share
one per-scan step, :func:`_scan`); the only Python loop is the one over scans
(plus, inside GNN and JPDA, a loop over the runs or clusters where an
assignment must be solved).  Per scan:

1. every (track, detection) hypothesis is evaluated with one ``step`` call
   (:func:`pursuit.multitarget.association.evaluate_hypotheses`) and gated;
2. the tracker associates and gives each track its posterior and a hit flag;
3. the counters confirm and delete tracks
   (:func:`pursuit.multitarget.management.update_counts`);
4. detections no track gated start tentative tracks with those of the
   previous scan (:func:`pursuit.multitarget.management.initiate`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Callable, Iterable, Iterator

import numpy as np

from .._validation import as_float_array, in_range, positive, positive_int
from ..filters.gaussian import CubatureKalmanFilter, ExtendedKalmanFilter, UnscentedKalmanFilter
from ..filters.imm import InteractingMultipleModel
from ..gaussian import Gaussian
from ..rng import RNGLike
from .association import Hypotheses, evaluate_hypotheses, log_weights
from .management import TrackTable, detection_positions, initiate, new_table, update_counts

__all__ = ["TrackerBase", "MultiTrackResult", "ScanTracks", "track_scans", "track_stream", "checked_scans"]

# what the hypothesis evaluation and the JPDA moment matching need: a Gaussian state (mean, cov) per track
_PER_TRACK_FILTERS = (ExtendedKalmanFilter, UnscentedKalmanFilter, CubatureKalmanFilter, InteractingMultipleModel)


def resolve_position(position: Any, filt: Any, motion: Any) -> Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]]:
    """The detection → (position, covariance) function that track initiation uses.

    ``position`` when given (it must be callable), else the built-in one for the
    filter's sensor (:func:`pursuit.multitarget.management.detection_positions`);
    raises ``ValueError`` naming ``position`` when there is neither.
    """
    if position is not None:
        if not callable(position):
            raise ValueError("position: expected a function z -> (position, covariance)")
        return position
    to_position = detection_positions(_layout_measurement(filt), motion)
    if to_position is None:
        raise ValueError(
            "position: give a function from a detection to a position and covariance; the measurement "
            "model is neither a position fix of the motion model's positions nor a range-bearing sensor"
        )
    return to_position


def _layout_motion(filt: Any) -> Any:
    """The motion model whose state the tracks carry: the filter's, or an IMM's first mode without maps."""
    motion = getattr(filt, "motion", None)
    if motion is None and hasattr(filt, "filters") and all(m is None for m in getattr(filt, "maps", (None,))):
        motion = getattr(filt.filters[0], "motion", None)
    return motion


def _layout_measurement(filt: Any) -> Any:
    """The filter's measurement model, or an IMM's first mode's (the modes share the sensor)."""
    measurement = getattr(filt, "measurement", None)
    if measurement is None and hasattr(filt, "filters"):
        measurement = getattr(filt.filters[0], "measurement", None)
    return measurement


@dataclass(frozen=True)
class TrackerBase:
    """What GNN and JPDA share: the per-track filter, the detection model, the gate, track management.

    Parameters
    ----------
    filter
        The per-track filter: any pursuit Gaussian filter (KF, EKF, UKF,
        CKF) or an IMM of them, with its motion and measurement models.
    p_detect
        Detection probability P_D in (0, 1].
    clutter_density
        λ: expected false alarms per scan per unit volume of measurement
        space (> 0), e.g. 10 / (300 m × 300 m).
    gate
        χ² gate probability P_G in (0, 1), keyword only (default 0.99).
    capacity
        L, track slots per run (keyword only, default 32).
    confirm
        (M, N): a tentative track is confirmed after M hits in the N scans
        after its initiation (keyword only, default (2, 3)).
    max_misses
        Consecutive misses that delete a track (keyword only, default 3).
    max_speed
        Largest target speed, for two-point initiation (keyword only).
        None (the default): no tracks are started from detections; tracks
        come only from the ``initial`` tracks given to :func:`track_scans`.
    position
        ``position(z (*b, m)) -> (p (*b, d), C (*b, d, d))``, a detection's
        position and covariance for initiation (keyword only; default: the
        built-in position and range-bearing sensors, see
        :func:`pursuit.multitarget.management.detection_positions`).
    name
        Label in results (keyword only).
    """

    filter: Any
    p_detect: float
    clutter_density: float
    gate: float = field(default=0.99, kw_only=True)
    capacity: int = field(default=32, kw_only=True)
    confirm: tuple[int, int] = field(default=(2, 3), kw_only=True)
    max_misses: int = field(default=3, kw_only=True)
    max_speed: float | None = field(default=None, kw_only=True)
    position: Callable[[np.ndarray], tuple[np.ndarray, np.ndarray]] | None = field(default=None, kw_only=True)
    name: str = field(default="", kw_only=True)

    def __post_init__(self) -> None:
        if not (callable(getattr(self.filter, "init", None)) and callable(getattr(self.filter, "step", None))):
            raise TypeError(f"filter: {type(self.filter).__name__} is not a filter (needs init and step)")
        if not isinstance(self.filter, _PER_TRACK_FILTERS):
            raise ValueError(
                f"filter: {type(self.filter).__name__} cannot be a per-track filter; the trackers combine Gaussian "
                "hypotheses: use a KalmanFilter, ExtendedKalmanFilter, UnscentedKalmanFilter, CubatureKalmanFilter "
                "or an InteractingMultipleModel of them"
            )
        in_range("p_detect", self.p_detect, 0.0, 1.0, low_open=True)
        positive("clutter_density", self.clutter_density)
        in_range("gate", self.gate, 0.0, 1.0, low_open=True, high_open=True)
        positive_int("capacity", self.capacity)
        positive_int("max_misses", self.max_misses)
        if len(tuple(self.confirm)) != 2:
            raise ValueError(f"confirm: expected (M, N), got {self.confirm!r}")
        m_hits, n_scans = (positive_int("confirm", v) for v in self.confirm)
        if m_hits > n_scans:
            raise ValueError(f"confirm: M must not exceed N, got {self.confirm!r}")
        object.__setattr__(self, "confirm", (m_hits, n_scans))
        if self.max_speed is not None:
            positive("max_speed", self.max_speed)
            motion = _layout_motion(self.filter)
            if motion is None or not hasattr(motion, "position_indices"):
                raise ValueError("filter: initiation (max_speed) needs a motion model with position_indices")
            object.__setattr__(self, "position", resolve_position(self.position, self.filter, motion))
        if not self.name:
            object.__setattr__(self, "name", f"{type(self).__name__.removesuffix('Tracker')}-{getattr(self.filter, 'name', '')}")

    def track(self, z: Any, *, times: Any = None, rng: RNGLike = None) -> "MultiTrackResult":
        """Track scans ``z (K, M, D, m)`` of all runs: :func:`track_scans` with no initial tracks.

        Every multi-target tracker has this method (the experiment kind calls it).
        """
        return track_scans(self, z, times=times, rng=rng)

    def associate(self, hyp: Hypotheses, log_g: np.ndarray) -> tuple[Any, np.ndarray]:
        """Each track's posterior (batch ``(M, L)``) and hit flag ``(M, L)`` from the scan's hypotheses."""
        raise NotImplementedError


@dataclass(frozen=True)
class MultiTrackResult:
    """Tracks over time, for all runs.

    Attributes
    ----------
    mean
        ``(K, M, L, n)`` track estimates after each scan (NaN in free slots).
    cov
        ``(K, M, L, n, n)`` their covariances (NaN in free slots).
    label
        ``(K, M, L)`` persistent track labels (per run), −1 for a free slot.
    confirmed
        ``(K, M, L)`` the slot holds a confirmed track.
    dropped
        ``(K, M)`` new tracks dropped for want of a free slot.
    name
        The tracker's name.
    """

    mean: np.ndarray
    cov: np.ndarray
    label: np.ndarray
    confirmed: np.ndarray
    dropped: np.ndarray
    name: str = ""

    @property
    def steps(self) -> int:
        """K."""
        return self.mean.shape[0]

    @property
    def runs(self) -> int:
        """M."""
        return self.mean.shape[1]

    @property
    def capacity(self) -> int:
        """L."""
        return self.mean.shape[2]

    def positions(self, indices: Any, confirmed_only: bool = True) -> tuple[np.ndarray, np.ndarray]:
        """Track positions ``(K, M, L, d)`` and their mask ``(K, M, L)``, the layout of the metrics.

        ``indices`` are the position components of the state (e.g. the
        motion model's ``position_indices``).
        """
        mask = self.confirmed if confirmed_only else self.label >= 0
        return self.mean[..., list(indices)], mask


def _as_initial(initial: Any, runs: int, capacity: int) -> tuple[np.ndarray, np.ndarray, int]:
    """Given tracks ``(L0, n)`` or ``(M, L0, n)`` as full ``(M, L, n)`` and ``(M, L, n, n)`` arrays."""
    g = initial if isinstance(initial, Gaussian) else Gaussian(*initial)
    mean = g.mean if g.mean.ndim == 3 else np.broadcast_to(g.mean, (runs, *g.mean.shape[-2:]))
    if mean.ndim != 3 or mean.shape[0] != runs:
        raise ValueError(f"initial: expected a mean of shape (L0, n) or ({runs}, L0, n), got {g.mean.shape}")
    L0, n = mean.shape[1:]
    if L0 > capacity:
        raise ValueError(f"initial: {L0} tracks exceed the capacity of {capacity} slots")
    cov = np.broadcast_to(g.cov, (runs, L0, n, n))
    full_mean = np.zeros((runs, capacity, n))
    full_cov = np.broadcast_to(np.eye(n), (runs, capacity, n, n)).copy()
    full_mean[:, :L0] = mean
    full_cov[:, :L0] = cov
    return full_mean, full_cov, L0


def track_scans(
    tracker: TrackerBase, z: Any, *, initial: Any = None, times: Any = None, rng: RNGLike = None
) -> MultiTrackResult:
    """Run a multi-target tracker over scans of detections, for all runs at once.

    Parameters
    ----------
    tracker
        A :class:`TrackerBase` subclass (GNN, JPDA).
    z
        ``(K, M, D, m)`` detections; NaN rows are padding (a row is either
        all finite or all NaN); the order of rows carries no meaning.
    initial
        Tracks known before the first scan, as a :class:`pursuit.Gaussian`
        (or ``(mean, cov)``) with mean ``(L0, n)`` or ``(M, L0, n)``: they take
        slots 0..L0−1, confirmed, labels 0..L0−1.  Default: none.
    times
        ``(K,)`` scan times; the step from scan k−1 to k uses their
        difference.  Default: the motion model's own ``dt`` (and the first
        scan is always one model ``dt`` after ``initial``).
    rng
        Passed to the filter's ``init``; Gaussian filters draw nothing.

    Returns
    -------
    MultiTrackResult

    See Also
    --------
    track_stream : the same tracks one scan at a time, in constant memory.
    """
    z, times = checked_scans(z, times, tracker.filter)
    K, M, D, m = z.shape
    L = tracker.capacity
    _check_timing(tracker, timed=times is not None)
    table, parking = _start(tracker, M, initial, rng)
    n = parking.mean.shape[-1]

    out_mean = np.full((K, M, L, n), np.nan)
    out_cov = np.full((K, M, L, n, n), np.nan)
    out_label = np.full((K, M, L), -1, dtype=np.int64)
    out_conf = np.zeros((K, M, L), dtype=bool)
    out_drop = np.zeros((K, M), dtype=np.int64)
    scans = zip([None] * K if times is None else times.tolist(), z)
    for k, tracks in enumerate(_steps(tracker, table, parking, scans, rng)):
        out_mean[k] = tracks.mean
        out_cov[k] = tracks.cov
        out_label[k] = tracks.label
        out_conf[k] = tracks.confirmed
        out_drop[k] = tracks.dropped
    return MultiTrackResult(out_mean, out_cov, out_label, out_conf, out_drop, tracker.name)


@dataclass(frozen=True)
class ScanTracks:
    """The tracks of all runs after one scan: one time slice of a :class:`MultiTrackResult`.

    Attributes
    ----------
    time
        The scan's time (None when the scans came without times).
    mean, cov
        ``(M, L, n)``, ``(M, L, n, n)`` (NaN in free slots).
    label
        ``(M, L)`` persistent labels, −1 for a free slot.
    confirmed
        ``(M, L)`` the slot holds a confirmed track.
    dropped
        ``(M,)`` new tracks dropped at this scan for want of a free slot.
    """

    time: float | None
    mean: np.ndarray
    cov: np.ndarray
    label: np.ndarray
    confirmed: np.ndarray
    dropped: np.ndarray


def track_stream(
    tracker: TrackerBase, scans: Iterable[tuple[float | None, Any]], *, initial: Any = None, rng: RNGLike = None
) -> Iterator[ScanTracks]:
    """Run a multi-target tracker scan by scan, yielding the tracks after each scan.

    The same computation as :func:`track_scans` (both run one shared
    per-scan step), in memory that does not grow with the number of scans:
    for a live feed or a recording too long to hold.  With the same
    detections (a scan's rows may be given without :func:`track_scans`'s
    padding) and times, the tracks are bit for bit those of
    :func:`track_scans`.

    Parameters
    ----------
    tracker
        A :class:`TrackerBase` subclass (GNN, JPDA).
    scans
        ``(time, z)`` pairs, read lazily: ``z (M, D, m)`` the detections of
        one scan for M runs (M fixed, D free to change from scan to scan, NaN
        rows padding), ``time`` its time, strictly increasing, or None for
        every scan (steps of the motion model's ``dt``).
    initial, rng
        As in :func:`track_scans`.

    Yields
    ------
    ScanTracks
        The tracks after each scan, once the scan has been processed.

    Raises
    ------
    ValueError
        Naming the field, when a scan's detections, its time or ``initial``
        do not fit; raised when that scan is reached, after the scans before it
        were yielded.
    """
    return _stream(tracker, scans, initial, rng)


def _stream(tracker: TrackerBase, scans: Iterable[tuple[float | None, Any]], initial: Any, rng: RNGLike) -> Iterator[ScanTracks]:
    it = iter(scans)
    first = next(it, None)
    if first is None:
        return
    time, z0 = first
    z0 = _checked_scan(z0, 1, None)
    _check_timing(tracker, timed=time is not None)
    table, parking = _start(tracker, z0.shape[0], initial, rng)

    def checked() -> Iterator[tuple[float | None, np.ndarray]]:
        previous, shape = time, z0.shape
        yield time, z0
        for k, (t, z) in enumerate(it, start=2):
            z = _checked_scan(z, k, shape)
            if (t is None) != (previous is None):
                have = ("no", "had one") if t is None else ("a", "had none")
                raise ValueError(f"time: scan {k} has {have[0]} time and scan 1 {have[1]}: give every scan a time, or none")
            if t is not None and not float(t) > float(previous):
                raise ValueError(f"time: scan {k} at {float(t)!r} is not after the previous scan's time {float(previous)!r}")
            previous = t
            yield t, z

    yield from _steps(tracker, table, parking, checked(), rng)


def checked_scans(z: Any, times: Any, filt: Any) -> tuple[np.ndarray, np.ndarray | None]:
    """The checks every multi-target tracker makes of its input: ``z (K, M, D, m)`` and ``times (K,)``.

    Rows all finite or all NaN (padding), no infinity; times increasing; a
    motion model with a ``dt`` when the scans are timed (the first scan is one
    model ``dt`` after the start).  Returns ``z`` and ``times`` as float arrays;
    raises ``ValueError`` naming the argument.
    """
    z = np.asarray(z, dtype=float)
    if z.ndim != 4:
        raise ValueError(f"z: expected detections of shape (K, M, D, m), got {z.shape}")
    _check_rows("z", z)
    K = z.shape[0]
    if times is not None:
        times = as_float_array("times", times)
        if times.shape != (K,) or np.any(np.diff(times) <= 0):
            raise ValueError(f"times: expected {K} increasing scan times, got shape {times.shape}")
        if getattr(_layout_motion(filt), "dt", None) is None:
            raise ValueError("times: the first scan is one motion-model dt after the start, and this motion model has no dt")
    return z, times


def _check_rows(name: str, z: np.ndarray) -> None:
    if np.isinf(z).any():
        raise ValueError(f"{name}: detections must be finite or NaN (padding)")
    nan = np.isnan(z)
    if (nan.any(axis=-1) != nan.all(axis=-1)).any():
        raise ValueError(f"{name}: a detection row must be all finite or all NaN (padding)")


def _checked_scan(z: Any, k: int, shape: tuple[int, ...] | None) -> np.ndarray:
    z = np.asarray(z, dtype=float)
    if z.ndim != 3:
        raise ValueError(f"z: scan {k}: expected detections of shape (M, D, m), got {z.shape}")
    if shape is not None and (z.shape[0], z.shape[2]) != (shape[0], shape[2]):
        raise ValueError(f"z: scan {k}: expected {shape[0]} runs of {shape[2]}-component detections as in scan 1, got {z.shape}")
    _check_rows(f"z: scan {k}", z)
    return z


def _check_timing(tracker: TrackerBase, timed: bool) -> None:
    if tracker.max_speed is not None and not timed and getattr(_layout_motion(tracker.filter), "dt", None) is None:
        raise ValueError("times: initiation needs scan times when the motion model has no dt")


def _start(tracker: TrackerBase, runs: int, initial: Any, rng: RNGLike) -> tuple[Any, Any]:
    """The track table before the first scan, and the parked state that fills free slots."""
    M, L = runs, tracker.capacity
    filt = tracker.filter
    if initial is not None:
        mean, cov, L0 = _as_initial(initial, M, L)
    else:
        n = getattr(_layout_motion(filt), "dim", None)
        if n is None:
            raise ValueError("initial: give initial tracks, or a filter whose motion model has dim")
        mean, cov, L0 = np.zeros((M, L, int(n))), np.broadcast_to(np.eye(int(n)), (M, L, int(n), int(n))).copy(), 0
    n = mean.shape[-1]
    parking = filt.init(Gaussian(np.zeros((M, L, n)), np.broadcast_to(np.eye(n), (M, L, n, n))), batch=(M, L), rng=rng)
    table = new_table(filt.init(Gaussian(mean, cov), batch=(M, L), rng=rng), M, L, L0)
    return table, parking


def _steps(
    tracker: TrackerBase, table: TrackTable, parking: Any, scans: Iterable[tuple[float | None, np.ndarray]], rng: RNGLike
) -> Iterator[ScanTracks]:
    """The one loop over scans of :func:`track_scans` and :func:`track_stream` (inputs already checked)."""
    previous = None
    for k, (time, zk) in enumerate(scans, start=1):
        dt = None if time is None or k == 1 else float(time - previous)
        table = _scan(tracker, table, parking, zk, k, dt, rng)
        previous = time
        alive = table.alive
        yield ScanTracks(
            time=None if time is None else float(time),
            mean=np.where(alive[..., None], table.state.mean, np.nan),
            cov=np.where(alive[..., None, None], table.state.cov, np.nan),
            label=table.label,
            confirmed=table.confirmed,
            dropped=table.dropped,
        )


def _scan(tracker: TrackerBase, table: TrackTable, parking: Any, zk: np.ndarray, k: int, dt: float | None, rng: RNGLike) -> TrackTable:
    """One scan (``zk (M, D, m)``, the k-th, ``dt`` after the last or None): associate, count, initiate."""
    filt = tracker.filter
    hyp = evaluate_hypotheses(filt, table.state, zk, table.alive, tracker.gate, k, dt)
    log_g = log_weights(hyp, tracker.p_detect, tracker.clutter_density, tracker.gate)
    state, hit = tracker.associate(hyp, log_g)
    table = update_counts(table, state, hit & table.alive, parking, tracker.confirm, tracker.max_misses)
    if tracker.max_speed is not None:
        motion = _layout_motion(filt)
        unused = hyp.detected & ~hyp.gated.any(axis=1)
        step_dt = dt if dt is not None else getattr(motion, "dt", None)  # None only at the first scan, which pairs nothing
        table = initiate(table, filt, zk, unused, tracker.position, motion, tracker.max_speed, step_dt, rng)
    return table
