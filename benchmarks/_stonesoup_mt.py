"""Stone Soup's GNN and JPDA trackers on pursuit's detections, one run at a time (the peer of ``bench_mt.py``).

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
