"""Stone Soup's multi-target trackers on pursuit's detections, one run at a time (the peer of ``bench_mt.py``,
``bench_pmht.py`` and ``bench_gmphd.py``).

Only the benchmark environment has Stone Soup (``benchmarks/requirements-peers.txt``); nothing in
``src/`` imports this module.  The trackers are set up as in Stone Soup's own tutorials, with the
same models, gate, detection probability and clutter density as pursuit's trackers:

* per-track filter: ``KalmanPredictor`` / ``KalmanUpdater`` with a 2-D nearly-constant-velocity
  model (``ConstantVelocity(q)`` per axis, state ``[x, vx, y, vy]``) and a linear position sensor;
* GNN: ``DistanceHypothesiser`` (Mahalanobis distance, missed distance = the χ² gate) with
  ``GNNWith2DAssignment`` in a ``MultiTargetTracker``;
* JPDA: ``PDAHypothesiser`` (P_D, clutter density, gate probability) with ``JPDA`` in a
  ``MultiTargetMixtureTracker``;
* management: ``MultiMeasurementInitiator`` (a tentative track confirmed after ``min_points``
  updates, started from one measurement with the prior's velocity spread) and
  ``UpdateTimeStepsDeleter`` (deleted after ``misses`` scans without an update).  pursuit starts a
  track by two-point differencing and confirms M of N: the same job, not the same rule.

PMHT (:func:`pmht_one_run`): Stone Soup's ``PMHTTracker`` (a fixed set of tracks from given priors,
no initiation or deletion) with ``KalmanPredictor``, ``KalmanUpdater`` and ``KalmanSmoother``; a scan's
estimate is the track state at that scan in the batch that first brings the scan in.
:func:`corrected_pmht` is the same tracker with one line's worth of change (the clutter prior of
each scan read at that scan), labelled as such wherever it is used.

GM-PHD (:func:`gmphd_one_run`): ``PointProcessMultiTargetTracker`` with ``PHDUpdater``,
``GaussianMixtureHypothesiser`` over a ``DistanceHypothesiser`` and ``GaussianMixtureReducer``, one
fixed birth component, as in Stone Soup's GM-PHD tutorial; the estimates of a scan are its
``extracted_target_states``.

The output is what GOSPA needs: per scan, the positions of the tracks that exist after that scan.
"""

from __future__ import annotations

import datetime
from typing import Sequence

import numpy as np


def _components(q: float, R: np.ndarray, dt: float, prior_vel_var: float, prior_pos_var: float):
    from stonesoup.models.measurement.linear import LinearGaussian
    from stonesoup.models.transition.linear import CombinedLinearGaussianTransitionModel, ConstantVelocity
    from stonesoup.predictor.kalman import KalmanPredictor
    from stonesoup.types.state import GaussianState
    from stonesoup.updater.kalman import KalmanUpdater

    transition = CombinedLinearGaussianTransitionModel([ConstantVelocity(q), ConstantVelocity(q)])
    measurement = LinearGaussian(ndim_state=4, mapping=(0, 2), noise_covar=np.asarray(R, dtype=float))
    predictor = KalmanPredictor(transition)
    updater = KalmanUpdater(measurement)
    prior = GaussianState(
        np.zeros((4, 1)), np.diag([prior_pos_var, prior_vel_var, prior_pos_var, prior_vel_var])
    )
    return transition, measurement, predictor, updater, prior


def track_one_run(
    scans: Sequence[np.ndarray],
    *,
    method: str,
    q: float,
    R: np.ndarray,
    dt: float,
    p_detect: float,
    clutter_density: float,
    gate_probability: float,
    min_points: int = 2,
    misses: int = 3,
    prior_vel_var: float = 100.0,
) -> list[np.ndarray]:
    """Track one run's scans with Stone Soup; returns, per scan, the ``(n_tracks, 2)`` track positions.

    ``scans[k]`` is the ``(n_k, 2)`` array of position detections of scan k (no labels).
    """
    from scipy.stats import chi2
    from stonesoup.dataassociator.neighbour import GNNWith2DAssignment
    from stonesoup.dataassociator.probability import JPDA
    from stonesoup.deleter.time import UpdateTimeStepsDeleter
    from stonesoup.hypothesiser.distance import DistanceHypothesiser
    from stonesoup.hypothesiser.probability import PDAHypothesiser
    from stonesoup.initiator.simple import MultiMeasurementInitiator
    from stonesoup.measures import Mahalanobis
    from stonesoup.tracker.simple import MultiTargetMixtureTracker, MultiTargetTracker
    from stonesoup.types.detection import Detection

    _, measurement, predictor, updater, prior = _components(q, R, dt, prior_vel_var, float(np.max(np.diag(R))))
    gate = float(np.sqrt(chi2.ppf(gate_probability, 2)))  # Mahalanobis distance, not its square
    if method == "gnn":
        hyp = DistanceHypothesiser(predictor, updater, measure=Mahalanobis(), missed_distance=gate)
        associator = GNNWith2DAssignment(hyp)
        tracker_cls = MultiTargetTracker
    elif method == "jpda":
        hyp = PDAHypothesiser(
            predictor, updater, clutter_spatial_density=clutter_density, prob_detect=p_detect,
            prob_gate=gate_probability,
        )
        associator = JPDA(hyp)
        tracker_cls = MultiTargetMixtureTracker
    else:
        raise ValueError(f"method: expected 'gnn' or 'jpda', got {method!r}")
    deleter = UpdateTimeStepsDeleter(misses)
    # the initiator's own association is GNN in both trackers, as in Stone Soup's tutorials
    init_assoc = GNNWith2DAssignment(DistanceHypothesiser(predictor, updater, measure=Mahalanobis(), missed_distance=gate))
    initiator = MultiMeasurementInitiator(
        prior_state=prior, measurement_model=measurement, deleter=UpdateTimeStepsDeleter(misses),
        data_associator=init_assoc, updater=updater, min_points=min_points,
    )
    start = datetime.datetime(2000, 1, 1)
    feed = []
    for k, z in enumerate(scans):
        t = start + datetime.timedelta(seconds=(k + 1) * dt)
        feed.append((t, {Detection(row.reshape(2, 1), timestamp=t, measurement_model=measurement) for row in z}))
    tracker = tracker_cls(
        initiator=initiator, deleter=deleter, detector=feed, data_associator=associator, updater=updater
    )
    out = []
    for _, tracks in tracker:
        pos = [np.asarray(tr.state_vector, dtype=float).ravel()[[0, 2]] for tr in tracks]
        out.append(np.array(pos).reshape(-1, 2))
    return out


def _feed(scans: Sequence[np.ndarray], measurement, dt: float, start: datetime.datetime, pad: int = 0) -> list:
    """``(time, set of Detection)`` per scan (scan k at ``start + k dt``), then ``pad`` empty scans."""
    from stonesoup.types.detection import Detection

    feed = []
    for k in range(len(scans) + pad):
        t = start + datetime.timedelta(seconds=(k + 1) * dt)
        z = scans[k] if k < len(scans) else np.zeros((0, 2))
        feed.append((t, {Detection(row.reshape(2, 1), timestamp=t, measurement_model=measurement) for row in z}))
    return feed


def corrected_pmht():
    """Stone Soup's ``PMHTTracker`` with each scan's clutter prior read at that scan (a labelled variant).

    Stone Soup 1.9.1's ``_compute_log_weights`` gives the clutter row of scan k of a batch the prior
    ``log_pi[start][0]`` of the batch's *first* scan, while the target rows use ``log_pi[start + k]``.
    This subclass recomputes the weights with ``log_pi[start + k][0]``; nothing else changes.
    """
    from scipy.special import logsumexp
    from stonesoup.tracker.pmht import PMHTTracker

    class CorrectedPMHTTracker(PMHTTracker):
        def _compute_log_weights(self):
            model = self.updater.measurement_model
            H, R = model.matrix(), np.asarray(model.noise_covar, dtype=float)
            Rinv = np.linalg.inv(R)
            const = np.linalg.slogdet(2.0 * np.pi * R)[1]
            tracks = list(self._tracks)  # the set's iteration order, as the other methods use it
            n = len(self._measurement_history)
            first = len(self._log_pi) - n
            out = []
            for k, scan in enumerate(self._measurement_history):
                z = np.array([np.asarray(d.state_vector, dtype=float).ravel() for d in scan]).reshape(len(scan), H.shape[0])
                log_pi = self._log_pi[first + k]
                lw = np.empty((len(tracks) + 1, len(scan)))
                lw[0] = log_pi[0] - np.log(self.clutter_spatial_volume)  # this scan's prior, not the batch's first
                for m, track in enumerate(tracks, 1):
                    x = np.asarray(track[len(track) - n + k].state_vector, dtype=float).ravel()
                    r = z - H @ x
                    lw[m] = log_pi[m] - 0.5 * (np.einsum("ri,ij,rj->r", r, Rinv, r) + const)
                out.append(lw - logsumexp(lw, axis=0, keepdims=True) if len(scan) else lw)
            return out

    return CorrectedPMHTTracker


def pmht_one_run(
    scans: Sequence[np.ndarray],
    *,
    prior_means: np.ndarray,
    prior_cov: np.ndarray,
    q: float,
    R: np.ndarray,
    dt: float,
    p_detect: float,
    clutter_rate: float,
    meas_range: np.ndarray,
    batch_len: int,
    overlap_len: int,
    max_iter: int,
    update_log_pi: bool,
    corrected: bool = False,
) -> list[np.ndarray]:
    """Track one run's scans with Stone Soup's ``PMHTTracker``; returns, per scan, the ``(T, 2)`` track positions.

    ``prior_means (T, 4)`` and ``prior_cov (4, 4)``: the fixed tracks' priors, one ``dt`` before the
    first scan.  Scans are padded with empty ones to whole batches (Stone Soup stops mid-batch
    otherwise); an empty scan after the data adds no information to the estimates before it.
    """
    from stonesoup.smoother.kalman import KalmanSmoother
    from stonesoup.tracker.pmht import PMHTTracker
    from stonesoup.types.state import GaussianState

    transition, measurement, predictor, updater, _ = _components(q, R, dt, 1.0, 1.0)
    start = datetime.datetime(2000, 1, 1)
    step = batch_len - overlap_len
    K = len(scans)
    pad = (-K) % step
    priors = [GaussianState(np.asarray(m, dtype=float).reshape(-1, 1), np.asarray(prior_cov, dtype=float), timestamp=start) for m in prior_means]
    cls = corrected_pmht() if corrected else PMHTTracker
    tracker = cls(
        detector=_feed(scans, measurement, dt, start, pad), predictor=predictor, smoother=KalmanSmoother(transition),
        updater=updater, meas_range=np.asarray(meas_range, dtype=float), clutter_rate=clutter_rate,
        detection_probability=p_detect, batch_len=batch_len, overlap_len=overlap_len, init_priors=priors,
        max_num_iterations=max_iter, update_log_pi=update_log_pi,
    )  # fmt: skip
    out: list[np.ndarray] = []
    for _, tracks in tracker:
        # the batch's newest ``step`` scans are reported now: the estimates at them, in this batch
        for j in range(step, 0, -1):
            out.append(np.array([np.asarray(tr[-j].state_vector, dtype=float).ravel()[[0, 2]] for tr in tracks]).reshape(-1, 2))
    return out[:K]


def gmphd_one_run(
    scans: Sequence[np.ndarray],
    *,
    q: float,
    R: np.ndarray,
    dt: float,
    p_detect: float,
    p_survive: float,
    clutter_density: float,
    birth_mean: np.ndarray,
    birth_cov: np.ndarray,
    birth_rate: float,
    prune: float,
    merge: float,
    max_components: int,
    extract: float,
    gate: float,
) -> list[np.ndarray]:
    """Track one run's scans with Stone Soup's GM-PHD; returns, per scan, the ``(n, 2)`` extracted positions.

    One birth component ``N(birth_mean, birth_cov)`` of weight ``birth_rate`` every scan; the
    hypothesiser pairs components and detections within Mahalanobis distance ``gate``.
    """
    from stonesoup.hypothesiser.distance import DistanceHypothesiser
    from stonesoup.hypothesiser.gaussianmixture import GaussianMixtureHypothesiser
    from stonesoup.measures import Mahalanobis
    from stonesoup.mixturereducer.gaussianmixture import GaussianMixtureReducer
    from stonesoup.tracker.pointprocess import PointProcessMultiTargetTracker
    from stonesoup.types.state import TaggedWeightedGaussianState
    from stonesoup.updater.pointprocess import PHDUpdater

    _, measurement, predictor, updater, _ = _components(q, R, dt, 1.0, 1.0)
    start = datetime.datetime(2000, 1, 1)
    hyp = GaussianMixtureHypothesiser(DistanceHypothesiser(predictor, updater, Mahalanobis(), missed_distance=gate), order_by_detection=True)
    phd = PHDUpdater(updater, clutter_spatial_density=clutter_density, prob_detection=p_detect, prob_survival=p_survive)
    reducer = GaussianMixtureReducer(prune_threshold=prune, merge_threshold=merge, max_number_components=max_components)
    birth = TaggedWeightedGaussianState(
        np.asarray(birth_mean, dtype=float).reshape(-1, 1), np.asarray(birth_cov, dtype=float), weight=birth_rate,
        tag=TaggedWeightedGaussianState.BIRTH, timestamp=start,
    )  # fmt: skip
    tracker = PointProcessMultiTargetTracker(
        detector=_feed(scans, measurement, dt, start), updater=phd, hypothesiser=hyp, reducer=reducer,
        birth_component=birth, extraction_threshold=extract,
    )  # fmt: skip
    out = []
    for _ in tracker:
        est = tracker.extracted_target_states
        out.append(np.array([np.asarray(c.state_vector, dtype=float).ravel()[[0, 2]] for c in est]).reshape(-1, 2))
    return out
